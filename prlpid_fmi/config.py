"""Typed configuration of one tuning problem: plant, prior, loops, controller, strategies, reward, episodes.

The environment, training and evaluation read these frozen dataclasses; the scenario loader builds
them from a validated scenario file. Their defaults are NOT written here: each one is read from the
scenario schema (prlpid_fmi/schema/model.py, one pydantic class per YAML section), where it sits
with its unit and constraint. To change a default, change it there.
Units: seconds for times, samples ("steps") for counts, plant units for setpoints and signals.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from prlpid_fmi.control.reward import RewardWeights
from prlpid_fmi.schema import model as _m
from prlpid_fmi.schema.model import default as _d
from prlpid_fmi.schema.types import (
    Algorithm,
    AnchorOn,
    AntiWindup,
    DisturbanceKind,
    GainChange,
    GainMapping,
    GainScale,
    Isolation,
    Smoothing,
    VecEnv,
)


@dataclass(frozen=True)
class GainRange:
    """Range an action in [-1, 1] maps into. scale "log" (geometric, needs low > 0) or "linear"."""

    low: float
    high: float
    scale: GainScale = _d(_m.GainsModel, "Kp")[2]


def _gain(name: str) -> GainRange:
    return GainRange(*_d(_m.GainsModel, name))


@dataclass(frozen=True)
class LoopConfig:
    """One control loop: the FMU input it drives and the FMU output it measures.

    measurement_scale (plant units) normalises errors for the observation and the reward, so that
    the reward's clip bounds and bonus band mean the same for a level in cm and an angle in rad.
    control_scale [input units] normalises |u_k - u_{k-1}|; None: u_max - u_min when both are finite,
    else Kp.high * measurement_scale. divergence_bound: |measurement - setpoint| / measurement_scale
    past this ends the episode.
    """

    input: str
    output: str
    setpoint_range: tuple[float, float] = _d(_m.LoopModel, "setpoint_range")
    u_min: float = _d(_m.LoopModel, "u_limits")[0]
    u_max: float = _d(_m.LoopModel, "u_limits")[1]
    u_rate_limit: float = float("inf")  # [input units / s]; LoopModel.u_rate_limit null = inf (none)
    Kp: GainRange = _gain("Kp")
    Ti: GainRange = _gain("Ti")
    Td: GainRange = _gain("Td")
    measurement_scale: float = _d(_m.LoopModel, "measurement_scale")
    divergence_bound: float = _d(_m.LoopModel, "divergence_bound")
    control_scale: Optional[float] = _d(_m.LoopModel, "control_scale")


@dataclass(frozen=True)
class Disturbance:
    """A change applied during an episode, from start_step to end_step (exclusive; None = to the end).

    kind "fmu": set the FMU input or tunable parameter `target` to `value` (restored after end_step);
    kind "actuator" / "measurement": add `value` to the control signal / measurement of the loop whose
    output (measured variable) is named `target`.
    """

    kind: DisturbanceKind
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

    fmu: Optional[str] = _d(_m.PriorModel, "fmu")
    parameters: dict = field(default_factory=dict)
    state_map: dict = field(default_factory=dict)


@dataclass(frozen=True)
class AnchorBands:
    """How far the anchored gain map moves each gain from the tuned fixed PID (action -1 .. +1).

    Kp, Ti: factors >= 1 (Kp within [Kp0/f, Kp0*f]); Td: additive band, a fraction (0, 1] of the
    loop's Td range width; coupling: additive band for the coupling coefficients.
    """

    Kp: float = _d(_m.AnchorBandsModel, "Kp")
    Ti: float = _d(_m.AnchorBandsModel, "Ti")
    Td: float = _d(_m.AnchorBandsModel, "Td")
    coupling: float = _d(_m.AnchorBandsModel, "coupling")


@dataclass(frozen=True)
class TuningConfig:
    """Everything PidTuningEnv needs. `fmu` is a path to a .fmu file or a bundled plant's name."""

    fmu: str
    loops: tuple[LoopConfig, ...]
    plant_parameters: dict = field(default_factory=dict)
    sample_time_s: float = _d(_m.PlantModel, "sample_time")
    fmi_version: int = _d(_m.PlantModel, "fmi_version")  # for bundled plants only
    isolation: Isolation = _d(_m.PlantModel, "isolation")  # auto | process | none (prlpid_fmi.loop.isolated)
    leak_check_every: int = _d(_m.PlantModel, "leak_check_every")  # resets between leak checks; 0 = off
    leak_limit_mb: float = _d(_m.PlantModel, "leak_limit_mb")  # growth [MB] over one check that re-instantiates
    step_timeout_s: Optional[float] = _d(_m.PlantModel, "step_timeout_s")  # watchdog [s]; None: measured (fmu.watchdog)
    prior: PriorConfig = PriorConfig()
    # how the plant FMU serves as its own prior: None = as its description says (FmuDescription.prior_mode);
    # "rollback" = its own instance rolled back even where a second instance could be one (that instance kept
    # crashing: run.tune's prior fallback); not a scenario key
    prior_mode: Optional[str] = None
    # controller
    anti_windup: AntiWindup = _d(_m.ControllerModel, "anti_windup")
    gain_change: GainChange = _d(_m.ControllerModel, "gain_change")  # bumpless | positional (control.pid)
    derivative_filter_N: Optional[float] = _d(_m.ControllerModel, "derivative_filter_N")
    setpoint_weight: object = _d(_m.ControllerModel, "setpoint_weight")  # b in [0, 1] or "tuned"
    derivative_weight: float = _d(_m.ControllerModel, "derivative_weight")  # c in [0, 1]
    measurement_filter: object = _d(_m.ControllerModel, "measurement_filter")  # Tf [s] >= 0 or "tuned"
    measurement_filter_order: int = _d(_m.ControllerModel, "measurement_filter_order")  # 1 | 2
    # the (b, c, Tf) per loop in force once tuned (tuning.fixed_pid); None: from the three fields above, with
    # "tuned" read as b = 1 and Tf = 0 (loop.core.pid_structure)
    tuned_structure: Optional[tuple[tuple[float, float, float], ...]] = None
    coupled: bool = _d(_m.ControllerModel, "coupled")  # cross-axis coupled PID (paper eq. 26-27), needs 3 loops
    coupling_range: float = _d(_m.ControllerModel, "coupling_range")  # coupling coefficients in [-c, c]
    gain_mapping: GainMapping = _d(_m.ControllerModel, "gain_mapping")  # anchored (action 0 = tuned fixed PID) | absolute
    anchor_on: AnchorOn = _d(_m.ControllerModel, "anchor_on")  # auto (the classical schedule where built) | fixed_pid
    anchor_bands: AnchorBands = AnchorBands()
    # strategies
    forecast_horizon: int = _d(_m.StrategiesModel, "forecast_horizon")  # N; 0 = plain one-step reward
    smoothing: Smoothing = _d(_m.StrategiesModel, "smoothing")
    smoothing_window: int = _d(_m.StrategiesModel, "smoothing_window")
    smoothing_alpha: Optional[float] = _d(_m.StrategiesModel, "smoothing_alpha")  # None: the method's default
    reward: RewardWeights = RewardWeights()
    divergence_penalty: float = _d(_m.RewardModel, "divergence_penalty")
    # episodes
    episode_steps: int = _d(_m.TrainingModel, "episode_steps")
    setpoint_hold_steps: int = _d(_m.TrainingModel, "setpoint_hold_steps")
    setpoint_schedule: Optional[tuple[tuple[int, tuple[float, ...]], ...]] = None  # ((step, setpoints), ...)
    disturbances: tuple[Disturbance, ...] = ()
    measurement_noise_std: float = _d(_m.TrainingModel, "measurement_noise_std")  # plant units, Gaussian
    actuator_noise_std: float = _d(_m.TrainingModel, "actuator_noise_std")  # control-signal units, Gaussian
    randomize: dict = field(default_factory=dict)  # {FMU parameter: (low, high)} drawn uniformly per episode
    load_disturbance: float = _d(_m.TrainingModel, "load_disturbance")  # fraction of the control span; 0 = none

    @property
    def n_loops(self) -> int:
        return len(self.loops)


