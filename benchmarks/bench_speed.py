"""Speed of PidTuningEnv beside its numpy twin and FMUGym, training throughput, a full run, memory (issue 7).

Run:  python benchmarks/bench_speed.py            (full table, a few minutes)
      python benchmarks/bench_speed.py --quick    (same table, fewer repeats and steps, under a minute)
      python benchmarks/bench_speed.py --full-run (adds the 500k-step `prlpid-fmi tune` run, minutes)
      python benchmarks/bench_speed.py --search [NAME ...]
                                                  (the fixed-PID search on one process and on all cores, default
                                                  first_order and two_tank; minutes)
      python benchmarks/bench_speed.py --design-model [NAME ...]
                                                  (the fixed-PID stage with baseline.design_model fmu and
                                                  identified, default first_order, first_order_1p5 and two_tank,
                                                  its load IAE on the FMU, and the yardstick; minutes)
      python benchmarks/bench_speed.py --stages [STEPS] [--stages-only]
                                                  (stage times of `tune` on first_order, two_tank and the quadrotor,
                                                  STEPS training steps each, default 500000; tens of minutes)

Per-step rows: CPU µs per env step (process CPU time; reset included: each measurement is a seeded
reset and E episodes of the scenario's length with uniformly random actions from a fixed seed, reset
again whenever an episode ends), median over R repeats. Within a repeat every implementation is
measured once, in an order shuffled per repeat, so load on the shared machine hits all alike.
- env: PidTuningEnv(dataclasses.replace(preset(name), forecast_horizon=N)) on the bundled FMU;
- fmi: the same with PidTuningEnv(config, forecast_path="fmi"), the standard FMI path a third-party
  FMU takes (n/a while the keyword does not exist);
- twin: benchmarks/twins.py, the same logic in numpy/Python with the same RK4 sub-steps
  (its agreement with env is printed below the table); twin-RK4: the twin less the time of its plant
  steps (RK4 plant steps per env step x the median CPU time of one, timed alone in the same repeats),
  i.e. the twin's control logic, smoothing, reward and glue without the integrator that env runs in C;
- FMUGym: benchmarks/fmugym_peer.py, gains as its action, the PID in _process_action, reward -e^2;
  it forecasts nothing, so its cost is the same at every N.
Run rows: training steps/s of prlpid_fmi.tuning.agent.train with the AgentConfig defaults (wall time),
the optional full run (wall time, peak RSS of the child), and the peak RSS of this process.
Targets (issue 7) are printed beside the ratios they apply to.

Search rows (--search, issue 24): tuning.design_rule.tune_fixed_pid of the scenario's file with its own budget and
limits, baseline.workers 1 and then one per core, each in a fresh subprocess, one after another: wall seconds,
the ratio, and whether the two controllers (Kp, Ti, Td, b, c, Tf, cost, evaluations) are the same bit for bit.

Design-model rows (--design-model, issue 36): the same fixed-PID search (one fresh subprocess each, one after another,
baseline.workers one per core) with baseline.design_model "fmu" (every candidate of the load search simulated on the
FMU) and "identified" (on local models fitted to the measured frequency responses, the choice verified on the FMU):
wall seconds, each against the yardstick (SB3's PPO, 50,000 steps on the trivial env like first_order's, measured in
the same run), the design's load IAE on the FMU for both (quality: identified / fmu), the path the identified
option took and its model-vs-FMU validation error.

Stage rows (--stages, issue 24): `prlpid-fmi tune <scenario> --timesteps STEPS` in a subprocess per scenario, one
after another; its wall time, the seconds of each stage from the run's run.json ("stage_seconds", recorded by
prlpid_fmi.progress; from the progress lines on stderr, whole seconds, where a run.json has none), "rest" = wall
- the stages (start-up, imports, files, plots), the ratio (wall - training) / training and the time outside
training against the issue's target (<= 20 s on first_order, <= 60 s on two_tank and the quadrotor, at 500k steps).
Beside the training rate (trained steps / training seconds): SB3's PPO with the scenario's agent settings
(prlpid_fmi.tuning.agent.build_model, its n_envs in a DummyVecEnv with Monitor, VecNormalize when set) on a
trivial numpy env with the same observation and action spaces (no FMU, no forecast: a constant observation,
reward -|a|^2, episodes of the scenario's length), timed over the same number of steps (at least 20,000).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fmugym_peer import UNAVAILABLE as PEER_UNAVAILABLE, make_peer  # noqa: E402
from twins import agreement, make_twin  # noqa: E402

from prlpid_fmi.config import AgentConfig  # noqa: E402
from prlpid_fmi.loop.env import PidTuningEnv
from prlpid_fmi.fmu import bundled_fmu  # noqa: E402
from prlpid_fmi.scenario.presets import preset

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = ("first_order", "two_tank", "quadrotor")
HORIZONS = (0, 3, 10)
TARGET_HORIZON = 3
# Issue 7 targets: (numerator, denominator) -> maximum ratio, at N = TARGET_HORIZON.
RATIO_TARGETS = {("env", "twin"): 2.0, ("fmi", "twin"): 4.0, ("env", "peer"): 0.5, ("fmi", "peer"): 1.0}
FULL_RUN_WALL_TARGET_S = 180.0
RSS_TARGET_MIB = 1024.0
FULL_RUN_STEPS = 500_000
NA_FMI = "n/a (forecast_path not available)"


@dataclasses.dataclass
class Contestant:
    """One implementation on one scenario and horizon, with its fixed action sequence."""

    kind: str  # env | fmi | twin | peer | rk4 (the twin's plant step alone)
    scenario: str
    horizon: int | None  # None for the peer (no forecast) and rk4
    env: object
    actions: np.ndarray  # for rk4: the number of plant steps to time
    samples: list = dataclasses.field(default_factory=list)  # µs per step (rk4: per plant step), one per repeat
    resets: int = 0
    plant_calls_per_step: float = 0.0  # twin: RK4 plant steps (plant and prior) per env step


def cpu_us_per_plant_step(c: Contestant) -> float:
    """Process CPU µs per call of the twin plant's step (the RK4 sub-steps of one sample)."""
    plant, u = c.env, [0.0] * len(c.env.inputs)
    plant.reset()
    start = time.process_time_ns()
    for _ in range(len(c.actions)):
        plant.step(u)
    return (time.process_time_ns() - start) / len(c.actions) / 1e3


