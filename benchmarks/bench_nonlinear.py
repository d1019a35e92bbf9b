"""Issue 23's nonlinear benchmark: fixed PID, classical gain schedule, adaptive schedule and the deployed controller
on plants whose gain varies strongly over their setpoint range, on the evaluation and on held-out episodes.

    python benchmarks/bench_nonlinear.py                                   # every plant, seeds 0 1 2, full budget
    python benchmarks/bench_nonlinear.py --plants ph_neutralization --seeds 0 --timesteps 2000 --out /tmp/nl

Plants: two_tank (scenarios/two_tank.yaml, the bundled TwoTank FMU) and the nonlinear plants of
benchmarks/plants/ (PhNeutralization, ExothermicCSTR, ConicalTank; built into benchmarks/scenarios/fmus/ with the
project's build layer) with their scenarios benchmarks/scenarios/<plant>.yaml. Each (plant, seed) is one ordinary
`prlpid-fmi tune SCENARIO --seed S [--timesteps N] --out RUN` in a subprocess, one after the other (a run directory
that already holds metrics.json is read, not run again), then `prlpid-fmi evaluate RUN --scenario HELDOUT` on the
held-out schedule benchmarks/scenarios/heldout/<plant>.yaml (other setpoint steps, loads and noise seed; a file
holding only an `evaluation:` section; where `evaluate` does not take such a file yet, a full copy of the scenario
with that evaluation is used instead, and the output says so).

Everything in the tables is read from the run directories, not recomputed: metrics.json's
`fixed_pid_assessment` (the fixed PID replayed on the evaluation, its margins at the low end, middle and high
end of the range), `schedule_replay` (the adaptive policy's gain table replayed as a plain PID, its margins at
every breakpoint), a classical gain schedule where the run's metrics.json has one (a key or candidate whose name
contains "classical"; "not available" otherwise), `policy` (the neural policy itself), `deployed` (the word of
the choice); and the held-out evaluation's metrics.json (`fixed_pid`, `policy`, `deployed_schedule`, and a
classical and adaptive tables' entries, which `evaluate` replays from classical_schedule.csv and
adaptive_schedule.csv). A candidate the run did not produce or did not write is "not available".

Columns: ISE and its ratio to the fixed PID of the same run and schedule; worst overshoot over the setpoint steps
[%] (the staircase's steps: the first segment, from the FMU's start state to the first setpoint, is not one);
setpoint steps settled (SettlingTime finite) out of those in the schedule, and the longest settling time;
TV = total variation of u and its ratio to the fixed PID's; Chatter = share of samples where u reverses by more
than 1 % of its range (metrics.chatter_fraction); worst Ms over the margin estimates the run made (the same on
held-out episodes: the controller is the same). A second table gives the settling time of every setpoint step.
The targets table applies the issue's targets to the deployed controller (plants with >= 10x steady-state gain
variation: ISE <= 0.5x, every step settled, overshoot <= 25 %, chatter <= 5 %, TV <= 1.5x, Ms <= 2; two_tank on
held-out episodes: ISE <= 0.8x, TV <= 1.5x, every step settled), per seed. Nothing is asserted: it is a
measurement.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
PLANTS = HERE / "plants"
SCENARIOS = HERE / "scenarios"
HELDOUT = SCENARIOS / "heldout"
FMU_DIR = SCENARIOS / "fmus"

# plant -> (scenario file, benchmarks/plants model to build or None for a bundled plant, steady-state gain
# variation over the setpoint range from tests/test_nonlinear_plants.py (None: below 10x), its note)
PLANT_SET = {
    "two_tank": (REPO / "scenarios" / "two_tank.yaml", None, None, "h2 ~ q^2: static gain x1.7 over 5-15 cm"),
    "ph_neutralization": (SCENARIOS / "ph_neutralization.yaml", "PhNeutralization", 42.0, "d pH/d F_b x42 over pH 4-7"),
    "exothermic_cstr": (SCENARIOS / "exothermic_cstr.yaml", "ExothermicCSTR", math.inf,
                        "dT/dT_c from 1.3 through infinity, negative on the unstable branch"),
    "conical_tank": (SCENARIOS / "conical_tank.yaml", "ConicalTank", None,
                     "static gain x2 (sqrt h), time constant x22 over 15-60 cm"),
}
SEEDS = (0, 1, 2)
NA = "not available"
ISE_TARGET, ISE_TARGET_TWO_TANK, TV_TARGET, OVERSHOOT_TARGET, CHATTER_TARGET, MS_TARGET = 0.5, 0.8, 1.5, 25.0, 0.05, 2.0


def cli() -> list[str]:
    """The prlpid-fmi command of this interpreter's environment."""
    exe = Path(sys.executable).with_name("prlpid-fmi")
    return [str(exe)] if exe.is_file() else [sys.executable, "-m", "prlpid_fmi"]


