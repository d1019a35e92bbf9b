"""The scenario file as pydantic models, one class per YAML section; the single home of every default.

Each field carries its default, its unit and meaning (the description) and its constraint (a
type from types.py or a validator), so the JSON Schema (``prlpid-fmi schema``), docs/scenarios.md
and the dataclasses of prlpid_fmi.config all read them from here. The defaults of the reward
weights and the smoothing window live beside their equations (control/reward.py, control/smoothing.py)
and are referenced, never copied.

Checks that need the FMU or an earlier section run in validators through the ``State`` in the
validation context (checks.py), in section order, so that one pass reports every mistake.
"""
from __future__ import annotations

import math
from typing import Annotated, Any, Literal, Optional

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from prlpid_fmi.control.reward import RewardWeights
from prlpid_fmi.control.smoothing import DEFAULT_ALPHA, DEFAULT_WINDOW
from prlpid_fmi.fmu.watchdog import MIN_STEP_TIMEOUT_S, STEP_TIMEOUT_FACTOR
from prlpid_fmi.schema import checks
from prlpid_fmi.schema.checks import check_variable, state_of
from prlpid_fmi.schema.types import (
    LOOP_TARGETS,
    Algorithm,
    AnchorOn,
    AntiWindup,
    AutoOrFlag,
    Count,
    DisturbanceType,
    Finite,
    Flag,
    Fraction,
    GainChange,
    GainMapping,
    GainScale,
    Isolation,
    Name,
    NonNegative,
    Positive,
    Seed,
    Smoothing,
    Steps,
    VecEnv,
    as_number,
    number,
    problem,
    tuned_or_number,
)

_REWARD = RewardWeights()


class Section(BaseModel):
    """A mapping in the scenario file: unknown keys are refused; models are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True)


def section(description: str) -> Any:
    """A section field: absent = all defaults (validated, so checks of defaulted keys run too)."""
    return Field(default_factory=dict, validate_default=True, description=description)


def _no_default_in_schema(schema: dict) -> None:
    schema.pop("default", None)  # JSON has no infinity


def _number_or_list(schema: dict) -> None:
    for k in ("type", "items"):
        schema.pop(k, None)
    schema["anyOf"] = [{"type": "number"}, {"type": "array", "items": {"type": "number"}}]


def _range(value: tuple, info: ValidationInfo) -> tuple:
    lo, hi = value[0], value[1]
    if not lo < hi:
        raise problem("low >= high", "low < high")
    return value


Range = Annotated[tuple[Finite, Finite], AfterValidator(_range)]


def _randomize_range(value: tuple) -> tuple:
    if not value[0] <= value[1]:
        raise problem("low > high", "[low, high] with low <= high")
    return value


RandomRange = Annotated[tuple[Finite, Finite], AfterValidator(_randomize_range)]


# ---------------------------------------------------------------------------------------------
# FMU variable names, checked against the FMU when a State is present

def _variable_check(causalities, role, variabilities=None, prior=False):
    def check(name: str, info: ValidationInfo) -> str:
        state = state_of(info)
        if state is None:
            return name
        if prior and state.prior_fmu_given is not False:  # another prior FMU: only once it is known to be valid
            desc = state.prior_desc
        else:
            desc = state.desc
        if desc is not None:
            check_variable(desc, name, causalities, role, variabilities)
        return name
    return AfterValidator(check)


PlantParameter = Annotated[Name, _variable_check(("parameter", "input"), "a parameter")]
PriorParameter = Annotated[Name, _variable_check(("parameter", "input"), "a parameter", prior=True)]
PriorStateParameter = Annotated[Name, _variable_check(("parameter",), "a prior parameter", prior=True)]
PlantVariable = Annotated[Name, _variable_check(("output", "local", "parameter", "input"), "a plant variable")]
RandomizedParameter = Annotated[Name, _variable_check(("parameter", "input"), "a parameter or input")]


# ---------------------------------------------------------------------------------------------
# plant

class GainsModel(Section):
    """Ranges an action in [-1, 1] maps into: [low, high] or [low, high, scale]; scale log (geometric,
    low > 0) or linear (ranges containing 0 or negative values); without a scale the default's is kept."""

    Kp: tuple[Finite, Finite, GainScale] = Field(
        (0.1, 10.0, "log"), json_schema_extra={"minItems": 2},
        description="proportional gain range [input units / output units]; a negative linear range for a "
                    "reverse-acting plant")
    Ti: tuple[Finite, Finite, GainScale] = Field(
        (0.1, 100.0, "log"), json_schema_extra={"minItems": 2},
        description="integral time range [s], low > 0 (Ti divides the integral term)")
    Td: tuple[Finite, Finite, GainScale] = Field(
        (0.0, 1.0, "linear"), json_schema_extra={"minItems": 2},
        description="derivative time range [s], low >= 0")

    @field_validator("Kp", "Ti", "Td", mode="before")
    @classmethod
    def _default_scale(cls, value: Any, info: ValidationInfo) -> Any:
        if isinstance(value, (list, tuple)):
            if len(value) == 2:
                return [*value, cls.model_fields[info.field_name].default[2]]
            if len(value) != 3:
                raise problem(f"list of length {len(value)}", "[low, high] or [low, high, log|linear]")
        return value

    @field_validator("Kp", "Ti", "Td")
    @classmethod
    def _bounds(cls, value: tuple, info: ValidationInfo) -> tuple:
        lo, hi, scale = value
        if not lo < hi:
            raise problem("low >= high", "low < high")
        if scale == "log" and lo <= 0:
            raise problem("a log range needs low > 0", "low > 0, or scale linear")
        if info.field_name == "Ti" and lo <= 0:
            raise problem("Ti divides the integral term and must stay > 0", "low > 0")
        if info.field_name == "Td" and lo < 0:
            raise problem("Td must be >= 0", "low >= 0")
        return value