DEFAULT_N_ENVS = {"ppo": 8, "sac": 1, "td3": 1}  # docs/results.md "Training defaults"


def _agent(key: str):
    return _d(_m.AgentModel, key)


@dataclass(frozen=True)
class AgentConfig:
    """The RL agent and its training budget (meaning and unit of each field: schema.model.AgentModel)."""

    algorithm: Algorithm = _agent("algorithm")
    total_timesteps: int = _agent("total_timesteps")
    seed: int = _agent("seed")
    n_envs: Optional[int] = _agent("n_envs")  # None: DEFAULT_N_ENVS[algorithm]; use .envs
    vec_env: VecEnv = _agent("vec_env")
    normalize: bool = _agent("normalize")
    learning_rate: float = _agent("learning_rate")
    gamma: float = _agent("gamma")
    net_arch: tuple[int, ...] = _agent("net_arch")
    # PPO
    n_steps: int = _agent("n_steps")
    batch_size: int = _agent("batch_size")
    n_epochs: int = _agent("n_epochs")
    gae_lambda: float = _agent("gae_lambda")
    clip_range: float = _agent("clip_range")
    ent_coef: float = _agent("ent_coef")
    # SAC / TD3
    buffer_size: int = _agent("buffer_size")
    learning_starts: int = _agent("learning_starts")
    checkpoint_every: int = _agent("checkpoint_every")
    checkpoint_minutes: float = _agent("checkpoint_minutes")
    torch_threads: int = _agent("torch_threads")
    extra: dict = field(default_factory=dict)  # further keyword arguments for the SB3 algorithm

    @property
    def envs(self) -> int:
        """The number of parallel environments: n_envs, or DEFAULT_N_ENVS[algorithm] when it is None."""
        return self.n_envs if self.n_envs is not None else DEFAULT_N_ENVS[self.algorithm]