def build_plants(names) -> None:
    from prlpid_fmi.fmu import build_fmu

    for name in names:
        model = PLANT_SET[name][1]
        if model is not None:
            build_fmu(model, out_dir=FMU_DIR, source_dir=PLANTS / model)


# ------------------------------------------------------------------------------------------------ runs

def run_tune(name: str, seed: int, out: Path, timesteps: int | None) -> tuple[Path, float | None]:
    """The run directory of (plant, seed), tuned in a subprocess unless it has finished already; wall time [s]."""
    run_dir = out / f"{name}_seed{seed}"
    if (run_dir / "metrics.json").is_file() and "finished" in json.loads((run_dir / "run.json").read_text()):
        return run_dir, None
    if run_dir.exists():   # an unfinished earlier attempt: keep it for inspection, start anew
        run_dir.rename(run_dir.with_name(f"{run_dir.name}.unfinished-{int(time.time())}"))
    cmd = cli() + ["tune", str(PLANT_SET[name][0]), "--seed", str(seed), "--out", str(run_dir), "--no-progress"]
    if timesteps is not None:
        cmd += ["--timesteps", str(timesteps)]
    t0 = time.time()
    print("$ " + " ".join(cmd), flush=True)
    proc = subprocess.run(cmd, check=False, cwd=REPO, capture_output=True, text=True)
    if proc.returncode != 0:
        print(proc.stdout[-2000:] + proc.stderr[-4000:], file=sys.stderr)
        raise RuntimeError(f"tune failed for {name} seed {seed} (exit {proc.returncode})")
    return run_dir, time.time() - t0


def heldout_file(name: str, out: Path, full_copy: bool) -> Path:
    """The held-out evaluation file: benchmarks/scenarios/heldout/<name>.yaml, or (full_copy) the plant's scenario
    with that evaluation, written into out/ with the FMU path made absolute."""
    path = HELDOUT / f"{name}.yaml"
    if not full_copy:
        return path
    scenario = yaml.safe_load(PLANT_SET[name][0].read_text())
    scenario = copy.deepcopy(scenario)
    scenario["evaluation"] = yaml.safe_load(path.read_text())["evaluation"]
    fmu = scenario["plant"]["fmu"]
    if fmu.endswith(".fmu") and not Path(fmu).is_absolute():
        scenario["plant"]["fmu"] = str((PLANT_SET[name][0].parent / fmu).resolve())
    scenario["name"] = f"{scenario.get('name', name)}_heldout"
    target = out / f"{name}_heldout.yaml"
    target.write_text(yaml.safe_dump(scenario, sort_keys=False))
    return target


def run_heldout(name: str, run_dir: Path, out: Path) -> tuple[dict | None, str]:
    """The held-out evaluation's metrics.json (run again unless recorded in run_dir/heldout.json) and a note."""
    record = run_dir / "bench_heldout.json"
    if record.is_file():
        info = json.loads(record.read_text())
        return json.loads(Path(info["metrics"]).read_text()), info["note"]
    note = ""
    for full_copy in (False, True):
        cmd = cli() + ["evaluate", str(run_dir), "--scenario", str(heldout_file(name, out, full_copy)), "-q"]
        print("$ " + " ".join(cmd), flush=True)
        proc = subprocess.run(cmd, check=False, cwd=REPO, capture_output=True, text=True)
        if proc.returncode == 0:
            break
        if full_copy:
            print(proc.stdout[-2000:] + proc.stderr[-2000:], file=sys.stderr)
            return None, "held-out evaluation failed"
        note = "evaluate does not take an evaluation-only file: held-out via a full scenario copy"
    evaluations = run_dir / "evaluations"
    latest = max((p for p in evaluations.iterdir() if p.name.isdigit()), key=lambda p: int(p.name))
    record.write_text(json.dumps({"metrics": str(latest / "metrics.json"), "note": note}))
    return json.loads((latest / "metrics.json").read_text()), note