class LoopModel(Section):
    """One control loop: the FMU input the PID drives and the FMU output it measures."""

    input: Name = Field(description="FMU variable (causality input) the PID drives")
    output: Name = Field(description="FMU variable (causality output or local) it measures; also names the loop")
    u_limits: tuple[number(infinite=True), number(infinite=True)] = Field(
        (-math.inf, math.inf), json_schema_extra=_no_default_in_schema,
        description="[min, max] saturation of the control signal [input units]; default [-.inf, .inf]; "
                    "the only numbers that may be infinite")
    u_rate_limit: Optional[Positive] = Field(
        None, description="|du/dt| limit of the control signal [input units / s] that the PID honours (its anti-windup "
                          "treats the limit like saturation), the search and every export too; null: none")
    setpoint_range: Range = Field((0.0, 1.0), description="[low, high] training setpoints are drawn from "
                                                          "[output units]")
    measurement_scale: Positive = Field(1.0, description="typical setpoint step [output units]; errors are divided "
                                                         "by it for the observation and the reward")
    divergence_bound: Positive = Field(100.0, description="|measurement - setpoint| / measurement_scale beyond which "
                                                          "the episode ends with reward.divergence_penalty")
    control_scale: Optional[Positive] = Field(
        None, description="[input units] normalises |u_k - u_{k-1}| in the control-variation penalty; null: "
                          "u_max - u_min when both are finite, else Kp.high * measurement_scale")
    gains: GainsModel = section("ranges of Kp, Ti, Td")

    @field_validator("u_limits")
    @classmethod
    def _limits(cls, value: tuple) -> tuple:
        if not value[0] < value[1]:
            raise problem("low >= high", "min < max")
        return value

    @field_validator("divergence_bound")
    @classmethod
    def _reachable(cls, bound: float, info: ValidationInfo) -> float:
        low_high, scale = info.data.get("setpoint_range"), info.data.get("measurement_scale")
        span = (low_high[1] - low_high[0]) / scale if low_high is not None and scale is not None else 0.0
        if span > bound:
            raise problem(f"a training setpoint step across setpoint_range, {span:g} x measurement_scale, would end "
                          "the episode as diverged at once", f"a bound >= {span:g}, or a narrower setpoint_range")
        return bound

    @model_validator(mode="after")
    def _remember_largest_step(self, info: ValidationInfo) -> "LoopModel":
        state = state_of(info)
        if state is not None:
            state.largest_step.append(self.divergence_bound * self.measurement_scale)
        return self

    @field_validator("input", "output")
    @classmethod
    def _fmu_variable(cls, name: str, info: ValidationInfo) -> str:
        state = state_of(info)
        if state is not None:
            what = info.field_name
            seen = state.loop_inputs if what == "input" else state.outputs
            taken = name in seen
            seen.append(name)
            if taken:
                raise problem(f"two loops share the {what}", f"a different {what} per loop")
            if state.desc is not None:
                check_variable(state.desc, name, ("input",) if what == "input" else ("output", "local"),
                               f"a loop {what}")
        return name


class PlantModel(Section):
    """The plant FMU and its control loops."""

    fmu: Name = Field(description="a bundled plant's name (built on demand) or a path to a .fmu file, relative to "
                                  "the scenario's folder")
    fmi_version: Literal[2, 3] = Field(2, description="2 or 3: which build of a bundled plant; ignored for .fmu paths")
    sample_time: Positive = Field(0.1, description="control period Ts [s]; the FMU is stepped by this")
    parameters: dict[PlantParameter, Finite] = Field(
        default_factory=dict, description="{FMU parameter or input: value} set before every episode [FMU units]")
    loops: list[LoopModel] = Field(min_length=1, description="one loop per controlled output, at least one")
    isolation: Isolation = Field(
        "auto", description="where the FMU (plant and prior) runs: none = in this process (fastest); process = in a "
                            "worker process, so a crashing FMU ends its episode instead of the tool; auto = in this "
                            "process, switched to process for the rest of the run once the FMU crashed a worker (the "
                            "loop check, a margin experiment, a search) or the tool's own process (`tune` then "
                            "resumes the run), and when `tune --resume` finds the run ended abruptly")
    leak_check_every: Steps = Field(
        100, description="resets between checks of the memory the FMU's resets added; 0 = no check")
    leak_limit_mb: Positive = Field(
        64.0, description="memory [MB] the resets may add between two checks before the FMU is instantiated afresh")
    step_timeout_s: Optional[Positive] = Field(
        None, description="a call into the FMU (a step, a reset, its instantiation) that has not returned after this "
                          "many seconds ends the run with one line, the run directory kept (with isolation process: "
                          f"ends its episode like a crash); null = {STEP_TIMEOUT_FACTOR:g} x the measured cost of a step, at "
                          f"least {MIN_STEP_TIMEOUT_S:g} s")

    @model_validator(mode="before")
    @classmethod
    def _remember_version(cls, data: Any, info: ValidationInfo) -> Any:
        state = state_of(info)
        if state is not None and isinstance(data, dict):
            fallback = cls.model_fields["fmi_version"].default
            version = data.get("fmi_version", fallback)
            state.fmi_version = version if version in (2, 3) and not isinstance(version, bool) else fallback
            loops = data.get("loops")
            state.n_loops = len(loops) if isinstance(loops, list) else None
        return data

    @field_validator("fmu")
    @classmethod
    def _fmu(cls, value: str, info: ValidationInfo) -> str:
        state = state_of(info)
        if state is None:
            return value
        resolved, path = checks.scenario_fmu(value, state)
        desc = checks.describe(path)
        if not (desc.co_simulation or desc.model_exchange):
            raise problem("the FMU has neither a co-simulation nor a model-exchange interface",
                          "an FMU exported for co-simulation or model exchange")
        state.desc = desc
        return resolved