def cpu_us_per_step(c: Contestant, seed: int) -> float:
    """Seeded reset + len(c.actions) steps (reset when an episode ends before the last); process CPU µs per step.

    FMUGym also resets itself inside step() when its stop_time or a termination is reached; those
    resets are in its time but not in c.resets (the resets this loop asked for).
    """
    env, actions = c.env, c.actions
    if c.kind == "twin":
        env.plant.calls = env.prior.calls = 0
    resets, last = 1, len(actions) - 1
    start = time.process_time_ns()
    env.reset(seed=seed)
    for i, a in enumerate(actions):
        _, _, terminated, truncated, _ = env.step(a)
        if (terminated or truncated) and i < last:
            env.reset()
            resets += 1
    elapsed = time.process_time_ns() - start
    c.resets = resets
    if c.kind == "twin":
        c.plant_calls_per_step = (env.plant.calls + env.prior.calls) / len(actions)
    return elapsed / len(actions) / 1e3


def build_contestants(episodes: int, seed: int) -> tuple[list[Contestant], str | None, str | None]:
    """Every implementation that can run here; also why the fmi and peer columns are missing, if they are."""
    contestants, fmi_missing, peer_missing = [], None, PEER_UNAVAILABLE
    for name in SCENARIOS:
        base = preset(name)
        steps = episodes * base.episode_steps
        for n in HORIZONS:
            config = dataclasses.replace(base, forecast_horizon=n)
            env = PidTuningEnv(config)
            actions = np.random.default_rng(seed).uniform(-1, 1, (steps, env.action_space.shape[0])).astype(np.float32)
            contestants.append(Contestant("env", name, n, env, actions))
            contestants.append(Contestant("twin", name, n, make_twin(config), actions))
            if n == 0:
                contestants.append(Contestant("rk4", name, None, make_twin(config).plant, np.empty(steps)))
            try:
                fmi_env = PidTuningEnv(config, forecast_path="fmi")
            except TypeError:
                fmi_missing = NA_FMI
            else:
                contestants.append(Contestant("fmi", name, n, fmi_env, actions))
        if peer_missing is None:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)  # FMUGym's float64 Box bounds
                    peer = make_peer(base, bundled_fmu(base.fmu, base.fmi_version))
            except Exception as exc:  # report why and skip the column, do not hide it
                peer_missing = f"FMUGym failed on {name}: {type(exc).__name__}: {exc}"
            else:
                low, high = peer.action_space.low, peer.action_space.high
                actions = np.random.default_rng(seed).uniform(low, high, (steps, low.size)).astype(np.float32)
                contestants.append(Contestant("peer", name, None, peer, actions))
    return contestants, fmi_missing, peer_missing


