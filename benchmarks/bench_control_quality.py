"""Control quality of what `prlpid-fmi tune` delivers: adaptive policy, its replayed gain schedule, the
tuned fixed PID and the deployed controller, over seeds, with ratios to the fixed PID and, for the
linear plants, the physical limit of a saturated one-step deadbeat controller that knows the plant.

    python benchmarks/bench_control_quality.py                      # first_order, time_varying, two_tank; seeds 0 1 2
    python benchmarks/bench_control_quality.py --scenarios first_order --seeds 0 --timesteps 50000   # quick

Each run is an ordinary `tune` run directory (under --out, default a temporary folder), at each
scenario's default budget unless --timesteps is given. Prints one markdown table per scenario and a
summary of the issue's targets (means over seeds). Nothing here is asserted: it is a measurement.

Deadbeat limit (linear plants only): before every sample, the plant's state is saved, the FMU is stepped
with u = 0 and u = 1 from that state to read y(k+1) = A + B*u exactly, the state is restored, and
u = clip((r_k - A) / B) is applied: the output reaches the setpoint in one sample wherever the input
limits allow. Its ISE on the evaluation is a floor no causal sampled controller can beat.
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

import numpy as np
from gymnasium.utils.seeding import np_random

from prlpid_fmi.loop.core import LoopCore
from prlpid_fmi.metrics import overall_metric
from prlpid_fmi.loop.evaluation import Trajectory, measure
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.run.tune import tune
from prlpid_fmi.scenario.load import load_scenario

LINEAR = ("first_order", "first_order_1p5", "time_varying")
COLUMNS = (("ISE", "ISE"), ("IAE", "IAE"), ("Overshoot", "overshoot %"), ("SettlingTime", "settling s"),
           ("TotalVariation", "TV(u)"), ("Chatter", "chatter"))


def deadbeat_ise(scenario) -> float:
    """ISE of the omniscient saturated one-step deadbeat controller on the scenario's evaluation."""
    config = dataclasses.replace(scenario.evaluation_config(), forecast_horizon=0)
    core = LoopCore(config)
    try:
        core.reset(np_random(scenario.evaluation.seed)[0])
        rows = {"setpoint": [list(core.setpoint)], "measurement": [list(core.measurement)], "control": []}
        terminated = False
        for _ in range(config.episode_steps):
            core.begin_step()
            plant = core.plant
            state = plant.get_state()
            y0 = plant.step_values([0.0] * core.n_loops)
            plant.set_state(state)
            y1 = plant.step_values([1.0] * core.n_loops)
            plant.set_state(state)
            u = [min(max((r - a) / (b - a), lo), hi) if b != a else 0.0
                 for r, a, b, lo, hi in zip(core.setpoint, y0, y1, core.u_min, core.u_max)]
            _, terminated = core.step_control(u)
            rows["setpoint"].append(list(core.setpoint))
            rows["measurement"].append(list(core.measurement))
            rows["control"].append(list(core.control_signal))
            if terminated:
                break
    finally:
        core.close()
    n = len(rows["control"])
    traj = Trajectory(time_s=np.arange(n + 1) * config.sample_time_s, setpoint=np.array(rows["setpoint"]),
                      measurement=np.array(rows["measurement"]),
                      control_signal=np.array(rows["control"] + rows["control"][-1:]),
                      pid_output=np.array(rows["control"]), reward=np.zeros(n), gains={}, terminated=terminated,
                      termination=core.termination if terminated else None)
    return overall_metric(measure(traj, config)["overall"], "ISE")