class PriorModel(Section):
    """The model the reward forecast runs on (paper eq. 12-14)."""

    fmu: Optional[Name] = Field(
        None, description="null: the plant FMU itself: a second instance that receives the plant's state each step "
                          "(needs canGetAndSetFMUstate and canSerializeFMUstate), or, for an FMU that cannot serialize "
                          "its state or may be instantiated only once per process, the plant's own instance rolled "
                          "N steps and set back (needs canGetAndSetFMUstate); else a bundled name or a path of "
                          "another FMU with the same loop inputs and outputs")
    parameters: dict[PriorParameter, Finite] = Field(
        default_factory=dict, description="{prior parameter: value} applied after every state copy (model mismatch) "
                                          "[FMU units]")
    state_map: dict[PriorStateParameter, PlantVariable] = Field(
        default_factory=dict, validate_default=True,
        description="{prior parameter: plant variable}: a different prior FMU cannot take the plant's state, so it "
                    "is re-initialised each step from these plant values; required when fmu is given")

    @model_validator(mode="before")
    @classmethod
    def _remember_fmu(cls, data: Any, info: ValidationInfo) -> Any:
        state = state_of(info)
        if state is not None:
            state.prior_fmu_given = None if not isinstance(data, dict) else data.get("fmu") is not None
        return data

    @field_validator("fmu")
    @classmethod
    def _fmu(cls, value: Optional[str], info: ValidationInfo) -> Optional[str]:
        state = state_of(info)
        if state is None or value is None:
            return value
        resolved, path = checks.scenario_fmu(value, state)
        desc = checks.describe(path)
        for i, (u, y) in enumerate(zip(state.loop_inputs, state.outputs)):
            try:
                check_variable(desc, u, ("input",), f"loop {i}'s input")
                check_variable(desc, y, ("output", "local"), f"loop {i}'s output")
            except PydanticCustomError:
                raise problem(f"the prior FMU {path.name} lacks loop {i}'s input {u!r} or output {y!r}",
                              "an FMU with the plant's loop inputs and outputs") from None
        state.prior_desc = desc
        return resolved

    @field_validator("state_map")
    @classmethod
    def _state_map(cls, value: dict, info: ValidationInfo) -> dict:
        state = state_of(info)
        fmu = info.data.get("fmu")
        if (state is not None and fmu is not None and not value and state.prior_desc is not None
                and state.desc is not None and state.prior_desc.path != state.desc.path):
            raise problem("a different prior FMU needs a state map",
                          "a mapping {prior parameter: plant variable} (its state cannot be copied from the plant)")
        return value


# ---------------------------------------------------------------------------------------------
# controller, strategies, reward

class AnchorBandsModel(Section):
    """How far the anchored gain map moves each gain from the tuned fixed PID's (action -1 .. 1)."""

    Kp: number(ge=1) = Field(3.0, description="factor f >= 1: Kp within [Kp0 / f, Kp0 * f]")
    Ti: number(ge=1) = Field(3.0, description="factor f >= 1: Ti within [Ti0 / f, Ti0 * f]")
    Td: number(gt=0, le=1) = Field(0.1, description="additive band, a fraction (0, 1] of the loop's Td range width: "
                                                    "Td within Td0 +- band * (Td.high - Td.low)")
    coupling: NonNegative = Field(0.1, description="additive band of the coupling coefficients: c within c0 +- band")


