"""Training with stable-baselines3: PPO per Algorithm 1 / Table 1, SAC and TD3 as the paper's baselines.

The actor and the critic share one tanh MLP feature extractor (Table 1: state -> 64 -> 64), followed
by a linear action head and a linear value head. Vectorised envs hold one plant + prior FMU pair each.
"""
from __future__ import annotations

import functools
import math
import os
import re
import warnings
from pathlib import Path

import gymnasium as gym
import torch
from torch import nn

import prlpid_fmi.schema as schema
from prlpid_fmi.config import AgentConfig, TuningConfig
from prlpid_fmi.errors import PrlPidError, RunError
from prlpid_fmi.fmu import describe_fmu
from prlpid_fmi.fmu.resolve import resolve_fmu
from prlpid_fmi.loop.env import PidTuningEnv, is_anchored
from prlpid_fmi.progress import training_progress
from prlpid_fmi import rundir as rd
from prlpid_fmi.rundir import write_atomic

ALGORITHMS = schema.ALGORITHMS  # ppo | sac | td3: the scenario schema's choices
ANCHORED_INITIAL_STD = 0.3  # PPO's initial action std around the fixed PID (action units; the band is [-1, 1])


def _shared_mlp_class():
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    class SharedMLP(BaseFeaturesExtractor):
        """obs (batch, n_obs) -> tanh MLP features (batch, net_arch[-1]), shared by actor and critic."""

        def __init__(self, observation_space: gym.spaces.Box, net_arch=(64, 64)):
            super().__init__(observation_space, features_dim=net_arch[-1])
            layers, n_in = [], int(observation_space.shape[0])
            for width in net_arch:
                layers += [nn.Linear(n_in, width), nn.Tanh()]
                n_in = width
            self.mlp = nn.Sequential(*layers)

        def forward(self, observations: torch.Tensor) -> torch.Tensor:
            return self.mlp(observations)

    return SharedMLP


def make_vec_env(config: TuningConfig, agent: AgentConfig, monitor_dir: Path | None = None, anchor=None,
                 append: bool = False):
    """n_envs PidTuningEnvs (each with its own plant and prior FMU instances), seeded from agent.seed.

    anchor: the tuned fixed PID's Gains the anchored gain map is centred on (None: absolute map).
    append: add to existing Monitor CSVs (a resumed training) instead of starting them afresh."""
    from stable_baselines3.common.env_util import make_vec_env as sb3_make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    vec_cls = SubprocVecEnv if agent.vec_env == "subproc" and agent.envs > 1 else DummyVecEnv
    if agent.envs > 1 and describe_fmu(resolve_fmu(config.fmu, config.fmi_version)).once_per_process:
        vec_cls = SubprocVecEnv  # canBeInstantiatedOnlyOncePerProcess: one env (one instance) per process
    return sb3_make_vec_env(functools.partial(PidTuningEnv, config, anchor=anchor, info=False), n_envs=agent.envs, seed=agent.seed,
                            vec_env_cls=vec_cls, monitor_dir=str(monitor_dir) if monitor_dir else None,
                            monitor_kwargs={"override_existing": not _monitors_exist(monitor_dir, agent.envs)}
                            if append and monitor_dir else None)


def _monitors_exist(monitor_dir: Path, n_envs: int) -> bool:
    """Whether every env's Monitor CSV (SB3 names them <i>.monitor.csv) exists, so that all can be appended to."""
    return all((Path(monitor_dir) / f"{i}.monitor.csv").is_file() for i in range(n_envs))


def build_model(agent: AgentConfig, env, tensorboard_dir: Path | None = None, anchored: bool = False):
    """An untrained SB3 model for `env` as configured by `agent`.

    anchored: the env's gain map is anchored at the tuned fixed PID; PPO's mean action then starts at
    exactly 0 (the fixed PID) with exploration std ANCHORED_INITIAL_STD, so training starts from the
    fixed PID and moves away only where that earns reward.
    """
    from stable_baselines3 import PPO, SAC, TD3

    if agent.algorithm not in ALGORITHMS:
        raise PrlPidError(f"agent.algorithm must be one of {', '.join(ALGORITHMS)}, got {agent.algorithm!r}")
    common = dict(learning_rate=agent.learning_rate, gamma=agent.gamma, seed=agent.seed, device="cpu",
                  tensorboard_log=str(tensorboard_dir) if tensorboard_dir else None, verbose=0, **agent.extra)
    if agent.algorithm == "ppo":
        policy_kwargs = dict(features_extractor_class=_shared_mlp_class(),
                             features_extractor_kwargs=dict(net_arch=tuple(agent.net_arch)),
                             share_features_extractor=True, net_arch=dict(pi=[], vf=[]), activation_fn=nn.Tanh)
        if anchored:
            policy_kwargs["log_std_init"] = math.log(ANCHORED_INITIAL_STD)
        model = PPO("MlpPolicy", env, n_steps=agent.n_steps, batch_size=agent.batch_size, n_epochs=agent.n_epochs,
                    gae_lambda=agent.gae_lambda, clip_range=agent.clip_range, ent_coef=agent.ent_coef,
                    policy_kwargs=policy_kwargs, **common)
        if anchored:
            with torch.no_grad():  # mean action exactly 0 for every observation at the start
                model.policy.action_net.weight.zero_()
                model.policy.action_net.bias.zero_()
        return model
    policy_kwargs = dict(net_arch=list(agent.net_arch), activation_fn=nn.Tanh)
    cls = SAC if agent.algorithm == "sac" else TD3
    return cls("MlpPolicy", env, buffer_size=agent.buffer_size, learning_starts=agent.learning_starts,
               batch_size=agent.batch_size, policy_kwargs=policy_kwargs, **common)


