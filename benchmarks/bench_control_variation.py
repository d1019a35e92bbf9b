"""Choosing the default control-variation weight: ISE, total variation, chatter and Ms of the tuned fixed PID
and of the deployed controller, for a grid of `reward.control_variation_weight` values.

    python benchmarks/bench_control_variation.py                       # 4 plants x 5 weights, seed 0
    python benchmarks/bench_control_variation.py --plants first_order --weights 0 0.2 --timesteps 50000  # quick

Plants: first_order and two_tank (bundled scenarios, their default budgets) and two third-party-like
plants built from tests/plants (benchmarks/scenarios/room_heating.yaml: the room heater at Ts = 60 s;
benchmarks/scenarios/inertia.yaml: the motor inertia with a noisy speed measurement). Each (plant, weight,
seed) is an ordinary `tune` run directory under --out (default: a temporary folder) of a copy of the
scenario with only `reward.control_variation_weight` changed; a run whose metrics.json exists is not run
again, so an interrupted benchmark resumes. Prints one markdown table: per plant and weight, the fixed
PID's and the deployed controller's ISE, TotalVariation, Chatter (prlpid_fmi.metrics; also counting only
reversals by more than 5 % of the actuator range) and worst Ms on the scenario's evaluation, and ISE and TotalVariation as ratios to the same plant and seed at weight 0. The
metrics are measured here, with the current metrics code, by replaying the run's fixed_pid.csv and
schedule.csv (what `tune` deployed) on its evaluation; Ms and the choice come from its metrics.json.
Nothing here is asserted: it is a measurement.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import yaml

from prlpid_fmi.metrics import overall_metric
from prlpid_fmi.fmu import build_fmu
from prlpid_fmi.metrics import chatter_fraction
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.run.tune import tune
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv
from prlpid_fmi.tuning.schedule.replay import replay_schedule

HERE = Path(__file__).parent
TEST_PLANTS = HERE.parent / "tests" / "plants"
# plant -> (scenario file, FMU source folder in tests/plants or None for a bundled plant)
PLANTS = {"first_order": (scenario_path("first_order"), None), "two_tank": (scenario_path("two_tank"), None),
          "room_heating": (HERE / "scenarios" / "room_heating.yaml", "RoomHeating"),
          "inertia": (HERE / "scenarios" / "inertia.yaml", "Inertia")}
WEIGHTS = (0.0, 0.05, 0.2, 0.5, 1.0)
METRICS = (("ISE", "ISE"), ("TotalVariation", "TV(u)"), ("Chatter", "chatter"), ("Chatter5", "chatter > 5 %"))


def scenario_with_weight(plant: str, weight: float, folder: Path) -> Path:
    """A copy of the plant's scenario in `folder` (with its FMU built there for a test plant) whose
    reward.control_variation_weight is `weight`."""
    source, fmu_source = PLANTS[plant]
    folder.mkdir(parents=True, exist_ok=True)
    if fmu_source is not None and not (folder / f"{fmu_source}.fmu").is_file():
        build_fmu(fmu_source, out_dir=folder, source_dir=TEST_PLANTS / fmu_source)
    doc = yaml.safe_load(Path(source).read_text())
    doc.setdefault("reward", {})["control_variation_weight"] = float(weight)
    path = folder / f"{plant}_w{weight:g}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def run(plant: str, weight: float, seed: int, out: Path, timesteps: int | None) -> tuple[Path, dict, float]:
    """Run directory and metrics.json of the tune run of (plant, weight, seed), running it if needed; and
    its wall time [s] (NaN when it was run before)."""
    run_dir = out / f"{plant}_w{weight:g}_seed{seed}"
    wall = math.nan
    if not (run_dir / "metrics.json").is_file():
        path = scenario_with_weight(plant, weight, out / "scenarios")
        t0 = time.time()
        tune(path, timesteps=timesteps, seed=seed, out=run_dir, progress_bar=False)
        wall = time.time() - t0
    return run_dir, json.loads((run_dir / "metrics.json").read_text()), wall


def replayed(run_dir: Path, csv_name: str) -> dict:
    """Overall evaluation metrics of a schedule CSV of the run (fixed_pid.csv, schedule.csv) replayed as a
    plain PID on the run's evaluation, as `tune` assesses it (without parameter randomisation), plus
    "Chatter5": Chatter counting only moves > 5 % of the actuator range (worst loop): large reversals."""
    scenario = load_scenario(run_dir / "scenario.yaml")
    config = scenario.evaluation_config()
    config = dataclasses.replace(config, randomize={}) if config.randomize else config
    metrics, traj = replay_schedule(read_schedule_csv(run_dir / csv_name), config, seed=scenario.evaluation.seed)
    large = []
    for i, loop in enumerate(config.loops):
        u = traj.pid_output[:, i]
        span = loop.u_max - loop.u_min
        span = span if math.isfinite(span) else float(max(abs(u)))  # Chatter's fallback for unbounded u
        large.append(chatter_fraction(u, 5 * span))  # its threshold is 1 % of the range given: 5 % of span
    return {**metrics["overall"], "Chatter5": max(large)}


def controllers(run_dir: Path, m: dict) -> tuple[tuple[dict, float | None], tuple[dict, float | None], str]:
    """((overall metrics, worst Ms) of the fixed PID, of the deployed controller, which one was deployed).
    When nothing was deployable ("none"), the second is the fixed PID's."""
    fixed = (replayed(run_dir, "fixed_pid.csv"), m["fixed_pid_assessment"]["worst_Ms"])
    if m["deployed"] != "gain schedule":
        return fixed, fixed, m["deployed"]
    return fixed, (replayed(run_dir, "schedule.csv"), m["schedule_replay"]["worst_Ms"]), m["deployed"]