class ControllerModel(Section):
    """The PID structure and how actions become gains."""

    anti_windup: AntiWindup = Field("clamping", description="clamping | back_calculation | none")
    gain_change: GainChange = Field(
        "bumpless", description="bumpless: when Kp, Ti, Td change between samples the error sum is rescaled so that "
                                "u does not jump (the P and D terms' changes included); positional: the paper's eq. 2, "
                                "a gain change acts on the whole sum")
    derivative_filter_N: Optional[Positive] = Field(
        None, description="null: unfiltered derivative; N > 0: first-order filter with time constant Td / N")
    setpoint_weight: tuned_or_number(0.0, 1.0) = Field(
        "tuned", description="b in [0, 1], the setpoint's weight in the proportional term (1: the paper's eq. 2); "
                             "tuned: chosen after the feedback gains, the fastest setpoint response within "
                             "deploy.max_overshoot (b changes neither Ms nor the load response)")
    derivative_weight: Fraction = Field(
        0.0, description="c in [0, 1], the setpoint's weight in the derivative term; 0: derivative on the measurement "
                         "(no derivative kick), 1: on the error (the paper's eq. 2)")
    measurement_filter: tuned_or_number(0.0) = Field(
        "tuned", description="Tf [s] of the low pass on the measurement that feeds P and D (0: none); tuned: searched "
                             "with the feedback gains when the scenario has measurement noise, else 0")
    measurement_filter_order: Literal[1, 2] = Field(
        1, description="1: 1/(1 + s Tf); 2: 1/(1 + s Tf/2)^2 (steeper roll-off for derivative action)")
    coupled: Flag = Field(False, description="cross-axis coupled PID (paper eq. 26-27); needs exactly 3 loops (roll, "
                                             "pitch, yaw); adds 6 coupling actions")
    coupling_range: Positive = Field(0.5, description="coupling coefficients lie in [-c, c]")
    gain_mapping: GainMapping = Field(
        "anchored", description="anchored: action 0 gives exactly the anchor's gains (anchor_on) and each action "
                                "moves its gain within anchor_bands; absolute: the paper's map over the whole gain range")
    anchor_on: AnchorOn = Field(
        "auto", description="what action 0 of the anchored gain map gives: auto: the classical gain schedule's gains "
                            "at the current setpoint where tune builds one (deploy.classical_schedule), else the "
                            "tuned fixed PID's; fixed_pid: always the tuned fixed PID's (the map before the classical "
                            "schedule)")
    anchor_bands: AnchorBandsModel = section("bands of the anchored gain map")

    @field_validator("coupled")
    @classmethod
    def _three_loops(cls, coupled: bool, info: ValidationInfo) -> bool:
        state = state_of(info)
        if coupled and state is not None and state.n_loops is not None and state.n_loops != 3:
            raise problem(f"the cross-axis coupled PID needs exactly 3 loops, the plant has {state.n_loops}",
                          "false, or 3 loops (roll, pitch, yaw)")
        return coupled


class StrategiesModel(Section):
    """PRL-PID's strategies: reward forecast on the prior, action smoothing."""

    forecast_horizon: Steps = Field(3, validate_default=True,
                                    description="N [samples]: the reward is forecast N steps ahead on the prior "
                                                "(eq. 12-14); 0 = plain one-step reward")
    smoothing: Smoothing = Field("era", description="action smoothing: none | sma (eq. 19) | lwma (eq. 20) | era "
                                                    "(eq. 21)")
    smoothing_window: Count = Field(DEFAULT_WINDOW, description="M [samples], window of sma and lwma")
    smoothing_alpha: Optional[Finite] = Field(
        None, description="null: the method's default (" + ", ".join(f"{k} {v}" for k, v in DEFAULT_ALPHA.items())
                          + "); lwma: [0, 1], era: (0, 1]; not for none / sma")

    @field_validator("forecast_horizon")
    @classmethod
    def _prior_can_copy(cls, horizon: int, info: ValidationInfo) -> int:
        state = state_of(info)
        episode = state.raw_training_steps if state is not None else None
        if horizon > 0 and episode is not None and horizon >= episode:
            raise problem(f"a forecast as long as a training episode ({episode} samples) or longer looks past its "
                          f"end and costs {horizon} prior steps per sample",
                          f"0 <= N < training.episode_steps = {episode} (the paper uses N <= 10)")
        if horizon > 0 and state is not None and state.prior_fmu_given is False and state.desc is not None:
            problems = state.desc.prior_problems()
            if problems:
                raise problem("the plant FMU cannot serve as its own prior: " + "; ".join(problems),
                              "0 (no reward forecast), or a prior.fmu with a state_map")
        return horizon

    @field_validator("smoothing_alpha")
    @classmethod
    def _alpha(cls, alpha: Optional[float], info: ValidationInfo) -> Optional[float]:
        method = info.data.get("smoothing")
        if alpha is None or method is None:
            return alpha
        if method not in DEFAULT_ALPHA:
            raise problem(f"smoothing {method!r} takes no alpha", f"null, or smoothing {' / '.join(DEFAULT_ALPHA)}")
        if not ((alpha >= 0 if method == "lwma" else alpha > 0) and alpha <= 1):
            raise problem("out of range", "a number in [0, 1]" if method == "lwma" else "a number in (0, 1]")
        return alpha


