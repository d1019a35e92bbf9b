"""Issue 8's targets for third-party FMUs, measured on plants the method was not developed on.

    python benchmarks/bench_third_party.py                 # every scenario, seed 0
    python benchmarks/bench_third_party.py --seed 1 --scenarios two_mass_drive motor_noise

The plants are benchmarks/plants/ (Astrom & Hagglund's PID benchmark families and two drivetrains, in
the bundled plants' C format), built into benchmarks/third_party/fmus/ with the project's build layer;
their scenarios are benchmarks/third_party/*.yaml. Each scenario is tuned as `prlpid-fmi tune` does it
(run.tune: fixed-PID search, training around it, schedule, deliverable), one after the other, each
into its own run directory under --out (default: a temporary folder; a run directory that already
holds metrics.json is read, not run again; wall times are the tune's, from its run.json).

Per plant it prints one table, for the fixed PID, the replayed gain schedule and the deployed
controller, measured on the scenario's evaluation, with PASS/FAIL per target of issue 8:
- the deployed controller does not diverge (the episode ends neither early nor diverged);
- it settles after every setpoint step (every step segment has a finite settling time);
- it does not chatter: Chatter <= CHATTER_LIMIT (metrics.chatter_fraction: the share of samples at
  which u reverses direction, both moves above 1 % of the actuator range);
- its ISE is at most 1.0x the fixed PID's;
- the fixed PID does not chatter either.
Nothing here is asserted: it is a measurement.
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import sys
import tempfile
import time
from pathlib import Path

from prlpid_fmi.metrics import overall_metric
from prlpid_fmi.fmu import build_fmu
from prlpid_fmi.run.tune import tune

HERE = Path(__file__).parent
PLANTS = HERE / "plants"
SCENARIOS = HERE / "third_party"
FMU_DIR = SCENARIOS / "fmus"
# "u reversing direction sample after sample": a loop whose actuator reverses (by more than 1 % of its
# range) at more than one sample in 20 over the evaluation chatters. A settled loop, a damped transient
# or noise below 1 % of the range scores about 0; a two-sample limit cycle scores 1.
CHATTER_LIMIT = 0.05
ISE_RATIO_LIMIT = 1.0


def build_plants() -> dict[str, Path]:
    """Build every plant of benchmarks/plants/ into benchmarks/third_party/fmus/ (skipped when current)."""
    names = sorted(p.name for p in PLANTS.iterdir() if (p / "model.yaml").is_file())
    return {name: build_fmu(name, out_dir=FMU_DIR, source_dir=PLANTS / name) for name in names}


def settled_every_step(metrics: dict) -> tuple[bool, float]:
    """(every setpoint-step segment settled, the longest settling time [s]); regulation segments
    (disturbances, no step) have no settling time and do not count. An early end never settles."""
    times = [s["SettlingTime"] for s in metrics["segments"] if not math.isnan(s["SettlingTime"])]
    worst = max(times, default=math.nan)
    return (not metrics.get("terminated")) and all(math.isfinite(t) for t in times), worst


def controller_row(label: str, metrics: dict, fixed: dict, worst_ms, is_deployed: bool, wall: str = "") -> list[str]:
    """One table row: the measured values and PASS/FAIL for the criteria that apply to `label`."""
    overall = metrics["overall"]
    diverged = bool(metrics.get("terminated"))
    settled, worst_settling = settled_every_step(metrics)
    chatter = overall_metric(overall, "Chatter")
    ise, f_ise = overall_metric(overall, "ISE"), overall_metric(fixed["overall"], "ISE")
    ratio = ise / f_ise if f_ise > 0 else math.nan
    verdict = lambda ok: "PASS" if ok else "FAIL"  # noqa: E731
    checks = {
        "diverged": verdict(not diverged) if is_deployed else "",
        "settled": verdict(settled) if is_deployed else "",
        "chatter": verdict(chatter <= CHATTER_LIMIT) if is_deployed or label == "fixed PID" else "",
        "ise": verdict(ratio <= ISE_RATIO_LIMIT) if is_deployed else "",
    }
    return [label,
            f"{'yes' if diverged else 'no'} {checks['diverged']}".strip(),
            f"{'yes' if settled else 'no'} ({worst_settling:.3g} s) {checks['settled']}".strip(),
            f"{overall_metric(overall, 'Overshoot'):.3g}",
            f"{chatter:.3f} {checks['chatter']}".strip(),
            f"{overall_metric(overall, 'TotalVariation'):.4g}",
            f"{ise:.4g}",
            f"{ratio:.3f} {checks['ise']}".strip(),
            "n/a" if worst_ms is None else f"{worst_ms:.3g}",
            wall]


HEADER = ["controller", "diverged?", "settled after every step? (worst settling)", "overshoot %",
          f"Chatter (≤ {CHATTER_LIMIT})", "TV(u)", "ISE", f"ISE ÷ fixed (≤ {ISE_RATIO_LIMIT})", "worst Ms", "wall"]


def plant_table(name: str, m: dict, wall_s: float) -> tuple[list[list[str]], bool]:
    """Rows of one plant's table from its metrics.json, and whether every criterion passed."""
    fixed = m["fixed_pid_assessment"]
    sched = m.get("schedule_replay")
    deployed = m["deployed"]
    rows = [controller_row("fixed PID", fixed["metrics"], fixed["metrics"], fixed["worst_Ms"], False)]
    if sched:
        rows.append(controller_row("gain schedule", sched["metrics"], fixed["metrics"], sched["worst_Ms"], False))
    chosen = {"gain schedule": sched, "fixed PID": fixed}.get(deployed)
    if chosen is None:
        rows.append([f"deployed: {deployed}", "FAIL (nothing deployable)", "", "", "", "", "", "", "", f"{wall_s:.0f} s"])
    else:
        rows.append(controller_row(f"deployed: {deployed}", chosen["metrics"], fixed["metrics"], chosen["worst_Ms"],
                                   True, f"{wall_s:.0f} s"))
    passed = all("FAIL" not in cell for row in rows for cell in row)
    return rows, passed