# --------------------------------------------------------------------------------------- candidates

def _classical(m: dict) -> dict | None:
    """A classical gain schedule's entry in a metrics.json, wherever the tool puts it (None: absent)."""
    for key, value in m.items():
        if "classical" in key.lower() and isinstance(value, dict):
            return value
    for value in m.get("candidates", []) if isinstance(m.get("candidates"), list) else []:
        if isinstance(value, dict) and "classical" in str(value.get("name", "")).lower():
            return value
    return None


def _metrics_of(entry) -> dict | None:
    """compute_metrics' dict of a candidate entry ({"metrics": ...} or the metrics themselves)."""
    if not isinstance(entry, dict):
        return None
    inner = entry.get("metrics", entry)
    return inner if isinstance(inner, dict) and "overall" in inner else None


def _ms(entry) -> float | None:
    value = entry.get("worst_Ms") if isinstance(entry, dict) else None
    return float(value) if isinstance(value, (int, float)) else None


def evaluation_candidates(m: dict) -> dict[str, tuple[dict | None, float | None]]:
    """label -> (metrics, worst Ms) on the run's evaluation."""
    fixed = m.get("fixed_pid_assessment") or m.get("fixed_pid") or {}
    sched = m.get("schedule_replay")
    classical = _classical(m)
    out = {"fixed PID": (_metrics_of(fixed), _ms(fixed)),
           "classical schedule": (_metrics_of(classical), _ms(classical)),
           "adaptive schedule": (_metrics_of(sched), _ms(sched)),
           "adaptive policy (NN)": (_metrics_of(m.get("policy")), None)}
    out["deployed"] = deployed_entry(m.get("deployed"), out)
    return out


def deployed_entry(word, candidates: dict) -> tuple[dict | None, float | None]:
    word = str(word or "").lower()
    if "classical" in word:
        return candidates["classical schedule"]
    if word == "gain schedule" or "adaptive" in word:
        return candidates["adaptive schedule"]
    if word == "fixed pid":
        return candidates["fixed PID"]
    return None, None


def heldout_candidates(h: dict | None, evaluation: dict) -> dict[str, tuple[dict | None, float | None]]:
    """label -> (metrics, worst Ms) on the held-out schedule (Ms: the run's, the controller is the same)."""
    if h is None:
        return {k: (None, None) for k in evaluation}
    deployed = str(h.get("deployed") or "").lower()
    classical = _classical(h)
    sched = h.get("adaptive_schedule") or (h.get("deployed_schedule") if deployed == "gain schedule" else None)
    out = {"fixed PID": (_metrics_of(h.get("fixed_pid")), evaluation["fixed PID"][1]),
           "classical schedule": (_metrics_of(classical), evaluation["classical schedule"][1]),
           "adaptive schedule": (_metrics_of(sched), evaluation["adaptive schedule"][1]),
           "adaptive policy (NN)": (_metrics_of(h.get("policy")), None)}
    out["deployed"] = deployed_entry(deployed, out)
    return out


# ------------------------------------------------------------------------------------------- tables

def _overall(metrics: dict, key: str) -> float:
    from prlpid_fmi.metrics import overall_metric

    return overall_metric(metrics["overall"], key)


def step_segments(metrics: dict) -> list[dict]:
    """The segments of the schedule's setpoint steps: those that start at a setpoint change (start_step > 0; the first
    segment, the FMU's start state approaching the first setpoint, is not a step of the staircase: on the pH plant
    a 0.07 pH offset whose 55 % "overshoot" is 0.04 pH) and have step metrics (not regulation segments)."""
    return [s for s in metrics["segments"] if s["start_step"] > 0 and not math.isnan(s["SettlingTime"])]