class RewardModel(Section):
    """Hierarchical reward (paper eq. 10-11) on errors divided by each loop's measurement_scale."""

    alpha: NonNegative = Field(_REWARD.alpha, description="weight of clip(V), V = e^2 / 2")
    beta: NonNegative = Field(_REWARD.beta, description="weight of clip(|e|)")
    v_clip: Positive = Field(_REWARD.v_clip, description="clip bound of V [normalised error^2]")
    e_clip: Positive = Field(_REWARD.e_clip, description="clip bound of |e| [normalised error]")
    bonus_threshold: NonNegative = Field(_REWARD.bonus_threshold, description="|e| below which the bonus is paid")
    bonus_numerator: NonNegative = Field(_REWARD.bonus_numerator, description="bonus = numerator / (|e| + offset)")
    bonus_offset: Positive = Field(_REWARD.bonus_offset, description="offset of the bonus denominator")
    control_variation_weight: NonNegative = Field(
        _REWARD.control_variation_weight,
        description="weight of the per-step penalty min(|u_k - u_{k-1}| / control_scale, 1), averaged over loops")
    divergence_penalty: Finite = Field(-100.0, description="reward of the step that ends an episode by divergence")


# ---------------------------------------------------------------------------------------------
# agent

class AgentModel(Section):
    """The RL agent and its training budget (paper Table 1 / Algorithm 1 for PPO)."""

    algorithm: Algorithm = Field("ppo", validate_default=True, description="ppo | sac | td3")
    total_timesteps: Count = Field(500_000, description="training budget [env steps]")
    seed: Seed = Field(0, description="seed of training")
    n_envs: Optional[Count] = Field(None, description="parallel environments; null: 8 for PPO (8 episodes in one "
                                                      "process batch the policy's forward pass; docs/results.md "
                                                      "\"Training defaults\"), 1 for SAC / TD3 (one gradient step "
                                                      "per env step, as their defaults assume)")
    vec_env: VecEnv = Field("dummy", description="dummy (one process) | subproc (one process per env)")
    normalize: Flag = Field(False, description="VecNormalize on observations and rewards")
    learning_rate: Positive = Field(3e-4, description="optimiser step size")
    gamma: Fraction = Field(0.99, description="discount factor")
    net_arch: tuple[Count, ...] = Field((64, 64), min_length=1,
                                        description="hidden layer sizes of the shared tanh MLP (Table 1)")
    n_steps: Count = Field(256, description="PPO: env steps per env per rollout (8 envs x 256 = Table 1's 2048 "
                                            "samples per update)")
    batch_size: Count = Field(256, description="minibatch size [transitions]")
    n_epochs: Count = Field(10, description="PPO: passes over each rollout")
    gae_lambda: Fraction = Field(0.95, description="PPO: GAE lambda")
    clip_range: Positive = Field(0.2, description="PPO: policy clip range")
    ent_coef: NonNegative = Field(0.0, description="PPO: entropy bonus weight")
    buffer_size: Count = Field(200_000, description="SAC / TD3: replay buffer [transitions]")
    learning_starts: Steps = Field(1_000, description="SAC / TD3: env steps before learning starts")
    checkpoint_every: Count = Field(50_000, description="env steps between checkpoints")
    checkpoint_minutes: Positive = Field(5.0, description="wall-clock minutes between checkpoints (whichever of "
                                                          "checkpoint_every and this comes first)")
    torch_threads: Count = Field(1, description="CPU threads of torch (64-64 MLPs train fastest on one)")
    extra: dict[Annotated[Name, AfterValidator(lambda k, info: _extra_key(k, info))], Any] = Field(
        default_factory=dict, description="further keyword arguments of the Stable-Baselines3 algorithm's "
                                          "constructor (checked against its signature)")

    @field_validator("algorithm")
    @classmethod
    def _remember(cls, algorithm: str, info: ValidationInfo) -> str:
        state = state_of(info)
        if state is not None:
            state.algorithm = algorithm
        return algorithm


def _extra_key(key: str, info: ValidationInfo) -> str:
    state = state_of(info)
    if state is not None and state.algorithm is not None:
        checks.check_extra_key(key, state.algorithm, tuple(AgentModel.model_fields))
    return key


# ---------------------------------------------------------------------------------------------
# episodes: setpoints, disturbances, intervals

def _setpoint_value(value: Any, info: ValidationInfo) -> Any:
    state = state_of(info)
    n = state.n_loops if state is not None else None
    if isinstance(value, (list, tuple)):
        if n is not None and len(value) != n:
            raise problem(f"{len(value)} setpoints for {n} loop(s)", f"a list of {n} numbers, one per loop")
        return value
    value = as_number(value)
    if n is not None and n != 1:
        raise problem(f"a single setpoint for {n} loops", f"a list of {n} numbers, one per loop")
    return [value]


