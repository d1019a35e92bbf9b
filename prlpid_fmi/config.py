"""Typed configuration of one tuning problem: plant, prior, loops, controller, strategies, reward, episodes.

These dataclasses are the single source of truth for every default. The YAML scenario loader
builds them (validating at the edge); the environment, training and evaluation only read them.
Units: seconds for times, samples ("steps") for counts, plant units for setpoints and signals.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from .control.reward import RewardWeights
from .control.smoothing import DEFAULT_WINDOW

INF = float("inf")


@dataclass(frozen=True)
class GainRange:
    """Range an action in [-1, 1] maps into. scale "log" (geometric, needs low > 0) or "linear"."""

    low: float
    high: float
    scale: str = "log"


@dataclass(frozen=True)
class LoopConfig:
    """One control loop: the FMU input it drives and the FMU output it measures.

    measurement_scale (plant units) normalises errors for the observation and the reward, so that
    the reward's clip bounds and bonus band mean the same for a level in cm and an angle in rad.
    """

    input: str
    output: str
    setpoint_range: tuple[float, float] = (0.0, 1.0)
    u_min: float = -INF
    u_max: float = INF
    Kp: GainRange = GainRange(0.1, 10.0, "log")
    Ti: GainRange = GainRange(0.1, 100.0, "log")
    Td: GainRange = GainRange(0.0, 1.0, "linear")
    measurement_scale: float = 1.0
    divergence_bound: float = 100.0  # |measurement - setpoint| / measurement_scale past this ends the episode
    control_scale: Optional[float] = None  # [input units] normalises |u_k - u_{k-1}|; None: u_max - u_min if finite


@dataclass(frozen=True)
class Disturbance:
    """A change applied during an episode, from start_step to end_step (exclusive; None = to the end).

    kind "fmu": set the FMU input or tunable parameter `target` to `value` (restored after end_step);
    kind "actuator" / "measurement": add `value` to the control signal / measurement of the loop whose
    output (measured variable) is named `target`.
    """

    kind: str
    target: str
    start_step: int
    value: float
    end_step: Optional[int] = None


@dataclass(frozen=True)
class PriorConfig:
    """The predictive prior: by default a second instance of the plant FMU.

    fmu: another FMU file (None: the plant's). parameters: values applied to the prior after every
    state copy (model mismatch). state_map {prior parameter: plant variable}: for a different FMU,
    whose state cannot be copied, the prior is re-initialised each step from these plant values.
    """

    fmu: Optional[str] = None
    parameters: dict = field(default_factory=dict)
    state_map: dict = field(default_factory=dict)


@dataclass(frozen=True)
class AnchorBands:
    """How far the anchored gain map moves each gain from the tuned fixed PID (action -1 .. +1).

    Kp, Ti: factors >= 1 (Kp within [Kp0/f, Kp0*f]); Td: additive band, a fraction (0, 1] of the
    loop's Td range width; coupling: additive band for the coupling coefficients.
    """

    Kp: float = 3.0
    Ti: float = 3.0
    Td: float = 0.1
    coupling: float = 0.1


@dataclass(frozen=True)
class TuningConfig:
    """Everything PidTuningEnv needs. `fmu` is a path to a .fmu file or a bundled plant's name."""

    fmu: str
    loops: tuple[LoopConfig, ...]
    plant_parameters: dict = field(default_factory=dict)
    sample_time_s: float = 0.1
    fmi_version: int = 2  # for bundled plants only
    prior: PriorConfig = PriorConfig()
    # controller
    anti_windup: str = "clamping"
    derivative_filter_N: Optional[float] = None
    coupled: bool = False  # cross-axis coupled PID (paper eq. 26-27), needs 3 loops
    coupling_range: float = 0.5  # coupling coefficients in [-c, c]
    gain_mapping: str = "anchored"  # anchored (action 0 = tuned fixed PID) | absolute (paper: whole ranges)
    anchor_bands: AnchorBands = AnchorBands()
    # strategies
    forecast_horizon: int = 3  # N; 0 = plain one-step reward
    smoothing: str = "era"  # none | sma | lwma | era
    smoothing_window: int = DEFAULT_WINDOW
    smoothing_alpha: Optional[float] = None  # None: the method's default (LWMA 0.2, ERA 0.3)
    reward: RewardWeights = RewardWeights()
    divergence_penalty: float = -100.0
    # episodes
    episode_steps: int = 200
    setpoint_hold_steps: int = 100
    setpoint_schedule: Optional[tuple[tuple[int, tuple[float, ...]], ...]] = None  # ((step, setpoints), ...)
    disturbances: tuple[Disturbance, ...] = ()
    measurement_noise_std: float = 0.0  # plant units, Gaussian, every loop
    actuator_noise_std: float = 0.0  # control-signal units, Gaussian, every loop
    randomize: dict = field(default_factory=dict)  # {FMU parameter: (low, high)} drawn uniformly per episode

    @property
    def n_loops(self) -> int:
        return len(self.loops)


@dataclass(frozen=True)
class AgentConfig:
    """The RL agent and its training budget (paper Table 1 / Algorithm 1 defaults for PPO)."""

    algorithm: str = "ppo"  # ppo | sac | td3
    total_timesteps: int = 500_000
    seed: int = 0
    n_envs: int = 8  # parallel episodes in one process: batches the policy's forward pass (measured, architecture.md)
    vec_env: str = "dummy"  # dummy (one process) | subproc (one process per env)
    normalize: bool = False  # VecNormalize on observations and rewards
    learning_rate: float = 3e-4
    gamma: float = 0.99
    net_arch: tuple[int, ...] = (64, 64)  # shared tanh MLP of the actor and the critic (Table 1)
    # PPO
    n_steps: int = 256  # per env, per rollout: 8 x 256 = Table 1's 2048 samples per update
    batch_size: int = 256
    n_epochs: int = 10
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    # SAC / TD3
    buffer_size: int = 200_000
    learning_starts: int = 1_000
    checkpoint_every: int = 50_000  # timesteps between checkpoints
    torch_threads: int = 1  # 64-64 MLPs train fastest on one CPU thread; more only adds contention
    extra: dict = field(default_factory=dict)  # further keyword arguments for the SB3 algorithm


@dataclass(frozen=True)
class BaselineConfig:
    """Search budget of the fixed-PID baseline (differential evolution over constant gains)."""

    episodes: int = 3  # seeded training episodes per cost evaluation
    maxiter: int = 20  # generations
    popsize: int = 8  # population = popsize x number of parameters