def step_settling(metrics: dict) -> list[float]:
    """Settling time [s] of every setpoint step (inf: never; an early end leaves the rest unsettled)."""
    return [s["SettlingTime"] for s in step_segments(metrics)]


def worst_overshoot(metrics: dict) -> float:
    """The largest overshoot [%] over the setpoint steps (NaN: no step)."""
    return max((s["Overshoot"] for s in step_segments(metrics)), default=math.nan)


def _fmt(x, nd=3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return f"{x:.{nd}g}"


def row(metrics: dict | None, ms: float | None, fixed: dict | None) -> list[str]:
    """ISE, ISE ratio, overshoot, settled, TV, TV ratio, chatter, Ms cells of one candidate."""
    if metrics is None:
        return [NA] + [""] * 7
    ise, tv = _overall(metrics, "ISE"), _overall(metrics, "TotalVariation")
    f_ise = _overall(fixed, "ISE") if fixed else math.nan
    f_tv = _overall(fixed, "TotalVariation") if fixed else math.nan
    times = step_settling(metrics)
    settled = sum(math.isfinite(t) for t in times) if not metrics.get("terminated") else 0
    worst = max(times, default=math.nan)
    return [_fmt(ise, 4), _fmt(ise / f_ise if f_ise > 0 else math.nan),
            _fmt(worst_overshoot(metrics)), f"{settled}/{len(times)} ({_fmt(worst)} s)"
            + (" diverged" if metrics.get("terminated") else ""),
            _fmt(tv, 4), _fmt(tv / f_tv if f_tv > 0 else math.nan), _fmt(_overall(metrics, "Chatter")), _fmt(ms)]


def markdown(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


HEADER = ["plant", "seed", "controller", "ISE", "÷ fixed", "overshoot %", "steps settled (worst)", "TV(u)", "TV ÷ fixed",
          "Chatter", "worst Ms"]


def targets(name: str, seed: int, ev: dict, ho: dict) -> list[str]:
    """The issue's targets for the deployed controller of one run."""
    variation = PLANT_SET[name][2]
    d_ev, ms = ev["deployed"]
    d_ho, _ = ho["deployed"]
    f_ev, f_ho = ev["fixed PID"][0], ho["fixed PID"][0]

    def ok(flag):
        return "n/a" if flag is None else ("met" if flag else "**missed**")

    def ratio(m, f, key):
        return _overall(m, key) / _overall(f, key) if m and f and _overall(f, key) > 0 else None

    def settled(m):
        return None if m is None else (not m.get("terminated") and all(math.isfinite(t) for t in step_settling(m)))

    if name == "two_tank":
        r_ise, r_tv = ratio(d_ho, f_ho, "ISE"), ratio(d_ho, f_ho, "TotalVariation")
        cells = [f"held-out ISE {_fmt(r_ise)}x (<= {ISE_TARGET_TWO_TANK}): "
                 + ok(None if r_ise is None else r_ise <= ISE_TARGET_TWO_TANK),
                 f"held-out TV {_fmt(r_tv)}x (<= {TV_TARGET}): " + ok(None if r_tv is None else r_tv <= TV_TARGET),
                 "held-out settled: " + ok(settled(d_ho)), "", "", ""]
    elif variation is None:
        cells = [f"gain variation below 10x ({PLANT_SET[name][3]}): targets do not apply"] + [""] * 5
    else:
        r_ise, r_tv = ratio(d_ev, f_ev, "ISE"), ratio(d_ev, f_ev, "TotalVariation")
        over = worst_overshoot(d_ev) if d_ev else None
        chat = _overall(d_ev, "Chatter") if d_ev else None
        cells = [f"ISE {_fmt(r_ise)}x (<= {ISE_TARGET}): " + ok(None if r_ise is None else r_ise <= ISE_TARGET),
                 f"TV {_fmt(r_tv)}x (<= {TV_TARGET}): " + ok(None if r_tv is None else r_tv <= TV_TARGET),
                 "settled: " + ok(settled(d_ev)),
                 f"overshoot {_fmt(over)} % (<= {OVERSHOOT_TARGET:g}): " + ok(None if over is None else over <= OVERSHOOT_TARGET),
                 f"chatter {_fmt(chat)} (<= {CHATTER_TARGET}): " + ok(None if chat is None else chat <= CHATTER_TARGET),
                 f"Ms {_fmt(ms)} (<= {MS_TARGET:g}): " + ok(None if ms is None else ms <= MS_TARGET)]
    return [name, str(seed)] + cells


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--plants", nargs="+", default=list(PLANT_SET), choices=list(PLANT_SET))
    p.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS), help="seeds of tune (default 0 1 2)")
    p.add_argument("--timesteps", type=int, default=None, help="training budget (default: each scenario's)")
    p.add_argument("--out", type=Path, default=None, help="folder for the run directories (default: temporary)")
    a = p.parse_args(argv)
    out = (a.out or Path(tempfile.mkdtemp(prefix="bench_nonlinear_"))).resolve()
    out.mkdir(parents=True, exist_ok=True)
    t_all = time.time()
    build_plants(a.plants)
    sys.path.insert(0, str(HERE))
    from bench_pid_design import (
        code_fingerprint,  # HEAD and the hash of the package code, one definition
    )

    fingerprint = code_fingerprint()   # of the code the runs below import
    results, notes = [], []
    for name in a.plants:
        for seed in a.seeds:
            run_dir, wall = run_tune(name, seed, out, a.timesteps)
            m = json.loads((run_dir / "metrics.json").read_text())
            h, note = run_heldout(name, run_dir, out)
            ev = evaluation_candidates(m)
            ho = heldout_candidates(h, ev)
            results.append((name, seed, run_dir, m, ev, ho))
            info = json.loads((run_dir / "run.json").read_text())
            notes.append(f"- {name} seed {seed}: {run_dir} ({info.get('trained_timesteps', '?')} training steps"
                         + (f", tune {wall:.0f} s" if wall is not None else ", read back")
                         + f"); deployed: {m.get('deployed', NA)}" + (f"; {note}" if note else ""))
    print()
    print(f"# Nonlinear plants (issue 23): {', '.join(a.plants)}; seeds {' '.join(map(str, a.seeds))}; "
          "training budget " + (f"{a.timesteps} steps" if a.timesteps is not None else "each scenario's"))
    print(fingerprint)
    print()
    for label, which in (("On the evaluation", 4), ("On held-out episodes (benchmarks/scenarios/heldout/)", 5)):
        rows = []
        for res in results:
            name, seed, cands = res[0], res[1], res[which]
            fixed = cands["fixed PID"][0]
            for cand, (metrics, ms) in cands.items():
                word = f" ({res[3].get('deployed', NA)})" if cand == "deployed" else ""
                rows.append([name, str(seed), cand + word] + row(metrics, ms, fixed))
        print(f"## {label}\n")
        print(markdown(HEADER, rows))
        print()
    print("## Settling time per setpoint step [s] (inf: never settled)\n")
    rows = []
    for name, seed, _, _, ev, ho in results:
        for where, cands in (("evaluation", ev), ("held-out", ho)):
            for cand, (metrics, _) in cands.items():
                rows.append([name, str(seed), where, cand,
                             NA if metrics is None else ", ".join(_fmt(t) for t in step_settling(metrics))])
    print(markdown(["plant", "seed", "schedule", "controller", "settling per step"], rows))
    print()
    print("## Targets of issue 23 (deployed controller)\n")
    print(markdown(["plant", "seed", "ISE", "TV", "settled", "overshoot", "chatter", "Ms"],
                   [targets(name, seed, ev, ho) for name, seed, _, _, ev, ho in results]))
    print()
    print("Steady-state gain variation over each setpoint range (tests/test_nonlinear_plants.py): "
          + "; ".join(f"{n}: {PLANT_SET[n][3]}" for n in a.plants))
    print("\n".join(notes))
    print(f"total wall time {time.time() - t_all:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