class SetpointModel(Section):
    """One entry of a setpoint schedule, held until the next entry."""

    at_step: Steps = Field(description="first sample of this setpoint; the schedule starts at 0 and increases")
    value: Annotated[tuple[Finite, ...], BeforeValidator(_setpoint_value)] = Field(
        json_schema_extra=_number_or_list,
        description="setpoint [output units]: a number (one loop) or a list with one number per loop")

    @field_validator("at_step")
    @classmethod
    def _order(cls, step: int, info: ValidationInfo) -> int:
        state = state_of(info)
        if state is None:
            return step
        first, last = state.last_step < 0, state.last_step
        state.last_step = step
        n = state.episode_steps
        if first and step != 0:
            raise problem("the schedule must start at step 0", "0")
        if step <= last or (n is not None and step >= n):
            raise problem("out of order or past the episode",
                          f"an integer in ({last}, {n}) (episode_steps = {n})" if n else f"an integer > {last}")
        return step

    @field_validator("value")
    @classmethod
    def _reachable(cls, value: tuple, info: ValidationInfo) -> tuple:
        """A step from the previous setpoint larger than divergence_bound x measurement_scale ends the episode
        at its first sample, whatever the controller: refused (known only when every loop was valid)."""
        state = state_of(info)
        if state is None:
            return value
        previous, state.last_setpoint = state.last_setpoint, value
        largest = state.largest_step
        if previous is None or len(largest) != state.n_loops or len(value) != len(largest):
            return value
        for i, (a, b, limit) in enumerate(zip(previous, value, largest)):
            if abs(b - a) > limit:
                loop = f"plant.loops[{i}]"
                raise problem(f"the step from {a:g} to {b:g} is larger than {loop}.divergence_bound x "
                              f"measurement_scale = {limit:g} and would end the episode as diverged at once",
                              f"a step <= {limit:g}, or a larger {loop}.divergence_bound")
        return value


def _schedule(value: Any, info: ValidationInfo) -> Any:
    state = state_of(info)
    if state is not None:
        state.last_step, state.last_setpoint = -1, None
    if isinstance(value, list) and not value:
        raise problem("empty schedule", "at least one {at_step: 0, value: ...}, or null")
    return value


Schedule = Annotated[Optional[list[SetpointModel]], BeforeValidator(_schedule)]


class DisturbanceModel(Section):
    """A change during an episode: an FMU input or tunable parameter is set, or a loop's signal is offset."""

    type: DisturbanceType = Field(description="step (from at_step on; an optional duration_steps ends it) | pulse "
                                              "(needs duration_steps) | parameter_change (a tunable FMU parameter)")
    target: Name = Field(description="an FMU input or tunable parameter (set to value, restored after a pulse), or "
                                     "actuator / measurement (value is added to that loop's control signal / "
                                     "measurement)")
    loop: Optional[Name] = Field(None, validate_default=True,
                                 description="for actuator / measurement: the loop, named by its output; may be "
                                             "omitted with one loop")
    at_step: Steps = Field(description="first sample of the disturbance, inside the episode")
    duration_steps: Optional[Count] = Field(None, validate_default=True,
                                            description="[samples] the disturbance ends at at_step + duration_steps")
    value: Finite = Field(description="the value set or added [target units]")

    @field_validator("target")
    @classmethod
    def _target(cls, target: str, info: ValidationInfo) -> str:
        kind = info.data.get("type")
        if target in LOOP_TARGETS:
            if kind == "parameter_change":
                raise problem("a parameter_change needs an FMU parameter", "the name of a tunable parameter of the FMU")
            return target
        state = state_of(info)
        if state is not None and state.desc is not None and kind is not None:
            if kind == "parameter_change":
                check_variable(state.desc, target, ("parameter",), "a parameter", ("tunable",))
            else:
                check_variable(state.desc, target, ("input", "parameter"), "an input or tunable parameter",
                               ("tunable",))
        return target

    @field_validator("loop")
    @classmethod
    def _loop(cls, loop: Optional[str], info: ValidationInfo) -> Optional[str]:
        target = info.data.get("target")
        if target is None:
            return loop
        if target not in LOOP_TARGETS:
            if loop is not None:
                raise problem(f"only for targets {' / '.join(LOOP_TARGETS)}", "no loop key for an FMU variable target")
            return loop
        state = state_of(info)
        outputs = state.outputs if state is not None else None
        if outputs is None or state.n_loops is None:
            return loop
        if loop is None and len(outputs) == 1:
            return outputs[0]
        if loop not in outputs:
            raise problem("not a loop output" if loop is not None else "missing key (several loops)",
                          f"the output of a loop: {', '.join(outputs)}")
        return loop

    @field_validator("at_step")
    @classmethod
    def _inside(cls, step: int, info: ValidationInfo) -> int:
        state = state_of(info)
        n = state.episode_steps if state is not None else None
        if n is not None and step >= n:
            raise problem("outside the episode", f"an integer in [0, {n})")
        return step

    @field_validator("duration_steps")
    @classmethod
    def _pulse(cls, duration: Optional[int], info: ValidationInfo) -> Optional[int]:
        if duration is None and info.data.get("type") == "pulse":
            raise problem("missing key (a pulse needs a duration)", "an integer >= 1")
        return duration


def _interval(value: tuple, info: ValidationInfo) -> tuple:
    state = state_of(info)
    n = state.episode_steps if state is not None else None
    a, b = value
    if not (0 <= a < b and (n is None or b <= n)):
        raise problem("outside the evaluation episode or empty",
                      f"0 <= start < end <= {n} (evaluation.episode_steps)" if n else "0 <= start < end")
    return value


Interval = Annotated[tuple[Steps, Steps], AfterValidator(_interval)]


# ---------------------------------------------------------------------------------------------
# training, evaluation, baseline, deploy