def _cells(overall: dict, ms, base: dict) -> list[str]:
    cells = [f"{overall_metric(overall, key):.3g}" for key, _ in METRICS]
    cells.append("not verified" if ms is None or math.isnan(ms) else f"{ms:.3g}")
    for key in ("ISE", "TotalVariation"):
        value, ref = overall_metric(overall, key), overall_metric(base, key)
        cells.append(f"{value / ref:.3f}" if ref > 0 and math.isfinite(ref) else "n/a")
    return cells


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--plants", nargs="+", default=list(PLANTS), choices=list(PLANTS))
    p.add_argument("--weights", nargs="+", type=float, default=list(WEIGHTS))
    p.add_argument("--seeds", nargs="+", type=int, default=[0])
    p.add_argument("--timesteps", type=int, default=None, help="training budget (default: each scenario's)")
    p.add_argument("--out", type=Path, default=None, help="folder for the run directories (default: temporary)")
    a = p.parse_args(argv)
    out = a.out or Path(tempfile.mkdtemp(prefix="bench_cv_"))
    out.mkdir(parents=True, exist_ok=True)
    weights = sorted(set(a.weights) | {0.0})  # ratios are to weight 0
    sides = [f"{who} {label}" for who in ("fixed", "deployed")
             for label in [lbl for _, lbl in METRICS] + ["Ms", "ISE ÷ w=0", "TV ÷ w=0"]]
    header = ["plant", "seed", "w", *sides, "deployed", "wall s"]
    rows = []
    for plant in a.plants:
        for seed in a.seeds:
            results = {}
            for w in weights:
                results[w] = run(plant, w, seed, out, a.timesteps)
                print(f"done: {plant} w={w:g} seed={seed} wall {results[w][2]:.0f} s", file=sys.stderr, flush=True)
            measured = {w: controllers(run_dir, m) for w, (run_dir, m, _) in results.items()}
            base_fixed, base_deployed, _ = measured[0.0]
            for w in weights:
                (f, f_ms), (d, d_ms), which = measured[w]
                rows.append([plant, str(seed), f"{w:g}", *_cells(f, f_ms, base_fixed[0]),
                             *_cells(d, d_ms, base_deployed[0]), which,
                             "–" if math.isnan(results[w][2]) else f"{results[w][2]:.0f}"])
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print(f"\nrun directories: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