def measure(contestants: list[Contestant], repeats: int, seed: int) -> None:
    order = np.random.default_rng(seed)
    for r in range(repeats):
        for i in order.permutation(len(contestants)):
            c = contestants[i]
            c.samples.append(cpu_us_per_plant_step(c) if c.kind == "rk4" else cpu_us_per_step(c, seed))
        print(f"  repeat {r + 1}/{repeats} done", file=sys.stderr, flush=True)


def training_steps_per_s(steps: int) -> float:
    """Wall-clock steps/s of train() on first_order with AgentConfig's defaults (model build and saves included)."""
    from prlpid_fmi.tuning.agent import train

    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        train(preset("first_order"), AgentConfig(total_timesteps=steps, seed=0), Path(tmp) / "run")
        return steps / (time.perf_counter() - start)


def full_run() -> tuple[float, float, int]:
    """`prlpid-fmi tune scenarios/first_order.yaml --timesteps 500000`: wall s, peak child RSS MiB, exit code."""
    exe = Path(sys.executable).with_name("prlpid-fmi")
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [str(exe), "tune", str(REPO / "scenarios" / "first_order.yaml"),
               "--timesteps", str(FULL_RUN_STEPS), "--out", str(Path(tmp) / "run")]
        with open(Path(tmp) / "tune.log", "w") as log:
            start = time.perf_counter()
            code = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=REPO)
            wall = time.perf_counter() - start
        if code != 0:
            print((Path(tmp) / "tune.log").read_text()[-2000:], file=sys.stderr)
    return wall, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0, code


STAGE_TARGETS_S = {"first_order": 20.0, "two_tank": 60.0, "quadrotor": 60.0}  # time outside training at 500k
STAGE_COLUMNS = ("fixed-PID search", "classical gain schedule", "training", "gain schedule", "evaluation",
                 "choice of the deployed controller")
STAGE_TITLES = ("fixed PID", "classical", "training", "schedule", "evaluation", "choice")


def _stages_from_log(text: str) -> dict[str, float]:
    """Stage seconds from tune's plain progress lines (whole seconds): "prlpid-fmi: <stage>: done in ..." and
    "prlpid-fmi: training: N steps in ..."."""
    import re

    def seconds(words: str) -> float:
        return sum(float(v) * {"h": 3600, "min": 60, "s": 1}[u] for v, u in re.findall(r"(\d+) (h|min|s)\b", words))
    out = {}
    for line in text.splitlines():
        m = re.match(r"prlpid-fmi: ([^:]+): (?:done in|[\d,]+ steps in) (.*)$", line)
        if m:
            out[m.group(1).split(" (")[0]] = seconds(m.group(2).split(" (")[0])
    return out