def _row(name: str, overall: dict, ms, fixed: dict, floor: float | None) -> list[str]:
    cells = [name]
    for key, _ in COLUMNS:
        cells.append(f"{overall_metric(overall, key):.4g}")
    cells.append("n/a" if ms is None else f"{ms:.3g}")
    f_ise, ise = overall_metric(fixed, "ISE"), overall_metric(overall, "ISE")
    cells.append(f"{ise / f_ise:.3f}")
    cells.append(f"{overall_metric(overall, 'Overshoot') / overall_metric(fixed, 'Overshoot'):.3f}"
                 if overall_metric(fixed, "Overshoot") > 0 else "n/a")
    cells.append(f"{overall_metric(overall, 'TotalVariation') / overall_metric(fixed, 'TotalVariation'):.3f}")
    if floor is not None:
        excess, f_excess = ise - floor, f_ise - floor
        cells.append(f"{excess:.4g} ({excess / f_excess:.2f}x)" if f_excess > 0 else f"{excess:.4g}")
    return cells


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenarios", nargs="+", default=["first_order", "time_varying", "two_tank"])
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("--timesteps", type=int, default=None, help="training budget (default: the scenario's)")
    p.add_argument("--out", type=Path, default=None, help="folder for the run directories (default: temporary)")
    a = p.parse_args(argv)
    out = a.out or Path(tempfile.mkdtemp(prefix="bench_cq_"))
    out.mkdir(parents=True, exist_ok=True)
    summary = []
    for name in a.scenarios:
        scenario = load_scenario(scenario_path(name))
        floor = deadbeat_ise(scenario) if name in LINEAR else None
        header = ["seed / controller", *[label for _, label in COLUMNS], "worst Ms", "ISE ÷ fixed",
                  "overshoot ÷ fixed", "TV ÷ fixed"] + (["excess ISE over deadbeat (÷ fixed's)"] if floor else [])
        print(f"\n### {name}" + (f" (deadbeat ISE floor {floor:.4g})" if floor is not None else "") + "\n")
        print("| " + " | ".join(header) + " |")
        print("|" + "---|" * len(header))
        per_seed = []
        for seed in a.seeds:
            run_dir = out / f"{name}_seed{seed}"
            t0 = time.time()
            if not (run_dir / "metrics.json").is_file():
                tune(scenario_path(name), timesteps=a.timesteps, seed=seed, out=run_dir, progress_bar=False)
            wall = time.time() - t0
            m = json.loads((run_dir / "metrics.json").read_text())
            fixed = m["fixed_pid_assessment"]["metrics"]["overall"]
            sched = m.get("schedule_replay") or None
            rows = [("policy", m["policy"]["overall"], None),
                    ("schedule", sched["metrics"]["overall"] if sched else None, sched["worst_Ms"] if sched else None),
                    ("fixed PID", fixed, m["fixed_pid_assessment"]["worst_Ms"])]
            deployed = {"gain schedule": rows[1], "fixed PID": rows[2]}.get(m["deployed"])
            for label, overall, ms in rows:
                if overall is not None:
                    print("| " + " | ".join(_row(f"{seed} {label}", overall, ms, fixed, floor)) + " |")
            print(f"| {seed} deployed: {m['deployed']} | wall {wall:.0f} s |" + " |" * (len(header) - 2))
            per_seed.append((sched, fixed, deployed))
        scheds = [s for s, _, _ in per_seed if s]
        if scheds:
            mean = lambda xs: sum(xs) / len(xs)  # noqa: E731
            ise_ratio = mean([overall_metric(s["metrics"]["overall"], "ISE") / overall_metric(f, "ISE")
                              for s, f, _ in per_seed if s])
            os_ratio = mean([overall_metric(s["metrics"]["overall"], "Overshoot") / overall_metric(f, "Overshoot")
                             for s, f, _ in per_seed if s and overall_metric(f, "Overshoot") > 0] or [math.nan])
            tv_ratio = mean([overall_metric(s["metrics"]["overall"], "TotalVariation")
                             / overall_metric(f, "TotalVariation") for s, f, _ in per_seed if s])
            measured = [s["worst_Ms"] for s in scheds if s["worst_Ms"] is not None]  # None: not verified
            worst_ms = max(measured) if measured else math.nan
            summary.append((name, ise_ratio, os_ratio, tv_ratio, worst_ms, len(scheds)))
    print("\n### Targets (schedule replayed as a plain PID, means over seeds)\n")
    print("| scenario | ISE ÷ fixed (≤ 1.0; two_tank ≤ 0.8) | overshoot ÷ fixed (≤ 0.5) | TV ÷ fixed (≤ 1.5) "
          "| worst Ms (≤ 2.0) | seeds |")
    print("|---|---|---|---|---|---|")
    for name, ise, os_, tv, ms, n in summary:
        ms_text = "not verified" if math.isnan(ms) else f"{ms:.3g}"
        print(f"| {name} | {ise:.3f} | {os_:.3f} | {tv:.3f} | {ms_text} | {n} |")
    print(f"\nrun directories: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