def tune_wall_s(run_dir: Path) -> float:
    """Wall time of the run's tune [s] from run.json (started, finished; to the second)."""
    info = json.loads((run_dir / "run.json").read_text())
    start, end = (dt.datetime.fromisoformat(info[k]) for k in ("started", "finished"))
    return (end - start).total_seconds()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenarios", nargs="+", default=None,
                   help="names of benchmarks/third_party/*.yaml (default: all)")
    p.add_argument("--seed", type=int, default=0, help="seed of the fixed-PID search and training (default 0)")
    p.add_argument("--timesteps", type=int, default=None, help="training budget (default: the scenario's)")
    p.add_argument("--out", type=Path, default=None, help="folder for the run directories (default: temporary)")
    a = p.parse_args(argv)
    names = a.scenarios or sorted(f.stem for f in SCENARIOS.glob("*.yaml"))
    missing = [n for n in names if not (SCENARIOS / f"{n}.yaml").is_file()]
    if missing:
        print(f"--scenarios: unknown {', '.join(missing)} (expected names of {SCENARIOS}/*.yaml)", file=sys.stderr)
        return 2
    out = a.out or Path(tempfile.mkdtemp(prefix="bench_third_party_"))
    out.mkdir(parents=True, exist_ok=True)
    t_build = time.time()
    build_plants()
    print(f"plants built into {FMU_DIR} in {time.time() - t_build:.1f} s", flush=True)
    summary = []
    t_all = time.time()
    for name in names:
        run_dir = out / f"{name}_seed{a.seed}"
        if not (run_dir / "metrics.json").is_file():
            tune(SCENARIOS / f"{name}.yaml", timesteps=a.timesteps, seed=a.seed, out=run_dir, progress_bar=False)
        wall = tune_wall_s(run_dir)
        m = json.loads((run_dir / "metrics.json").read_text())
        rows, passed = plant_table(name, m, wall)
        print(f"\n#### {name} (seed {a.seed})\n")
        print("| " + " | ".join(HEADER) + " |")
        print("|" + "---|" * len(HEADER))
        for row in rows:
            print("| " + " | ".join(row) + " |")
        print(f"\nrun directory: {run_dir}", flush=True)
        summary.append((name, m["deployed"], passed, wall))
    print("\n#### Summary\n")
    print("| scenario | deployed | every criterion | wall |")
    print("|---|---|---|---|")
    for name, deployed, passed, wall in summary:
        print(f"| {name} | {deployed} | {'PASS' if passed else 'FAIL'} | {wall:.0f} s |")
    print(f"\ntotal wall time {time.time() - t_all:.0f} s; run directories: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
