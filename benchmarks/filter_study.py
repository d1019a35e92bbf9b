"""What a run's fixed PID would do with other measurement-filter time constants Tf (the gains, b and c kept).

For issue 23's exothermic reactor: the load design chose a long Tf to meet deploy.max_noise_gain, and the deployed
loop runs away on large setpoint steps. For each Tf this prints, from the FMU:

- J_load, the load design's cost (noise-free load steps at the low end, middle and high end of the setpoint range,
  tuning.load_experiment.load_experiment), and the worst chatter of those experiments;
- Ms at NUMBER points evenly spaced over the setpoint range (robustness.margins.margins_of);
- std(u) from the scenario's measurement noise as a fraction of the span, estimated as the design does
  (robustness.plant_response.MeasuredPlant.noise_gains on the response measured at each point), worst point;
- the replay of the PID on the scenario's evaluation and on a held-out evaluation file: ISE, TV, overshoot,
  chatter and the largest measurement.

    python benchmarks/filter_study.py RUN_DIR SCENARIO [--heldout FILE] [--tf 30 10] [--points 5]

RUN_DIR: a `tune` run directory (its fixed_pid.csv); SCENARIO: the scenario it was tuned on (for its FMU path).
"""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from prlpid_fmi.loop.evaluation import constant_gains, gains_rollout
from prlpid_fmi.metrics import chatter_fraction
from prlpid_fmi.robustness.margins import margins_of, operating_point, pid_frequency_response
from prlpid_fmi.robustness.plant_response import MeasuredPlant
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.tuning.load_experiment import load_experiment
from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv
from prlpid_fmi.tuning.schedule.replay import replay_schedule


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("scenario")
    ap.add_argument("--heldout", help="a scenario file whose evaluation is replayed too")
    ap.add_argument("--tf", type=float, nargs="*", default=[30.0, 10.0], help="Tf values [s] beside the run's")
    ap.add_argument("--points", type=int, default=5, help="operating points for Ms and the noise estimate")
    args = ap.parse_args()
    fixed = read_schedule_csv(args.run_dir / "fixed_pid.csv")
    scenario = load_scenario(args.scenario)
    base = scenario.tuning
    Kp, Ti, Td = (float(np.ravel(a)[0]) for a in (fixed.Kp, fixed.Ti, fixed.Td))
    b, c = float(fixed.setpoint_weight[0]), float(fixed.derivative_weight[0])
    loop = base.loops[0]
    span = loop.u_max - loop.u_min
    lo, hi = loop.setpoint_range
    points = [operating_point(base, v) for v in np.linspace(lo, hi, args.points)]
    evaluations = [("evaluation", scenario)] + ([("held-out", load_scenario(args.heldout))] if args.heldout else [])
    print(f"Kp {Kp:.4g}, Ti {Ti:.4g} s, Td {Td:.4g} s, b {b:g}, c {c:g}; noise std {base.measurement_noise_std:g}")
    header = ["Tf s", "J_load", "load chatter", "worst Ms", "worst std(u)/span"]
    for label, _ in evaluations:
        header += [f"{label} {k}" for k in ("ISE", "TV", "overshoot %", "chatter", "max y")]
    print("| " + " | ".join(header) + " |\n|" + "---|" * len(header))
    for tf in [float(fixed.measurement_filter_s[0])] + list(args.tf):
        config = dataclasses.replace(base, tuned_structure=((b, c, tf),), forecast_horizon=0)
        gains = ([Kp], [Ti], [Td], None)
        chatter = []

        def run(cfg):
            traj = gains_rollout(constant_gains([Kp], [Ti], [Td]), cfg, seed=0)
            if not traj.terminated:
                chatter.append(chatter_fraction(traj.pid_output[cfg.setpoint_hold_steps:, 0], span))
            return traj
        j_load = load_experiment(config, scenario.baseline.load_step, run)
        ms, noise = [], []
        for p in points:
            m = margins_of(config, gains, p)
            ms.append(m.Ms)
            if len(m.frequencies_rad_s) >= 2 and np.all(np.isfinite(m.plant_response)):
                plant = MeasuredPlant(m.frequencies_rad_s, m.plant_response, base.sample_time_s, tuple(p), ())
                C = lambda w: pid_frequency_response(Kp, Ti, Td, base.sample_time_s, w, base.derivative_filter_N, tf,
                                                     base.measurement_filter_order)
                noise.append(base.measurement_noise_std * plant.noise_gains(C)[0] / span)
        row = [f"{tf:.3g}", f"{j_load:.4g}", f"{max(chatter, default=float('nan')):.3f}", f"{max(ms):.3g}",
               f"{max(noise, default=float('nan')):.4f}"]
        for _, sc in evaluations:
            schedule = dataclasses.replace(fixed, measurement_filter_s=np.array([tf]))
            metrics, traj = replay_schedule(schedule, sc.evaluation_config(), seed=sc.agent.seed)
            overall = metrics.get("overall", metrics)
            row += [f"{float(np.ravel(overall[k])[0]):.4g}" for k in ("ISE", "TotalVariation", "Overshoot", "Chatter")]
            row.append(f"{float(np.nanmax(traj.measurement[:, 0])):.4g}")
        print("| " + " | ".join(row) + " |", flush=True)


if __name__ == "__main__":
    main()