class _EpisodeSection(Section):
    """A section with its own episode length, which the checks of its setpoints, disturbances and intervals use
    (evaluation: null = training's)."""

    @model_validator(mode="before")
    @classmethod
    def _forget(cls, data: Any, info: ValidationInfo) -> Any:
        state = state_of(info)
        if state is not None:
            state.episode_steps = None
        return data

    @field_validator("episode_steps", check_fields=False)
    @classmethod
    def _remember(cls, steps: Optional[int], info: ValidationInfo) -> Optional[int]:
        state = state_of(info)
        if state is not None:
            state.episode_steps = steps if steps is not None else state.training_steps
            if cls is TrainingModel:
                state.training_steps = steps
        return steps


class TrainingModel(_EpisodeSection):
    """Training episodes: random (or scheduled) setpoints, noise, disturbances, parameter randomisation."""

    episode_steps: Count = Field(200, validate_default=True, description="length of a training episode [samples]")
    setpoint_hold_steps: Count = Field(100, description="a new random setpoint (from each loop's setpoint_range) "
                                                        "every this many samples")
    setpoints: Schedule = Field(None, description="a fixed schedule instead of random setpoints (format as in "
                                                  "evaluation); null: random")
    measurement_noise_std: NonNegative = Field(0.0, description="Gaussian noise on every measurement [output units]")
    actuator_noise_std: NonNegative = Field(0.0, description="Gaussian noise on every control signal [input units]")
    disturbances: list[DisturbanceModel] = Field(default_factory=list, description="disturbances of every episode")
    load_disturbance: number(ge=0, le=1) = Field(
        0.05, description="with random setpoints, a load step at the plant input in the second half of every "
                          "setpoint hold (a random loop, a random sign), this fraction of the loop's control span; "
                          "0: none (the paper's episodes)")
    randomize: dict[RandomizedParameter, RandomRange] = Field(
        default_factory=dict, description="{FMU parameter or input: [low, high]}: drawn uniformly and set before "
                                          "every episode starts, like plant.parameters [FMU units]")


class EvaluationModel(_EpisodeSection):
    """The evaluation episode(s) a trained controller is judged on; unset keys inherit training's."""

    episode_steps: Optional[Count] = Field(None, validate_default=True,
                                           description="length of the evaluation episode [samples]; default: "
                                                       "training.episode_steps")
    setpoints: Schedule = Field(None, description="[{at_step, value}, ...]: first at_step 0, increasing, inside the "
                                                  "episode; null: random setpoints as in training, seeded by seed")
    intervals: list[Interval] = Field(default_factory=list,
                                      description="[[start_step, end_step], ...] half-open windows for per-interval "
                                                  "metrics (ISE / IAE per interval, Table 2) [samples]")
    disturbances: Optional[list[DisturbanceModel]] = Field(None, description="default: training.disturbances")
    measurement_noise_std: Optional[NonNegative] = Field(None, description="[output units]; default: training's")
    actuator_noise_std: Optional[NonNegative] = Field(None, description="[input units]; default: training's")
    seed: Seed = Field(0, description="seed of the evaluation episode (noise, random setpoints)")
    randomize: Optional[dict[RandomizedParameter, RandomRange]] = Field(
        None, description="{parameter: [low, high]} of the Monte-Carlo evaluation set; default: training.randomize")
    randomize_samples: Steps = Field(0, description="number of randomised evaluation episodes (parameters drawn from "
                                                    "randomize); 0 = no Monte-Carlo set")


class BaselineModel(Section):
    """Search budget of the fixed-PID baseline: differential evolution over constant gains inside the gain ranges,
    each candidate scored on seeded training episodes."""

    objective: Literal["load", "setpoint"] = Field(
        "load", description="load: Kp, Ti, Td (and Tf) minimise the IAE of load steps at the plant input at the low, "
                            "middle and high setpoint, subject to deploy.max_sensitivity and deploy.max_noise_gain, "
                            "then b shapes the setpoint response; setpoint: the paper-era cost, ISE of the training "
                            "episodes plus the reward's control-variation term")
    load_step: number(gt=0, le=1) = Field(
        0.1, description="size of the load steps of the load objective, a fraction of the loop's control span "
                         "(u_max - u_min, or control_scale)")
    load_tolerance: number(ge=1) = Field(
        1.15, description="when no setpoint weight keeps the overshoot within deploy.max_overshoot, the feedback gains "
                          "may give up load rejection up to this factor on the load optimum's IAE to meet it")
    widen_ranges: number(ge=1) = Field(
        4.0, description="factor f >= 1 by which the search widens log gain ranges at both ends ([low/f, high*f]) "
                          "and Td's high end, so that the optimum of a plant lies inside; 1: the scenario's ranges "
                          "exactly (the paper's sweeps)")
    episodes: Count = Field(3, description="seeded training episodes per cost evaluation")
    maxiter: Count = Field(20, description="generations of differential evolution")
    popsize: Count = Field(10, description="population = popsize x number of gains searched")
    workers: Optional[Count] = Field(
        None, description="processes that evaluate the search's candidates (and the margin experiments of the "
                          "stages after training) side by side, each with its own FMU instances; null: one per CPU "
                          "core this process may use (1 in a sweep's trial). The result does not depend on it")
    design_model: Literal["identified", "fmu"] = Field(
        "identified", description="identified: the load search evaluates its candidates on a local linear model per "
                                  "operating point, fitted to the frequency response measured there, and the chosen "
                                  "gains are verified on the FMU (the search reruns on the FMU where the two load "
                                  "IAEs differ by more than 10 % or the FMU's loop chatters; with several loops, one model "
                                  "per loop, connected through their PIDs); fmu: every candidate simulated on the FMU")