def load_model(path: Path, algorithm: str, env=None):
    """Load a saved SB3 model of the given algorithm."""
    from stable_baselines3 import PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3}[algorithm].load(str(path), env=env, device="cpu")


def _timed_checkpoints(run_dir: Path, agent: AgentConfig):
    """A callback that saves a checkpoint every agent.checkpoint_minutes of wall time (beside the step-count
    checkpoints), so that a long training killed between them loses little."""
    import time

    from stable_baselines3.common.callbacks import BaseCallback

    interval_s = 60.0 * agent.checkpoint_minutes

    class TimedCheckpoint(BaseCallback):
        def _on_training_start(self) -> None:
            self.due = time.monotonic() + interval_s

        def _on_step(self) -> bool:
            if time.monotonic() >= self.due:
                save_checkpoint(self.model, run_dir, agent.normalize)
                self.due = time.monotonic() + interval_s
            return True

    return TimedCheckpoint()


REPEATED_FAULT_EPISODES = 20  # training episodes in a row ending at the same fault that stop the training


def fault_key(termination) -> tuple | None:
    """What makes two episode ends "the same fault": the kind, the sample and the FMI call named (fmi2DoStep, ...);
    None for an end that is not the FMU's fault (a divergence is the gains')."""
    if termination is None or termination.kind == "diverged":
        return None
    call = re.search(r"\bfmi[0-9]?[A-Z]\w*", termination.message)
    return termination.kind, termination.step, call.group(0) if call else ""


class FaultWatch:
    """Stops training when REPEATED_FAULT_EPISODES episodes in a row (over all envs, in the order they end) end at
    the same fault (fault_key): nothing is learnt from them. After training, `stopped` is the last such episode's
    Termination (None: training was not stopped) and `episodes` the count."""

    def __init__(self, limit: int = REPEATED_FAULT_EPISODES):
        self.limit = limit
        self.stopped = None
        self.episodes = 0
        self._key = None

    def ended(self, termination) -> bool:
        """Count one episode's end (its Termination, or None); True when training should stop."""
        key = fault_key(termination)
        self.episodes = self.episodes + 1 if key is not None and key == self._key else int(key is not None)
        self._key = key
        if key is not None and self.episodes >= self.limit:
            self.stopped = termination
            return True
        return False

    def callback(self):
        """An SB3 callback that feeds `ended` from the envs' infos (PidTuningEnv puts a Termination there)."""
        from stable_baselines3.common.callbacks import BaseCallback

        watch = self

        class RepeatedFault(BaseCallback):
            def _on_step(self) -> bool:
                go_on = True
                for done, info in zip(self.locals.get("dones", ()), self.locals.get("infos", ())):
                    if done and watch.ended(info.get("termination")):
                        go_on = False
                return go_on

        return RepeatedFault()


def save_checkpoint(model, run_dir: Path, normalize: bool) -> Path:
    """checkpoints/model_<timesteps>_steps.zip (+ the VecNormalize statistics) atomically; returns its path."""
    steps = int(model.num_timesteps)
    path = write_atomic(Path(run_dir) / rd.CHECKPOINTS / f"model_{steps}_steps.zip", lambda tmp: model.save(str(tmp)))
    if normalize and model.get_vec_normalize_env() is not None:
        stats = model.get_vec_normalize_env()
        write_atomic(Path(run_dir) / rd.CHECKPOINTS / f"model_vecnormalize_{steps}_steps.pkl",
                     lambda tmp: stats.save(str(tmp)))
    return path


def normalize_stats(run_dir: Path, model_file: Path) -> Path | None:
    """The VecNormalize statistics saved with `model_file`: a checkpoint's own
    checkpoints/model_vecnormalize_<steps>_steps.pkl, or run_dir/vecnormalize.pkl beside model.zip; None if
    absent. A checkpoint is paired with its own statistics: run_dir/vecnormalize.pkl may be older or newer."""
    model_file = Path(model_file)
    parts = model_file.stem.split("_")
    if model_file.parent.name == rd.CHECKPOINTS and len(parts) == 3 and parts[0] == "model" and parts[2] == "steps":
        paired = model_file.parent / f"model_vecnormalize_{parts[1]}_steps.pkl"
    else:
        paired = Path(run_dir) / rd.VECNORMALIZE
    return paired if paired.is_file() else None


