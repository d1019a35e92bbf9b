"""Settled-setpoint vs error-trajectory gain schedules of trained runs (docs/results.md "Error-scheduled gains").

For each run directory made by `prlpid-fmi tune` (its model.zip, scenario.yaml, fixed_pid.json), both
candidate tables are re-extracted from the saved policy exactly as `tune` builds them
(prlpid_fmi.tuning.schedule.extraction.extract + assess.robust_schedule), scored on the seeded training-distribution
episodes `deploy.schedule_by: auto` uses, and assessed like the deliverable (assess.assess_schedule:
evaluation + Monte-Carlo set + margins). Prints one markdown table: ISE and total variation of u as
ratios to the fixed PID on the run's evaluation, worst Ms, training-episode ISE, and auto's pick.
For error tables also their gains at e = 0 held as a constant PID (what the table does at rest): the
difference to the table is what its variation with the error buys.

--abs-error adds a table binned by |error| (the same samples, K bins of |e|), written as the
mirrored signed-error table g(|e|) (breakpoints -m..., +m...): linear interpolation in e on each side
equals interpolation in |e|, so it replays exactly as an |error| table would. It measures whether the
sign of the error carries information (docs/results.md "Error-scheduled gains").

    python benchmarks/bench_error_schedule.py RUN_DIR [RUN_DIR ...] [--points 9] [--abs-error]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

from prlpid_fmi.loop.gains import gains_from_values
from prlpid_fmi.deliver.evidence import assess_fixed, assess_schedule, max_sensitivity
from prlpid_fmi.deliver.candidates import robust_schedule
from prlpid_fmi.run.state import load_policy, load_trained, read_fixed_pid, run_anchor
from prlpid_fmi.tuning.schedule.table import schedule_from_rows
from prlpid_fmi.tuning.schedule.trajectories import TRAJECTORY_EPISODES, bin_rows, trajectory_samples
from prlpid_fmi.tuning.schedule.extraction import extract
from prlpid_fmi.tuning.schedule.replay import training_ise


def abs_error_table(policy, config, points: int, seed: int, anchor):
    """The |error|-binned table as a mirrored error[<loop 0>] table (see the module docstring)."""
    variable = f"error[{config.loops[0].output}]"
    values, gains, unit, meta = trajectory_samples(policy, config, variable, TRAJECTORY_EPISODES, seed, anchor)
    rows = bin_rows(abs(values), gains, points)
    mirrored = [(-v, g) for v, g in rows if v > 0] + rows
    return schedule_from_rows(config, variable, unit, mirrored, meta)


def _row(run: Path, kind: str, cand, fixed, train_ise: float | None, wall: float) -> str:
    ise, tv = cand.overall("ISE"), cand.overall("TotalVariation")
    f_ise, f_tv = fixed.overall("ISE"), fixed.overall("TotalVariation")
    ms = "n/a" if math.isnan(cand.worst_Ms) else f"{cand.worst_Ms:.2f}"
    train = "" if train_ise is None else f"{train_ise:.4g}"
    return (f"| {run.name} | {kind} | {ise:.4g} | {ise / f_ise:.3f} | {tv / f_tv:.3f} | {ms} | {cand.score:.4g} | "
            f"{train} | {wall:.0f} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--points", type=int, default=None, help="rows per table (default: the scenario's schedule_points)")
    p.add_argument("--abs-error", action="store_true", help="also a table binned by |error| (mirrored)")
    args = p.parse_args(argv)
    print("| run | controller | ISE | ISE ÷ fixed | TV ÷ fixed | worst Ms | score (eval + MC mean ISE) | "
          "training-episode ISE | wall s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for run in args.runs:
        scenario = load_trained(run)
        design = read_fixed_pid(run)
        policy = load_policy(run, scenario.agent.algorithm)
        anchor, seed = run_anchor(run, scenario, design), scenario.agent.seed
        points = args.points or scenario.deploy.schedule_points
        limit = max_sensitivity(scenario)
        t0 = time.time()
        fixed = assess_fixed(scenario, design.gains)
        print(_row(run, "fixed PID", fixed, fixed, None, time.time() - t0))
        scores = {}
        for kind in ("setpoint", "error") + (("abs(error)",) if args.abs_error else ()):
            t0 = time.time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                schedule = abs_error_table(policy, scenario.tuning, points, seed, anchor) if kind == "abs(error)" \
                    else extract(policy, scenario.tuning, kind, points, seed, anchor)
                schedule, _ = robust_schedule(schedule, scenario.tuning, limit)
                scores[kind] = training_ise(schedule, scenario.tuning, seed)
                cand = assess_schedule(scenario, schedule)
            print(_row(run, f"{kind} ({len(schedule.breakpoints)} rows)", cand, fixed, scores[kind],
                       time.time() - t0))
            if kind != "setpoint":  # does the table's variation matter, or only its steady-state gains?
                t0 = time.time()
                held = assess_fixed(scenario, gains_from_values(*[g.tolist() for g in schedule.gains_at(0.0)], None))
                print(_row(run, f"{kind}: its e = 0 gains held constant", held, fixed, None, time.time() - t0))
            sys.stdout.flush()
        auto = {k: v for k, v in scores.items() if k != "abs(error)"}
        print(f"| {run.name} | auto picks: {min(auto, key=auto.get)} | | | | | | | |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
