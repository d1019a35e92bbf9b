"""Environment steps per second for each paper scenario with the reward forecast off and on.

Run: python benchmarks/bench_env_steps.py [--steps N]
The ratio column is the cost of the forecast (N prior steps + N PID steps + N rewards per env step)
relative to N = 0, measured in the same run.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import prlpid_fmi
from prlpid_fmi.scenario.presets import PRESET_NAMES


def steps_per_s(name: str, horizon: int, steps: int) -> float:
    env = prlpid_fmi.make_env(name, forecast_horizon=horizon)
    action = np.zeros(env.action_space.shape, np.float32)
    env.reset(seed=0)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=5000)
    args = parser.parse_args()
    horizons = (0, 1, 3, 10)
    print(f"{'scenario':<18}" + "".join(f"{f'N={h}':>10}" for h in horizons) + f"{'N=3 / N=0':>11}")
    for name in PRESET_NAMES:
        rates = [steps_per_s(name, h, args.steps) for h in horizons]
        print(f"{name:<18}" + "".join(f"{r:>10.0f}" for r in rates) + f"{rates[2] / rates[0]:>11.2f}")


if __name__ == "__main__":
    main()