def _allocation_text(exc: BaseException) -> str:
    """What a failed allocation asked for, in GB when torch says it; else the message on one line."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    m = re.search(r"tried to allocate (\d+) bytes", text)
    return f"one tensor of {int(m.group(1)) / 1e9:.3g} GB could not be allocated" if m else text


def torch_threads(requested: int) -> int:
    """agent.torch_threads, at most the machine's cores (more only cost memory: 10**5 threads once exhausted the
    address space, and the FMU's shared library then failed to load); a warning says when it is lowered."""
    cores = os.cpu_count() or 1
    if requested > cores:
        warnings.warn(f"agent.torch_threads: {requested} is more than this machine's {cores} cores; torch uses "
                      f"{cores}", stacklevel=2)
        return cores
    return requested


def train(config: TuningConfig, agent: AgentConfig, run_dir: Path, progress_bar: bool = False,
          resume_from: Path | None = None, total_timesteps: int | None = None, anchor=None,
          faults: FaultWatch | None = None):
    """Train an agent; checkpoints, TensorBoard logs and Monitor CSVs go under run_dir.

    Returns the trained model (also saved as run_dir/model.zip, with run_dir/vecnormalize.pkl when used).
    faults: a FaultWatch that stops training early when episodes keep ending at the same FMU fault (its `stopped`
    says so afterwards; a checkpoint is saved there).
    """
    from stable_baselines3.common.callbacks import CheckpointCallback
    from stable_baselines3.common.vec_env import VecNormalize

    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(torch_threads(agent.torch_threads))
    env = make_vec_env(config, agent, run_dir / rd.MONITOR, anchor, append=resume_from is not None)
    if agent.normalize:
        stats = normalize_stats(run_dir, resume_from) if resume_from is not None else None
        env = VecNormalize.load(str(stats), env) if stats is not None else VecNormalize(env, gamma=agent.gamma)
    if resume_from is not None:
        try:
            model = load_model(resume_from, agent.algorithm, env)
        except Exception as exc:  # a damaged file fails in zipfile, pickle or torch: all mean the same here
            env.close()
            raise RunError(f"{resume_from}: cannot resume from this checkpoint ({type(exc).__name__}: "
                           f"{' '.join(str(exc).split())}; expected a {agent.algorithm.upper()} model written by "
                           "`tune`; delete it to resume from an earlier one)") from None
        model.tensorboard_log = str(run_dir / rd.TENSORBOARD)
    else:
        try:
            model = build_model(agent, env, run_dir / rd.TENSORBOARD, anchored=is_anchored(config, anchor))
        except (MemoryError, RuntimeError) as exc:  # torch: RuntimeError "can't allocate memory"; numpy: MemoryError
            if isinstance(exc, RuntimeError) and "allocate" not in str(exc):
                raise
            env.close()
            sizes = f"agent.net_arch {list(agent.net_arch)}" + (
                f", agent.buffer_size {agent.buffer_size}" if agent.algorithm != "ppo" else "")
            raise RunError(f"agent: the {agent.algorithm.upper()} model does not fit in this machine's memory "
                           f"({sizes}: {_allocation_text(exc)}; expected smaller hidden layers"
                           + (" or replay buffer)" if agent.algorithm != "ppo" else ")")) from None
    steps = total_timesteps if total_timesteps is not None else agent.total_timesteps
    checkpoint = CheckpointCallback(save_freq=max(agent.checkpoint_every // agent.envs, 1),
                                    save_path=str(run_dir / rd.CHECKPOINTS), name_prefix="model",
                                    save_vecnormalize=agent.normalize)
    callbacks = [checkpoint, _timed_checkpoints(run_dir, agent)] + ([training_progress()] if progress_bar else [])
    if faults is not None:
        callbacks.append(faults.callback())
    try:
        model.learn(total_timesteps=steps, callback=callbacks, reset_num_timesteps=resume_from is None,
                    tb_log_name=agent.algorithm)
        if faults is not None and faults.stopped is not None and model.num_timesteps > 0:
            save_checkpoint(model, run_dir, agent.normalize)
    except BaseException:  # a signal (SIGTERM, SIGINT) or an error: keep what was learnt for --resume
        if model.num_timesteps > 0:
            save_checkpoint(model, run_dir, agent.normalize)
        raise
    finally:
        write_atomic(run_dir / rd.MODEL, lambda tmp: model.save(str(tmp)))
        if agent.normalize:
            write_atomic(run_dir / rd.VECNORMALIZE, lambda tmp: env.save(str(tmp)))
        env.close()
    return model