def tune_stages(name: str, steps: int) -> dict:
    """One `prlpid-fmi tune <name> --timesteps steps` in a subprocess: {"wall", "stages", "trained", "code"}."""
    import json

    exe = Path(sys.executable).with_name("prlpid-fmi")
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        start = time.perf_counter()
        proc = subprocess.run([str(exe), "tune", name, "--timesteps", str(steps), "--out", str(run)],
                              capture_output=True, text=True, cwd=REPO)
        wall = time.perf_counter() - start
        info = json.loads((run / "run.json").read_text()) if (run / "run.json").is_file() else {}
    if proc.returncode:
        print(proc.stderr[-2000:], file=sys.stderr)
    stages = info.get("stage_seconds") or _stages_from_log(proc.stderr)
    return {"wall": wall, "stages": stages, "trained": info.get("trained_timesteps", steps), "code": proc.returncode,
            "source": "run.json" if info.get("stage_seconds") else "progress lines"}


SEARCH_SCENARIOS = ("first_order", "two_tank")
_SEARCH_CHILD = """
import json, sys, time, dataclasses
from prlpid_fmi.deliver.evidence import max_sensitivity
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.tuning.design_rule import tune_fixed_pid

def main():
    scenario = load_scenario(scenario_path(sys.argv[1]))
    baseline = dataclasses.replace(scenario.baseline, workers=int(sys.argv[2]))
    if len(sys.argv) > 3:
        baseline = dataclasses.replace(baseline, design_model=sys.argv[3])
    start = time.perf_counter()
    fixed = tune_fixed_pid(scenario.tuning, seed=scenario.agent.seed, max_sensitivity=max_sensitivity(scenario),
                           baseline=baseline, deploy=scenario.deploy)
    wall = time.perf_counter() - start
    design = fixed.report.details.as_json() if fixed.report is not None else {}
    record = design.get("design_model") or {}
    print(json.dumps({"wall": wall, "result": repr((fixed.gains.values(), fixed.structure, fixed.cost,
                                                    fixed.evaluations)),
                      "load_cost": design.get("load_cost"), "load_optimum": design.get("load_optimum"),
                      "path": record.get("path"), "validation_error": record.get("validation_error"),
                      "note": record.get("note")}))

if __name__ == "__main__":
    main()
"""