ClassicalSchedule = AutoOrFlag  # deploy.classical_schedule (prlpid_fmi.tuning.schedule.classical)
ScheduleBy = Literal["auto", "setpoint", "measurement", "error"]  # deploy.schedule_by (prlpid_fmi.tuning.schedule.trajectories)


class DeployModel(Section):
    """When a tuned controller may be deployed."""

    max_sensitivity: number(gt=1) = Field(2.0, description="limit of the peak sensitivity Ms = max |S(jw)|; a "
                                                           "controller above it is never deployed")
    max_overshoot: NonNegative = Field(0.05, description="setpoint overshoot limit of the tuned setpoint weight b, "
                                                         "a fraction of the step")
    max_noise_gain: Positive = Field(
        0.02, description="limit of the standard deviation of u caused by the scenario's measurement noise, a fraction "
                          "of the loop's control span (from |C S| over the Nyquist band at each operating point)")
    max_noise_increment: Positive = Field(
        0.005, description="limit of the standard deviation of the sample-to-sample change of u caused by the "
                           "scenario's measurement noise, a fraction of the loop's control span (from |C S| weighted "
                           "by |1 - exp(-j w Ts)| over the Nyquist band); 0.005: twice it is the chatter metric's "
                           "1 % threshold, so noise alone reverses u by more than that on a few % of samples at most")
    max_chatter: Fraction = Field(
        0.05, description="acceptance check: the largest fraction of samples at which a deployed controller's command "
                          "may oscillate at the sample rate (three moves in a row of alternating sign, each above 1 % "
                          "of the control span: a limit cycle, a ringing derivative, a command toggling at a limit) "
                          "on noise-free held-out episodes and on steps from one end of the setpoint range to the "
                          "other: a controller above it is never deployed (the fixed PID's design holds it to 0.8 x "
                          "this); the Chatter metric with the scenario's measurement noise above it is reported, "
                          "not refused")
    allow_unverified: Flag = Field(False, description="deploy a gain schedule whose robustness could not be verified "
                                                      "(an Ms estimate impossible to make: the plant varies faster "
                                                      "than the margin experiment); default false: such a schedule "
                                                      "is not deployed (the fixed PID may be, said in the verdict)")
    classical_schedule: ClassicalSchedule = Field(
        "auto", description="the classical gain schedule (local load designs at setpoints across the range, "
                            "interpolated over the setpoint) as a candidate: true, false, or auto: where the plant's "
                            "frequency response varies over the setpoint range by more than 25 %")
    schedule_points: Count = Field(9, description="operating points (rows) of the gain schedule `tune` reads from "
                                                  "the policy: setpoints evenly spaced over the first loop's "
                                                  "setpoint_range; Ms is measured at each")
    schedule_by: ScheduleBy = Field("auto", description="scheduling variable of the gain schedule `tune` reads from "
                                                        "the policy: setpoint or measurement (of the first loop; "
                                                        "gains settled at held setpoints), error (setpoint - "
                                                        "measurement; gains the policy applied on training episodes, "
                                                        "binned by the error, so that its adaptation during "
                                                        "transients is kept), or auto: the setpoint and error tables, "
                                                        "the one with the lower ISE on seeded training episodes")


_MISSING_STEPS = object()


class ScenarioModel(Section):
    """A prlpid-fmi scenario: one tuning problem (docs/scenarios.md)."""

    model_config = ConfigDict(extra="forbid", frozen=True, title="prlpid-fmi scenario")

    name: Optional[Name] = Field(None, description="scenario name (run directories, reports); default: the file "
                                                   "name without .yaml")
    plant: PlantModel = Field(description="the FMU and its loops (required)")
    prior: PriorModel = section("model for the reward forecast")
    controller: ControllerModel = section("PID structure and gain map")
    strategies: StrategiesModel = section("reward forecast and action smoothing")
    reward: RewardModel = section("hierarchical reward (eq. 10-11)")
    agent: AgentModel = section("RL algorithm and training budget")
    training: TrainingModel = section("training episodes")
    evaluation: EvaluationModel = section("evaluation episode and metrics intervals")
    baseline: BaselineModel = section("budget of the fixed-PID baseline search")
    deploy: DeployModel = section("deployment limits")

    @model_validator(mode="before")
    @classmethod
    def _remember_training_steps(cls, data: Any, info: ValidationInfo) -> Any:
        """training.episode_steps as written (or its default), for checks of sections validated before it."""
        state = state_of(info)
        if state is not None:
            training = data.get("training") if isinstance(data, dict) else None
            steps = training.get("episode_steps", _MISSING_STEPS) if isinstance(training, dict) else _MISSING_STEPS
            if steps is _MISSING_STEPS:
                steps = TrainingModel.model_fields["episode_steps"].default
            state.raw_training_steps = steps if isinstance(steps, int) and not isinstance(steps, bool) and steps > 0 \
                else None
        return data


def default(model: type[BaseModel], key: str) -> Any:
    """The default of `model`'s field `key` (factories called)."""
    return model.model_fields[key].get_default(call_default_factory=True)