@dataclass(frozen=True)
class BaselineConfig:
    """Search budget of the fixed-PID baseline (differential evolution over constant gains)."""

    episodes: int = _d(_m.BaselineModel, "episodes")  # seeded training episodes per cost evaluation
    maxiter: int = _d(_m.BaselineModel, "maxiter")  # generations
    popsize: int = _d(_m.BaselineModel, "popsize")  # population = popsize x number of parameters
    objective: str = _d(_m.BaselineModel, "objective")  # load | setpoint
    load_step: float = _d(_m.BaselineModel, "load_step")  # fraction of the control span
    load_tolerance: float = _d(_m.BaselineModel, "load_tolerance")  # factor on the load optimum (step 4)
    widen_ranges: float = _d(_m.BaselineModel, "widen_ranges")  # factor on log ranges (and Td's high end)
    workers: int | None = _d(_m.BaselineModel, "workers")  # processes of the search (None: one per core)
    design_model: str = _d(_m.BaselineModel, "design_model")  # identified | fmu: the load search's cost


@dataclass(frozen=True)
class DeployConfig:
    """When a tuned controller may be deployed: its peak sensitivity Ms = max |S(jw)| stays <= max_sensitivity."""

    max_sensitivity: float = _d(_m.DeployModel, "max_sensitivity")
    max_overshoot: float = _d(_m.DeployModel, "max_overshoot")  # fraction of the setpoint step
    max_noise_gain: float = _d(_m.DeployModel, "max_noise_gain")  # std(u) from measurement noise / control span
    max_noise_increment: float = _d(_m.DeployModel, "max_noise_increment")  # std(u_k - u_k-1) from the noise / span
    max_chatter: float = _d(_m.DeployModel, "max_chatter")  # acceptance check: Chatter metric limit, fraction
    allow_unverified: bool = _d(_m.DeployModel, "allow_unverified")  # a schedule with an impossible Ms estimate
    classical_schedule: object = _d(_m.DeployModel, "classical_schedule")  # "auto" | True | False
    schedule_points: int = _d(_m.DeployModel, "schedule_points")
    schedule_by: str = _d(_m.DeployModel, "schedule_by")  # auto | setpoint | measurement | error