def search_times(name: str, workers: int, design_model: str | None = None) -> dict:
    """The fixed-PID search of scenario `name` with baseline.workers = workers (and baseline.design_model, None: the
    scenario's) in a fresh subprocess: {"wall", "result", "load_cost", "load_optimum", "path", "validation_error",
    "note"} (result: repr of gains, structure, cost, evaluations; load_cost: the design's load IAE on the FMU), or
    {"error"}."""
    import json

    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "search_child.py"
        script.write_text(_SEARCH_CHILD)
        extra = [] if design_model is None else [design_model]
        proc = subprocess.run([sys.executable, str(script), name, str(workers), *extra], capture_output=True,
                              text=True, cwd=REPO)
    if proc.returncode:
        return {"error": proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else f"exit {proc.returncode}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def print_search(rows: dict, cores: int) -> None:
    print(f"\nFixed-PID search on 1 process and on {cores} (baseline.workers; issue 24)\n")
    print(f"| scenario | 1 process s | {cores} processes s | speed-up | same controller |")
    print("|---|---|---|---|---|")
    for name, (one, many) in rows.items():
        if "error" in one or "error" in many:
            print(f"| {name} | {one.get('error', '')} | {many.get('error', '')} | – | – |")
            continue
        print(f"| {name} | {one['wall']:.1f} | {many['wall']:.1f} | {one['wall'] / many['wall']:.2f}x | "
              f"{'yes' if one['result'] == many['result'] else 'NO'} |")


DESIGN_SCENARIOS = ("first_order", "first_order_1p5", "two_tank")
YARDSTICK_STEPS = 50_000  # SB3's PPO on the trivial env like first_order's: the yardstick of the fixed-PID stage
YARDSTICK_REPEATS = 3  # its median over this many runs (one run varies by ~20 % between runs on the 2-core machine)
FIXED_PID_TARGET = 1.3  # issue 36: the fixed-PID stage on first_order <= this many yardsticks


def print_design_model(rows: dict, yardstick_s: float, cores: int) -> None:
    """The fixed-PID stage per scenario with baseline.design_model fmu and identified (issue 36)."""
    print(f"\nFixed-PID stage, baseline.design_model fmu (every candidate simulated) vs identified (local models, "
          f"verified on the FMU), {cores} workers; yardstick: SB3 PPO {YARDSTICK_STEPS} steps on the trivial env like "
          f"first_order's = {yardstick_s:.1f} s (median of {YARDSTICK_REPEATS}), measured in this run\n")
    print("| scenario | fmu s | identified s | speed-up | fmu / yardstick | identified / yardstick | load IAE fmu | "
          "load IAE identified | identified / fmu | path | model vs FMU |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, (fmu, ident) in rows.items():
        if "error" in fmu or "error" in ident:
            print(f"| {name} | {fmu.get('error', '')} | {ident.get('error', '')} | | | | | | | | |")
            continue
        ratio = ident["load_cost"] / fmu["load_cost"] if fmu.get("load_cost") else float("nan")
        target = f" (target <= {FIXED_PID_TARGET})" if name == "first_order" else ""
        error = ident.get("validation_error")
        print(f"| {name} | {fmu['wall']:.1f} | {ident['wall']:.1f} | {fmu['wall'] / ident['wall']:.2f}x | "
              f"{fmu['wall'] / yardstick_s:.2f} | {ident['wall'] / yardstick_s:.2f}{target} | {fmu['load_cost']:.5g} | "
              f"{ident['load_cost']:.5g} | {ratio:.4f} | {ident.get('path')} | "
              f"{'–' if error is None else f'{100 * error:.2g} %'} |")
    print("load IAE: the chosen design's load cost on the FMU (tuning.load_experiment, fixed_pid.json design.load_cost); "
          "identified / fmu <= 1.02 is the quality target")


def sb3_trivial_steps_per_s(name: str, steps: int) -> float:
    """Wall steps/s of SB3's PPO with the scenario's agent settings on a trivial env of the same spaces."""
    import gymnasium as gym
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from prlpid_fmi.scenario.load import load_scenario
    from prlpid_fmi.scenario.presets import scenario_path
    from prlpid_fmi.tuning.agent import build_model

    scenario = load_scenario(scenario_path(name))
    probe = PidTuningEnv(scenario.tuning)
    obs_space, act_space, length = probe.observation_space, probe.action_space, scenario.tuning.episode_steps
    probe.close()

    class Trivial(gym.Env):
        observation_space, action_space = obs_space, act_space

        def reset(self, seed=None, options=None):
            super().reset(seed=seed)
            self.k = 0
            return np.zeros(obs_space.shape, obs_space.dtype), {}

        def step(self, action):
            self.k += 1
            reward = -float(np.sum(np.square(action)))
            return np.zeros(obs_space.shape, obs_space.dtype), reward, False, self.k >= length, {}

    agent = scenario.agent
    import torch

    from prlpid_fmi.tuning.agent import torch_threads

    torch.set_num_threads(torch_threads(agent.torch_threads))  # as tuning.agent.train sets them for the tune
    with tempfile.TemporaryDirectory() as tmp:
        env = make_vec_env(Trivial, n_envs=agent.envs, seed=agent.seed, vec_env_cls=DummyVecEnv, monitor_dir=tmp)
        if agent.normalize:
            env = VecNormalize(env, gamma=agent.gamma)
        model = build_model(agent, env)
        start = time.perf_counter()
        model.learn(total_timesteps=steps)
        rate = model.num_timesteps / (time.perf_counter() - start)
        env.close()
    return rate


def print_stages(steps: int, results: dict, trivial: dict) -> None:
    cols = [("scenario", 11), ("wall", 7)] + [(t, 10) for t in STAGE_TITLES] + [
        ("rest", 6), ("outside", 8), ("(wall-tr)/tr", 12), ("train/s", 8), ("SB3 triv/s", 10), ("ratio", 6)]
    line = "  ".join(f"{title:>{w}}" for title, w in cols)
    print(f"\nbench_speed --stages (issue 24): `prlpid-fmi tune <scenario> --timesteps {steps}`, seconds (wall); "
          f"outside = wall - training; target at 500k steps: first_order <= 20 s, two_tank and quadrotor <= 60 s")
    print(line)
    print("-" * len(line))
    for name, r in results.items():
        st = r["stages"]
        training = st.get("training", float("nan"))
        rest = r["wall"] - sum(st.get(k, 0.0) for k in STAGE_COLUMNS)
        outside = r["wall"] - training
        rate = r["trained"] / training if training > 0 else float("nan")
        target = STAGE_TARGETS_S[name]
        cells = [name, f"{r['wall']:.1f}"] + [f"{st[k]:.1f}" if k in st else "-" for k in STAGE_COLUMNS] + [
            f"{rest:.1f}", f"{outside:.1f}", f"{outside / training:.2f}" if training > 0 else "n/a",
            f"{rate:.0f}", f"{trivial[name]:.0f}", f"{rate / trivial[name]:.2f}"]
        print("  ".join(f"{cell:>{w}}" for cell, (_, w) in zip(cells, cols)))
        verdict_text = (f"outside training {outside:.1f} s, target <= {target:.0f} s at {FULL_RUN_STEPS:,} steps: "
                        + (verdict(outside, target) if steps == FULL_RUN_STEPS else f"not judged ({steps:,} steps)"))
        print(f"{'':>11}  {verdict_text}; stage times from {r['source']}" + (f"; exit {r['code']}" if r["code"] else ""))
    print("-" * len(line))
    print("ratio = training steps/s of the tune / SB3's PPO on the trivial env (target >= 0.9); '-': the stage did "
          "not run (classical: only on a nonlinear plant)")


# -- printing -------------------------------------------------------------------------------------------
def verdict(value: float, target: float) -> str:
    return "met" if value <= target else "missed"


def ratio_cell(num: float | None, den: float | None, key: tuple[str, str] | None, horizon: int) -> str:
    """'ratio' or, at the target horizon, 'ratio (<=target met|missed)'; 'n/a' when a side is missing."""
    if num is None or den is None:
        return "n/a"
    ratio = num / den
    if key is None or horizon != TARGET_HORIZON:
        return f"{ratio:.2f}"
    target = RATIO_TARGETS[key]
    return f"{ratio:.2f} (<={target:g} {verdict(ratio, target)})"


def print_table(contestants, fmi_missing, peer_missing, args, train_rate, full, agreements) -> None:
    med = {(c.kind, c.scenario, c.horizon): statistics.median(c.samples) for c in contestants}
    calls = {(c.scenario, c.horizon): c.plant_calls_per_step for c in contestants if c.kind == "twin"}
    cols = [("scenario", 11), ("N", 2), ("env", 6), ("fmi", 6), ("twin", 6), ("twin-RK4", 8),
            ("env/twin", 18), ("fmi/twin", 18), ("env/(twin-RK4)", 14), ("FMUGym", 6),
            ("env/FMUGym", 20), ("fmi/FMUGym", 20)]
    line = "  ".join(f"{title:>{w}}" for title, w in cols)
    print(f"\nbench_speed (issue 7): CPU µs per env step, median of {args.repeats} interleaved repeats of "
          f"{args.episodes} episode(s) each, resets included; python {platform.python_version()}, "
          f"{os.cpu_count()} CPUs; targets at N = {TARGET_HORIZON}")
    print(line)
    print("-" * len(line))
    for name in SCENARIOS:
        for n in HORIZONS:
            env, twin = med.get(("env", name, n)), med.get(("twin", name, n))
            fmi, peer = med.get(("fmi", name, n)), med.get(("peer", name, None))
            rk4 = med.get(("rk4", name, None))
            logic = None if rk4 is None else twin - calls[(name, n)] * rk4
            if n not in (0, TARGET_HORIZON):
                peer = None  # FMUGym is compared at N = 0 and N = 3 only
            cells = [name, str(n), f"{env:.1f}", "n/a" if fmi is None else f"{fmi:.1f}", f"{twin:.1f}",
                     "n/a" if logic is None else f"{logic:.1f}",
                     ratio_cell(env, twin, ("env", "twin"), n), ratio_cell(fmi, twin, ("fmi", "twin"), n),
                     ratio_cell(env, logic, None, n), "" if peer is None else f"{peer:.1f}",
                     "" if peer is None else ratio_cell(env, peer, ("env", "peer"), n),
                     "" if peer is None else ratio_cell(fmi, peer, ("fmi", "peer"), n)]
            print("  ".join(f"{cell:>{w}}" for cell, (_, w) in zip(cells, cols)))
    print("-" * len(line))
    print(f"{'training, first_order':<40}{train_rate:>12.0f} steps/s over {args.train_steps} steps "
          f"(train() with AgentConfig defaults, wall time)")
    if full is None:
        print(f"{'full run (500k steps, tune)':<40}{'not run':>12} (pass --full-run); target <= "
              f"{FULL_RUN_WALL_TARGET_S:.0f} s wall, <= {RSS_TARGET_MIB:.0f} MiB")
    else:
        wall, rss, code = full
        status = f"exit {code}" if code else f"{verdict(wall, FULL_RUN_WALL_TARGET_S)}"
        print(f"{'full run (500k steps, tune) wall':<40}{wall:>12.1f} s      target <= {FULL_RUN_WALL_TARGET_S:.0f} s: {status}")
        print(f"{'full run peak RSS (child)':<40}{rss:>12.0f} MiB    target <= {RSS_TARGET_MIB:.0f} MiB: "
              f"{verdict(rss, RSS_TARGET_MIB)}")
    rss_self = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"{'peak RSS of this benchmark process':<40}{rss_self:>12.0f} MiB")
    print("-" * len(line))
    if fmi_missing:
        print(f"fmi columns: {fmi_missing}")
    if peer_missing:
        print(f"FMUGym columns: skipped: {peer_missing}")
    sub_steps = ", ".join(f"{c.scenario} {c.env.plant.n_sub}" for c in contestants
                          if c.kind == "twin" and c.horizon == 0)
    print(f"RK4 sub-steps per sample (bundled FMUs' fixed_step): {sub_steps}")
    print("twin vs env, same seed and actions, max |Δ observation| / max |Δ reward|: " + "; ".join(
        f"{name} N={n} {d_obs:.1e}/{d_rew:.1e}" for (name, n), (d_obs, d_rew) in agreements.items()))
    resets = {}
    for c in contestants:
        if c.kind in ("env", "twin", "peer") and c.horizon in (None, TARGET_HORIZON):
            resets.setdefault(c.scenario, []).append(f"{c.kind} {c.resets}")
    print(f"resets asked for per measurement of {args.episodes} episode(s) (last repeat, N={TARGET_HORIZON}): "
          + "; ".join(f"{k}: {', '.join(v)}" for k, v in resets.items()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="3 repeats of 1 episode, 4096 training steps")
    parser.add_argument("--repeats", type=int, default=None, help="interleaved repeats (default 7, quick 3)")
    parser.add_argument("--episodes", type=int, default=None, help="episodes per measurement (default 2, quick 1)")
    parser.add_argument("--train-steps", type=int, default=None, help="training steps (default 50000, quick 4096)")
    parser.add_argument("--full-run", action="store_true", help="also time a 500k-step `prlpid-fmi tune` run")
    parser.add_argument("--stages", type=int, nargs="?", const=FULL_RUN_STEPS, default=None, metavar="STEPS",
                        help=f"stage times of `tune` on {', '.join(SCENARIOS)} (STEPS training steps, default "
                             f"{FULL_RUN_STEPS})")
    parser.add_argument("--stages-only", action="store_true", help="only the --stages table")
    parser.add_argument("--stages-scenarios", nargs="+", choices=SCENARIOS, default=list(SCENARIOS), metavar="NAME",
                        help=f"the scenarios of --stages (default: {' '.join(SCENARIOS)})")
    parser.add_argument("--search", nargs="*", default=None, metavar="NAME",
                        help=f"only the fixed-PID search on one process and on all cores (default "
                             f"{' '.join(SEARCH_SCENARIOS)})")
    parser.add_argument("--design-model", nargs="*", default=None, metavar="NAME",
                        help=f"only the fixed-PID stage with baseline.design_model fmu and identified, and the yardstick "
                             f"(default {' '.join(DESIGN_SCENARIOS)})")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.design_model is not None:
        from prlpid_fmi.tuning.search_pool import search_workers

        cores = search_workers(None)
        rows = {}
        for name in args.design_model or DESIGN_SCENARIOS:
            print(f"  fixed-PID stage of {name}, design_model fmu and identified ...", file=sys.stderr, flush=True)
            rows[name] = (search_times(name, cores, "fmu"), search_times(name, cores, "identified"))
        print(f"  yardstick: SB3 PPO on the trivial env like first_order's, {YARDSTICK_REPEATS} times ...",
              file=sys.stderr, flush=True)
        runs = sorted(YARDSTICK_STEPS / sb3_trivial_steps_per_s("first_order", YARDSTICK_STEPS)
                      for _ in range(YARDSTICK_REPEATS))
        print(f"  yardstick runs: {', '.join(f'{x:.2f} s' for x in runs)} (the median is used)", file=sys.stderr)
        print_design_model(rows, statistics.median(runs), cores)
        return
    if args.search is not None:
        from prlpid_fmi.tuning.search_pool import search_workers

        cores = max(2, search_workers(None))
        rows = {}
        for name in args.search or SEARCH_SCENARIOS:
            print(f"  fixed-PID search of {name} on 1 and {cores} processes ...", file=sys.stderr, flush=True)
            rows[name] = (search_times(name, 1), search_times(name, cores))
        print_search(rows, cores)
        return
    if args.stages_only and args.stages is None:
        args.stages = FULL_RUN_STEPS
    if args.stages is not None:
        if args.stages < 1:
            parser.error("--stages must be >= 1")
        results, trivial = {}, {}
        for name in args.stages_scenarios:
            print(f"  tune {name} ...", file=sys.stderr, flush=True)
            results[name] = tune_stages(name, args.stages)
            print(f"  SB3 on a trivial env like {name}'s ...", file=sys.stderr, flush=True)
            trivial[name] = sb3_trivial_steps_per_s(name, max(args.stages, 20_000))
        print_stages(args.stages, results, trivial)
        if args.stages_only:
            return
    args.repeats = args.repeats or (3 if args.quick else 7)
    args.episodes = args.episodes or (1 if args.quick else 2)
    args.train_steps = args.train_steps or (4096 if args.quick else 50_000)
    if min(args.repeats, args.episodes, args.train_steps) < 1:
        parser.error("--repeats, --episodes and --train-steps must be >= 1")

    contestants, fmi_missing, peer_missing = build_contestants(args.episodes, args.seed)
    agreements = {}
    for name in SCENARIOS:
        for n in (0, TARGET_HORIZON):
            env, twin = (next(c.env for c in contestants if (c.kind, c.scenario, c.horizon) == (k, name, n))
                         for k in ("env", "twin"))
            agreements[(name, n)] = agreement(env, twin, preset(name).episode_steps, args.seed)
    measure(contestants, args.repeats, args.seed)
    for c in contestants:
        if hasattr(c.env, "close"):
            c.env.close()
    print("  training ...", file=sys.stderr, flush=True)
    train_rate = training_steps_per_s(args.train_steps)
    full = None
    if args.full_run:
        print("  full run ...", file=sys.stderr, flush=True)
        full = full_run()
    print_table(contestants, fmi_missing, peer_missing, args, train_rate, full, agreements)


if __name__ == "__main__":
    main()
