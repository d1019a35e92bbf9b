"""Full-budget comparison on 1/(s-1) (paper §4.1): PRL-PID (reward forecast N=3 + ERA smoothing)
against PPO-PID (no forecast, no smoothing), same seed, same budget (paper: 500k steps).

Run: python benchmarks/bench_prlpid_vs_ppo.py [--timesteps 500000] [--seeds 0] [--out runs/bench]
Prints ISE, IAE, overshoot (%), 2 % settling time (s) on a servo schedule (0 -> 1 at t = 0,
1 -> -0.5 at t = 10 s), training steps per second, and the PRL/PPO ratios measured in the same run;
a fixed PID tuned by differential evolution on the same training distribution is the reference row.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

from prlpid_fmi.tuning.design_rule import tune_fixed_pid
from prlpid_fmi.config import AgentConfig
from prlpid_fmi.loop.evaluation import constant_gains, evaluate, evaluate_gains, model_policy
from prlpid_fmi.scenario.presets import preset
from prlpid_fmi.tuning.agent import train

VARIANTS = {"PRL-PID": dict(forecast_horizon=3, smoothing="era"),
            "PPO-PID": dict(forecast_horizon=0, smoothing="none")}
COLUMNS = ("ISE", "IAE", "Overshoot", "SettlingTime")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--timesteps", type=int, default=500_000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--out", default="runs/bench_prlpid_vs_ppo")
    args = parser.parse_args()
    base = preset("first_order")
    schedule = dataclasses.replace(base, setpoint_schedule=((0, (1.0,)), (100, (-0.5,))), episode_steps=200)
    rows = []
    for seed in args.seeds:
        for name, strategy in VARIANTS.items():
            config = dataclasses.replace(base, **strategy)
            agent = AgentConfig(total_timesteps=args.timesteps, seed=seed)
            start = time.perf_counter()
            model = train(config, agent, Path(args.out) / f"{name}-seed{seed}")
            elapsed = time.perf_counter() - start
            metrics, _ = evaluate(model_policy(model), dataclasses.replace(schedule, **strategy), seed=seed)
            row = {"variant": name, "seed": seed, "steps_per_s": args.timesteps / elapsed,
                   **{k: metrics["overall"][k] for k in COLUMNS}}
            rows.append(row)
            print(json.dumps(row), flush=True)
    fixed = tune_fixed_pid(base, seed=args.seeds[0])
    metrics, _ = evaluate_gains(constant_gains(*fixed.gains_values()), schedule, seed=args.seeds[0])
    rows.append({"variant": "fixedPID", "seed": args.seeds[0], "steps_per_s": float("nan"),
                 **{k: metrics["overall"][k] for k in COLUMNS}})
    print(json.dumps({**rows[-1], "gains": {k: v.tolist() for k, v in fixed.gains.as_dict().items()}}), flush=True)
    print(f"\n{'variant':<9}{'seed':>5}{'ISE':>9}{'IAE':>9}{'OS %':>8}{'Ts 2% s':>9}{'steps/s':>9}")
    for r in rows:
        print(f"{r['variant']:<9}{r['seed']:>5}{r['ISE']:>9.4f}{r['IAE']:>9.4f}{r['Overshoot']:>8.2f}"
              f"{r['SettlingTime']:>9.2f}{r['steps_per_s']:>9.0f}")
    for seed in args.seeds:
        prl, ppo = (next(r for r in rows if r["variant"] == v and r["seed"] == seed) for v in VARIANTS)
        print(f"seed {seed}: PRL/PPO ratios " + ", ".join(f"{k} {prl[k] / ppo[k]:.3f}" for k in COLUMNS if ppo[k]))


if __name__ == "__main__":
    main()
