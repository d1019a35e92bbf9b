"""The loop a step test suggests: which output to measure and which input drives it, and starting limits,
setpoint range, sample time, gain ranges and episode lengths for a scenario.

An engineer's choice, in this order: a pair is usable when the input moves the output with a nonzero
effect (not "none", not a zero-gain pulse) and the input is not on/off (`sweep_input`; an unstable response
is never on/off: every constant input runs it onto a stop, so its gain and growth rate come from the run
before the stop). Where one output is the rate of another, the identified mechanism decides: the rate is
the loop when the position integrates it and the rate has dynamics of its own (a free mechanism, torque ->
speed: the speed loop; a position loop goes around a tuned speed loop); otherwise the position, level or
temperature is (a mass on a spring, whose velocity returns to zero; a net flow that follows the input
within a step). Of the outputs left, the first in the FMU's order whose actuator is not disturbance-like is
measured (outputs in different units cannot be compared by size); its actuator is the usable input with
the most authority over its range.

The design (`_design`) reduces the identified model by Skogestad's half rule (an inverse response's
time 1/z and the neglected lags become effective delay θ) to K e^(-θ s)/((τ1 s + 1)(τ2 s + 1)), k e^(-θ s)/(s
(τ2 s + 1)) or k e^(-θ s)/s², and applies SIMC with the closed-loop time constant τc = max(θ, the time the
actuator's range allows, τ1/4): the largest bandwidth ω at which |G(jω)| times the actuator's headroom
still covers a typical setpoint step (a quarter of the setpoint range). The sample time is τc/5 (finer
where the lag τ2 or a delay need it), never below the FMU's own step size; below 1e-4 s only with its
reason. Unstable plants get a pole placement that stabilises (PI for one pole, PD with slow integral
action for a pole pair), lightly damped oscillators a PD that doubles their natural frequency.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

from prlpid_fmi.errors import PlantError
import numpy as np

from prlpid_fmi.probe.open_loop import ProbeResult, StepResponse, Sweep, snap_sample_time, sweep_input


@dataclass(frozen=True)
class LoopProposal:
    """A loop for a starter scenario, every number with the reason it was chosen (`why`, one line each)."""

    input: str
    output: str
    u_limits: tuple[float, float]
    setpoint_range: tuple[float, float]
    measurement_scale: float
    sample_time_s: float
    gains: dict                      # {Kp|Ti|Td: (low, high, scale)}
    why: dict                        # {key: one-line reason}
    others: tuple[str, ...]          # one comment line per input not chosen
    trim_input: float                # the input that holds the output at its start value
    sweep: Optional[Sweep] = None    # the input held at levels across u_limits: reach, on/off
    response: Optional[StepResponse] = None
    design: dict = None              # {Kp, Ti, Td}: the single design the ranges are centred on
    settling_s: float = 0.0          # the design's closed-loop settling time (a few closed-loop time constants), s
    hold_steps: int = 100            # samples per setpoint: the settling time at least
    episode_steps: int = 200         # samples per training episode: two holds at least


def _round(x: float, digits: int = 3) -> float:
    """x to `digits` significant digits (readable YAML)."""
    if x == 0 or not math.isfinite(x):
        return float(x)
    return float(f"{x:.{digits}g}")


def _initial_slope(r: StepResponse) -> float:
    """dy/dt of the trim run at t = 0 (second-order forward difference), output units per s."""
    y = r.trim
    if len(y) < 3:
        return 0.0
    return float((-3 * y[0] + 4 * y[1] - y[2]) / (2 * r.sample_time_s))


def usable(r: StepResponse) -> bool:
    """The input moves the output with an effect a PID can use: not "none", not a zero-gain pulse."""
    return r.kind != "none" and not r.zero_gain


FREE_POSITION = ("pure integrator", "integrator with lag", "double integrator")


def _rate_loop_wins(position: StepResponse, rate: StepResponse) -> bool:
    """A rate output is the loop rather than its position when the input acts through inertia: the position
    integrates (a free mechanism) and the rate has dynamics of its own (a lag or an integrator), not a flow
    that follows the input within a step."""
    return (position.mechanism in FREE_POSITION and usable(rate)
            and rate.mechanism in ("lag", "lag with delay", "pure integrator", "integrator with lag"))


def _authority(r: StepResponse, d) -> float:
    v = d.variable(r.input)
    span = (v.max - v.min) if v.min is not None and v.max is not None else 1.0
    return r.output_change_per_unit * span


def choose_input(result: ProbeResult, exclude: Sequence[str] = ()) -> tuple[StepResponse, str]:
    """The actuator: the usable input that moves the output most over its declared range (or per unit), never a
    disturbance-like input while another one moves the output. Returns (response, reason); PlantError (one
    line) when no input is usable, saying why for each."""
    from prlpid_fmi.fmu import describe_fmu

    d = describe_fmu(result.fmu)
    candidates = [r for r in result.responses if r.input not in exclude]
    moving = [r for r in candidates if usable(r)]
    if not moving:
        raise PlantError(f"{result.fmu}: no input moves {result.output} with a nonzero gain ("
                         + "; ".join(_unusable_reason(r) for r in result.responses) + ")")
    actuators = [r for r in moving if not r.disturbance_like] or moving
    best = max(actuators, key=lambda r: _authority(r, d))
    if best.disturbance_like:
        reason = (f"every input that moves {result.output} looks like a disturbance; {best.input} moves it most: "
                  "ADJUST if it is not the actuator")
    elif len(moving) > 1:
        reason = f"moves {result.output} most of the inputs that are not disturbances"
    else:
        reason = f"the only input that moves {result.output}"
    return best, reason


def _unusable_reason(r: StepResponse) -> str:
    if r.kind == "none":
        return f"{r.input}: does not move it"
    if r.zero_gain:
        return f"{r.input}: zero gain (a pulse that dies out: the output is a rate)"
    return f"{r.input}: {r.kind}"


def choose_loop(results: dict) -> tuple[ProbeResult, str]:
    """The output to measure of a multi-output probe ({output: ProbeResult}, `probe_outputs`): of a position and
    its rate, the one the mechanism calls for (`_passed_over`); then the first output in the FMU's order with a
    usable pair whose input is not disturbance-like, else the first with any usable pair. Returns (its ProbeResult, why). PlantError (one line) when no output has a usable input."""
    ordered = list(results.values())
    passed = _passed_over(results)
    candidates = [p for p in ordered if p.output not in passed]
    good = [p for p in candidates if any(usable(r) and not r.disturbance_like for r in p.responses)]
    some = [p for p in candidates if any(usable(r) for r in p.responses)]
    if not some:
        fmu = ordered[0].fmu if ordered else "the FMU"
        hints = _on_off_hints(ordered[0]) if ordered else []  # the first output: one sweep per input
        if hints:
            raise PlantError(f"{fmu}: {'; '.join(hints)}: a PID needs an input with a graded effect")
        raise PlantError(f"{fmu}: no input moves any output with a nonzero gain ("
                         + "; ".join(f"{p.output}: " + ", ".join(_unusable_reason(r) for r in p.responses)
                                     for p in ordered)[:600] + ")")
    chosen = (good or some)[0]
    skipped = [p for p in ordered if p is not chosen and (ordered.index(p) < ordered.index(chosen)
                                                          or p.output in passed)]
    kinds = "; ".join(f"{r.input}: {r.mechanism}" for r in chosen.responses if usable(r) and r.mechanism)
    why = (f"the first output an actuator moves with a nonzero gain ({kinds})" if kinds
           else "the first output an actuator moves with a nonzero gain")
    if skipped:
        why += " (not " + ", ".join(f"{p.output}: " + passed.get(p.output, _output_reason(p)) for p in skipped) + ")"
    return chosen, why


def _passed_over(results: dict) -> dict:
    """{output: why} for the outputs an engineer passes over where one output is the rate of another: the
    position of a free mechanism (its rate is the loop), or a rate whose position is the loop."""
    passed = {}
    for rate_out, p in results.items():
        for r in p.responses:
            if not r.rate_of or r.rate_of not in results or r.disturbance_like:
                continue
            position = results[r.rate_of].response(r.input)
            if _rate_loop_wins(position, r):
                article = "an" if position.mechanism[0] in "aeiou" else "a"
                passed[r.rate_of] = (f"{r.input} -> {r.rate_of} is {article} {position.mechanism}: a free mechanism, "
                                     f"its rate {rate_out} is the loop (a position loop goes around a tuned "
                                     f"{rate_out} loop)")
            elif r.rate_of not in passed:
                kind = r.mechanism or r.kind
                what = ("returns to zero (a mass on a spring)" if r.zero_gain else
                        f"is {'an' if kind[0] in 'aeiou' else 'a'} {kind}" + (" (it follows the input: a flow)" if r.kind == "static" else ""))
                passed[rate_out] = f"the rate of {r.rate_of}, which is the loop: {r.input} -> {rate_out} {what}"
    return passed


def _output_reason(p: ProbeResult) -> str:
    if any(r.zero_gain for r in p.responses):
        return "zero gain"
    if all(r.kind == "none" for r in p.responses):
        return "no input moves it"
    return "moved by disturbance-like inputs only"


def _on_off_hints(result: ProbeResult, most: int = 5) -> list[str]:
    """For inputs whose small step did not move the output (at most `most`, disturbances left out): held at
    levels across their limits, those that switch it between two values (one line each)."""
    from prlpid_fmi.fmu import describe_fmu

    d = describe_fmu(result.fmu)
    hints = []
    for r in [r for r in result.responses if r.kind == "none" and not r.disturbance_like][:most]:
        limits = _u_limits(r, d.variable(r.input), r.u0, result, {})
        if not (all(np.isfinite(limits)) and limits[1] > limits[0]):
            continue
        sweep = sweep_input(result, r, np.linspace(limits[0], limits[1], SWEEP_LEVELS))
        if sweep.on_off:
            lo, hi = sweep.on_off
            hints.append(f"{r.input} acts on/off on {result.output} (two values, {min(sweep.values):.4g} and "
                         f"{max(sweep.values):.4g}, switching between {lo:.4g} and {hi:.4g})")
    return hints


SWEEP_LEVELS = 7                 # levels across u_limits held until the output settles (reach, on/off)
HOLD_STEPS, EPISODE_STEPS = 100, 200   # the schema's defaults: a proposal never holds a setpoint shorter
MIN_SAMPLE_TIME_S = 1e-4         # a sample time below this needs a reason said in its comment
TYPICAL_STEP = 0.25              # a typical setpoint step: this part of the setpoint range


def propose_loop(result: ProbeResult, output_why: str = "") -> LoopProposal:
    """u_limits, setpoint range, sample time and gain ranges for the chosen input (each with its reason in `why`).
    An input that acts on/off is passed over for the next usable one; PlantError (one line) when none is left
    or when the chosen input cannot hold the output anywhere inside its limits."""
    from prlpid_fmi.fmu import describe_fmu

    d = describe_fmu(result.fmu)
    excluded, on_off = [], []
    while True:
        try:
            r, reason = choose_input(result, excluded)
        except PlantError:
            on_off = on_off or _on_off_hints(result)
            if on_off:
                raise PlantError(f"{result.fmu}: {'; '.join(on_off)}: a PID needs an input with a graded effect "
                                 f"on {result.output}") from None
            raise
        v = d.variable(r.input)
        u_trim = _trim_input(r)
        why = {"input": reason}
        if output_why:
            why["output"] = output_why
        u_limits = _u_limits(r, v, u_trim, result, why)
        sweep = None
        if all(np.isfinite(u_limits)) and u_limits[1] > u_limits[0] and r.kind != "unstable":
            # an unstable plant runs onto a stop at every constant input: a sweep would call it on/off
            sweep = sweep_input(result, r, np.linspace(u_limits[0], u_limits[1], SWEEP_LEVELS))
            if sweep.on_off:
                lo, hi = sweep.on_off
                on_off.append(f"{r.input} acts on/off on {result.output} (two values, "
                              f"{min(sweep.values):.4g} and {max(sweep.values):.4g}, switching between {lo:.4g} and {hi:.4g})")
                excluded.append(r.input)
                continue
        break
    if on_off:
        reason += f"; {'; '.join(on_off)}: not an actuator for a PID"
        why["input"] = reason
    out = d.variable(result.output)
    _require_holdable(r, sweep, result)
    sp = _setpoint_range(r, out, u_trim, u_limits, result, why, sweep)
    if "ADJUST" in why["u_limits"] and "ADJUST" not in why["setpoint_range"] and out.min is None and out.max is None:
        why["setpoint_range"] += "; ADJUST with u_limits, which the FMU does not declare"
    scale = _round(max((sp[1] - sp[0]) / 2, 1e-12))
    design = _design(r, u_trim, u_limits, sp, result, why, d.own_step_s)
    kc, ti, td, sign = design.kp, design.ti, design.td, design.sign
    if sign > 0:
        kp = (_round(kc / 10), _round(kc * 10), "log")
    else:
        kp = (_round(-kc * 10), _round(-kc / 10), "linear")
        why["gains"] += "; the output falls as the input rises (reverse acting): a negative Kp range"
    gains = {"Kp": kp, "Ti": (_round(ti / 10), _round(ti * 10), "log"), "Td": (0.0, _round(design.td_max), "linear")}
    hold = max(HOLD_STEPS, math.ceil(design.settling_s / design.sample_time_s))
    episode = max(EPISODE_STEPS, 2 * hold)
    why["hold"] = (f"the design settles in about {design.settling_s:.3g} s = {math.ceil(design.settling_s / design.sample_time_s)} "
                   f"samples" + (f" (at least {HOLD_STEPS})" if hold == HOLD_STEPS else ""))
    others = tuple(
        f"{o.input}: {'looks like a disturbance; ' if o.disturbance_like else ''}"
        + (f"moves {result.output} by {o.output_change_per_unit:.4g} per unit ({o.kind})" if usable(o)
           else _unusable_reason(o).split(': ', 1)[1])
        for o in result.responses if o.input != r.input)
    return LoopProposal(r.input, result.output, (float(u_limits[0]), float(u_limits[1])), sp, scale,
                        design.sample_time_s, gains, why, others, u_trim, sweep, r,
                        {"Kp": sign * kc, "Ti": ti, "Td": td}, design.settling_s, hold, episode)


def _require_holdable(r: StepResponse, sweep: Optional[Sweep], result: ProbeResult) -> None:
    """PlantError when an integrating output moves the same way at both input limits: no input inside the
    limits holds it (the trim input is outside)."""
    if r.kind != "integrating" or sweep is None:
        return
    lo, hi = sweep.slopes[0], sweep.slopes[-1]
    if lo * hi > 0:
        raise PlantError(f"{result.fmu}: {result.output} {'rises' if lo > 0 else 'falls'} at both limits of "
                         f"{r.input} ({sweep.levels[0]:.4g}: {lo:.4g}/s, {sweep.levels[-1]:.4g}: {hi:.4g}/s): no input "
                         "inside the limits holds it at a setpoint")


def settled_free_response(r: StepResponse) -> Optional[float]:
    """Where an integrating output's trim run (the input held at its start value) comes to rest, when it moved
    and its last third is flat (within 1 % of its travel: a drifting integrator moves a third of it there): the FMU
    starts off equilibrium (a wheel released onto its tyre), so the start value is a transient, not the operating
    point. None otherwise."""
    y = np.asarray(r.trim, dtype=float)
    if r.kind != "integrating" or len(y) < 12 or not np.all(np.isfinite(y)):
        return None
    travel = float(np.ptp(y))
    tail = y[-len(y) // 3:]
    if travel <= 0 or float(np.ptp(tail)) > 0.01 * travel:
        return None
    return float(tail[-1])


def _trim_input(r: StepResponse) -> float:
    """The input that holds the output at its start value, from the trim run's drift and the fitted model (an
    integrating output whose free response settles: the start value holds it where it settles)."""
    if settled_free_response(r) is not None:
        return _round(r.u0, 4)
    s0 = _initial_slope(r)
    if r.kind == "stable":
        u_trim = r.u0 - s0 * r.time_constant_s / r.gain
    elif r.kind == "unstable":
        b = -r.gain * r.growth_rate_per_s          # high-frequency gain of b/(s - λ)
        u_trim = r.u0 - s0 / b
    elif r.kind == "static":
        u_trim = r.u0                              # y0 was read at u0, and nothing drifts
    else:
        u_trim = r.u0 - s0 / r.rate
    return _round(u_trim, 4)


def _u_limits(r: StepResponse, v, u_trim: float, result: ProbeResult, why: dict) -> tuple[float, float]:
    """u_limits: the input's declared min and max, else symmetric around its start value (the FMU author's
    operating point), wide enough to reach twice past the trim input (why["u_limits"])."""
    if v.min is not None and v.max is not None:
        why["u_limits"] = f"{r.input}'s declared min and max"
        return (v.min, v.max)
    nominal = abs(v.nominal) if v.nominal is not None else 0.0
    reach = max(2 * abs(u_trim - r.u0), nominal, abs(r.u0), 10 * abs(r.du))
    lo, hi = r.u0 - reach, r.u0 + reach
    if v.min is not None:
        lo = max(lo, v.min)
    if v.max is not None:
        hi = min(hi, v.max)
    rest = settled_free_response(r)
    held = (f"holds {result.output} where its free response settles, {rest:.4g}" if rest is not None else
            f"holds {result.output} = {result.y0:.4g}")
    why["u_limits"] = (f"ADJUST to the actuator: ±{_round(reach)} around the start value {r.u0:g} (the trim input "
                       f"{u_trim:g} {held}, probe)")
    return (_round(lo), _round(hi))


def _setpoint_range(r: StepResponse, out, u_trim: float, u_limits, result: ProbeResult, why: dict,
                    sweep: Optional[Sweep] = None) -> tuple:
    """The setpoint range the actuator can hold at steady state, inside the output's declared range: the inner
    80 % of what the input held at its limits reached (the sweep), else of the probe's linear model."""
    y0 = result.y0
    if r.kind in ("stable", "static") and sweep is not None and all(sweep.settled):
        held = sweep.reach
        width = held[1] - held[0]
        sp = [held[0] + 0.1 * width, held[1] - 0.1 * width]
        why["setpoint_range"] = (f"80 % of what {r.input} held across u_limits reached at steady state "
                                 f"({held[0]:.4g} to {held[1]:.4g}, {len(sweep.levels)} levels, probe)")
    elif r.kind in ("stable", "unstable", "static"):
        held = sorted(y0 + r.gain * (u - u_trim) for u in u_limits)
        shrink = 0.25 if r.kind == "unstable" else 0.1
        width = held[1] - held[0]
        sp = [held[0] + shrink * width, held[1] - shrink * width]
        why["setpoint_range"] = (f"{100 * (1 - 2 * shrink):.0f} % of what u_limits hold in steady state by the "
                                 f"linear model ({held[0]:.4g} to {held[1]:.4g}: gain {r.gain:.4g} from the probe)"
                                 + ("; ADJUST: an unstable plant's reach is not measured open loop" if r.kind == "unstable"
                                    and out.min is None and out.max is None else ""))
        if sweep is not None and r.kind != "unstable":  # a slow side did not settle: still inside what it reached
            lo_seen, hi_seen = sweep.reach
            sp = [max(sp[0], lo_seen), min(sp[1], hi_seen)] if sp[0] < hi_seen and sp[1] > lo_seen else sp
    else:
        rest = settled_free_response(r)
        base = y0 if rest is None else rest
        span = abs(out.nominal) if out.nominal else max(abs(base), 1.0)
        sp = [base, base + span] if rest is None else [base - span / 2, base + span / 2]
        spanned = "nominal value" if out.nominal else "start value" if rest is None else "its magnitude"
        around = (f", around {rest:.4g} where its free response settles: the FMU starts off equilibrium at {y0:.4g}"
                  if rest is not None else "")
        why["setpoint_range"] = (f"an integrating plant holds any {result.output} while the trim input {u_trim:g} is "
                                 f"inside u_limits; ADJUST (span: {spanned}{around})")
    if out.min is not None:
        sp[0] = max(sp[0], out.min)
    if out.max is not None:
        sp[1] = min(sp[1], out.max)
    return (_round(sp[0]), _round(sp[1]))


def _oscillation_dominates(r: StepResponse) -> bool:
    """The slowest mode is the lightly damped pair itself (a mass on a spring), not a lag beside it."""
    if not r.period_s or r.kind != "stable":
        return False
    wn = 2 * math.pi / r.period_s / math.sqrt(max(1 - r.damping_ratio ** 2, 1e-12))
    return abs(r.time_constant_s * r.damping_ratio * wn - 1) < 0.05


@dataclass(frozen=True)
class Design:
    """One PID for the identified model (ideal form u = Kp (e + ∫e/Ti + Td de/dt)), its sample time and how
    long its closed loop takes to settle; sign: the sign of Kp (the plant's direction)."""

    kp: float
    ti: float
    td: float
    td_max: float
    sign: float
    sample_time_s: float
    settling_s: float


def _half_rule(model, dead: float) -> tuple[float, list, float]:
    """Skogestad's half rule on an identified model: (low-frequency gain, [τ1, τ2] (the kept lags, s), θ (s)).
    An RHP zero's time 1/z and the lags beyond the kept ones count as delay (the largest neglected lag by
    half, its other half to the last kept lag); a LHP zero cancels the nearest slower lag by its time."""
    keep = 2 - model.integrators
    lags = sorted((1 / abs(p) for p in model.poles if p.real < 0), reverse=True)
    theta = dead
    for z in model.zeros:
        if z.real > 0:
            theta += 1 / abs(z)
        elif z.real < 0:
            tz = 1 / abs(z)
            slower = [i for i, T in enumerate(lags) if T > tz]
            if slower:
                lags[slower[-1]] -= tz
    lags = sorted((T for T in lags if T > 0), reverse=True)
    kept, rest = lags[:max(keep, 0)], lags[max(keep, 0):]
    if rest:
        if kept:
            kept[-1] += rest[0] / 2
            theta += rest[0] / 2 + sum(rest[1:])
        else:
            theta += sum(rest)
    return model.low_frequency_gain, kept, theta


def _actuator_time(model, headroom: float, step: float) -> float:
    """1/ω for the largest ω at which |G(jω)| x headroom still covers `step`: how fast a loop can be while a
    typical setpoint step keeps the controller's proportional move inside the actuator's range, s."""
    w = np.logspace(-8, 8, 1601)
    ok = model.magnitude(w) * headroom >= step
    if not ok.any():
        return math.inf
    return float(1 / w[np.nonzero(ok)[0][-1]])


def _snap_floor(ts: float, floor: Optional[float], why: dict, needs: str) -> float:
    """ts on the 1-2-5 series, never below the FMU's own step; below MIN_SAMPLE_TIME_S only with a reason."""
    ts = snap_sample_time(ts)
    if floor and ts < floor:
        why["sample_time"] += f"; raised to the FMU's own step size {floor:g} s"
        return float(floor)
    if ts < MIN_SAMPLE_TIME_S:
        why["sample_time"] += f"; below {MIN_SAMPLE_TIME_S:g} s because {needs}"
    return ts


REPROBE_FACTOR = 10             # τc this many times below the probe's step: the model is extrapolated, probe finer
REPROBE_DECADES = 3             # the finer probe starts at most this many decades below the probe's step


def _finer_probe(r: StepResponse, result: ProbeResult, tau_c: float, fmu_step_s: Optional[float]) -> StepResponse:
    """The step response of r's input re-measured from a grid near τc (s), not finer than the FMU's own step nor
    REPROBE_DECADES below r's grid; the probe's usual grid search (`probe_input`) goes on from there."""
    from prlpid_fmi.probe.open_loop import probe_input

    dt = snap_sample_time(max(tau_c / 2, r.sample_time_s / 10 ** REPROBE_DECADES, fmu_step_s or 0.0))
    return probe_input(result.fmu, r.input, result.output, result.inputs, result.u0, result.parameters, dt, result.y0)


def _design(r: StepResponse, u_trim: float, u_limits, sp, result: ProbeResult, why: dict,
            fmu_step_s: Optional[float] = None, refine: bool = True) -> Design:
    """The design each identified mechanism calls for (module docstring), every number's reason in `why`.
    refine: an integrator whose τc falls far below the probe's step (no lag or delay resolved there) is
    re-probed on a finer grid (`_finer_probe`) and designed from that; without a lag there, τc is bounded by
    twice the finest step that showed none."""
    headroom = max(u_limits[1] - u_trim, u_trim - u_limits[0], 1e-300)
    step = max(TYPICAL_STEP * (sp[1] - sp[0]), 1e-300)
    model = r.model
    if r.kind == "stable" and _oscillation_dominates(r):
        P, zeta, K, L = r.period_s, r.damping_ratio, r.gain, r.dead_time_s
        wn = 2 * math.pi / P / math.sqrt(1 - zeta ** 2)
        why["sample_time"] = (f"oscillation period {P:.4g} s / 40 (probe: damping ratio {zeta:.3g}; its decay "
                              f"envelope is {r.time_constant_s:.4g} s)")
        ts = _snap_floor(min(P / 40, L / 2) if L > 0 else P / 40, fmu_step_s, why, "the oscillation needs it")
        wc = 2 * wn      # PD stiffens to twice the natural frequency with damping 0.7, slow integral action on top
        kc = (wc ** 2 / wn ** 2 - 1) / abs(K)
        td = max((2 * 0.7 * wc - 2 * zeta * wn) / (wn ** 2 * abs(K) * kc), 0.0)
        ti = 4 / (0.7 * wc)
        why["gains"] = (f"a lightly damped oscillator (gain {K:.4g}, period {P:.4g} s, damping {zeta:.3g}): PD that "
                        f"doubles its natural frequency at damping 0.7 (Kp {kc:.3g}, Td {td:.3g} s, Ti {ti:.3g} s)")
        return Design(kc, ti, td, max(3 * td, 2 * ts, L), math.copysign(1.0, K), ts, 4 * ti)
    if r.kind == "static":
        K = r.gain
        ts = snap_sample_time(r.sample_time_s)
        why["sample_time"] = (f"the probe's step: {result.output} follows {r.input} within one step, so there is no "
                              "time scale to choose it from; ADJUST to the controller's period")
        if r.dead_time_s > 0:  # a gain behind a delay (the sample adds one step to it): AMIGO's PI for τ = 0
            kc, ti = 0.15 / abs(K), 0.35 * (r.dead_time_s + ts)
        else:  # with the step's one-sample delay: closed-loop poles 0.78 and -0.38
            kc, ti = 0.3 / abs(K), ts
        why["gains"] = (f"a static gain {K:.4g}{f' behind a {r.dead_time_s:.3g} s delay' if r.dead_time_s else ''}: "
                        f"integral action does the work (Kp {kc:.3g}, Ti {ti:.3g} s)")
        # integral action alone: the closed loop's time constant is about Ti / (K Kp)
        return Design(kc, ti, 0.0, ts, math.copysign(1.0, K), ts, 5 * ti / (abs(K) * kc) + r.dead_time_s)
    if r.kind == "unstable":
        return _unstable_design(r, headroom, step, why, fmu_step_s)
    if model is None:  # an integrator the probe could not model: its rate alone
        from prlpid_fmi.probe.open_loop import Model
        model = Model((r.rate,), (1.0, 0.0), r.dead_time_s)
    K, lags, theta = _half_rule(model, r.dead_time_s)
    m = model.integrators
    t_act = _actuator_time(model, headroom, step)
    floor = lags[0] / 4 if m == 0 and lags else 0.0
    tau_c = max(theta, t_act if math.isfinite(t_act) else 0.0, floor)
    if tau_c <= 0:
        tau_c = 10 * (fmu_step_s or MIN_SAMPLE_TIME_S)
    resolved = ""
    if refine and m >= 1 and not lags and theta == 0 and tau_c * REPROBE_FACTOR < r.sample_time_s:
        fine = _finer_probe(r, result, tau_c, fmu_step_s)
        seen = (f"re-probed on a {fine.sample_time_s:g} s grid because τc = {tau_c:.3g} s lies below the probe's "
                f"{r.sample_time_s:g} s step")
        if fine.kind == "integrating" and fine.mechanism != r.mechanism:
            design = _design(fine, u_trim, u_limits, sp, result, why, fmu_step_s, refine=False)
            why["sample_time"] = f"{seen}: {fine.mechanism}; " + why["sample_time"]
            why["gains"] += f" (from the {fine.sample_time_s:g} s re-probe)"
            return design
        if 2 * fine.sample_time_s > tau_c:
            tau_c = 2 * fine.sample_time_s
            resolved = (f"; {seen}, which showed no lag or delay: τc bounded at twice that grid, "
                        f"{tau_c:.3g} s, as faster dynamics are not known")
    tau2 = lags[-1] if (m == 0 and len(lags) == 2) or (m == 1 and lags) else 0.0
    limits = [(tau_c / 5, "τc/5")] + (
        [(tau2 / 4, f"a quarter of the lag τ2 = {tau2:.3g} s the derivative acts on")] if tau2 > 0 else [])
    limit, reason = min(limits)
    actuator = (f"{t_act:.3g} s for the bandwidth the actuator's range allows" if math.isfinite(t_act) else
                "no bound from the actuator: by the probe's local gain its headroom moves less than a typical step")
    why["sample_time"] = (f"{limit:.3g} s, {reason}: τc = {tau_c:.3g} s = max(effective delay θ = {theta:.3g} s, "
                          f"{actuator}" + (f", τ1/4 = {floor:.3g} s" if floor else "") + ") (probe)" + resolved)
    ts = _snap_floor(limit, fmu_step_s, why, f"the loop's closed-loop time constant is {tau_c:.3g} s")
    tc = tau_c + theta
    if m == 0:
        tau1 = lags[0] if lags else ts
        kc, tau_i = tau1 / (abs(K) * tc), min(tau1, 4 * tc)
        form = f"K = {K:.4g}, τ1 = {tau1:.4g} s" + (f", τ2 = {tau2:.4g} s" if tau2 else "")
    elif m == 1:
        kc, tau_i = 1 / (abs(K) * tc), 4 * tc
        form = f"k = {K:.4g} per s" + (f", τ2 = {tau2:.4g} s" if tau2 else "")
    else:
        kc, tau_i, tau2 = 1 / (4 * abs(K) * tc ** 2), 4 * tc, 4 * tc
        form = f"k = {K:.4g} per s²"
    # series PID (SIMC) -> the ideal form the controller uses
    kp, ti, td = kc * (1 + tau2 / tau_i), tau_i + tau2, tau_i * tau2 / (tau_i + tau2)
    why["gains"] = (f"SIMC on the {r.mechanism} ({form}, θ = {theta:.3g} s by the half rule, τc = {tau_c:.3g} s): "
                    f"Kp {kp:.3g}, Ti {ti:.3g} s, Td {td:.3g} s")
    # the loop's fast mode settles in a few τc + θ; where the integral action does not cancel the slowest lag
    # (τI < τ1, or an integrating plant), its slow mode of about Ti takes longer
    settle = max(5 * tc, 2 * ti) if m == 0 else max(8 * tc, 4 * ti)
    return Design(kp, ti, td, max(3 * td, 2 * ts, r.dead_time_s), math.copysign(1.0, K), ts, settle)


def _unstable_design(r: StepResponse, headroom: float, step: float, why: dict, fmu_step_s) -> Design:
    """An unstable pole λ: PI that places both closed-loop poles (b/(s - λ): Kp b = 3 λ, Ti = 2/λ), or for a pole
    pair (b/((s - λ)(s + μ)), relative degree 2) PD that places them at ωn = 2 λ, damping 0.7, with slow
    integral action (Ti = 10/ωn). Kp's sign is the sign of the high-frequency gain b: the way the output first
    moves (the formal steady-state gain of a pole pair has the other sign)."""
    lam = r.growth_rate_per_s
    model = r.model
    poles = sorted(model.poles, key=lambda p: -p.real) if model is not None else []
    pair = model is not None and len(model.den) - len(model.num) >= 2 and len(poles) >= 2
    if pair:
        mu = -float(poles[1].real)
        b = model.high_frequency_gain
        wn, zeta = 2 * lam, 0.7
        kc = (wn ** 2 + lam * mu) / abs(b)
        td = max((2 * zeta * wn - mu + lam) / (abs(b) * kc), 0.0)
        ti = 10 / wn
        why["sample_time"] = f"1/(20 λ): the response grows as e^(λt), λ = {lam:.4g} 1/s (probe)"
        ts = _snap_floor(1 / (20 * lam), fmu_step_s, why, f"the plant grows as e^({lam:.3g} t)")
        why["gains"] = (f"unstable pole pair (λ = {lam:.4g} 1/s, other pole {-mu:.4g} 1/s, high-frequency gain "
                        f"b = {b:.4g}): PD placing the poles at {wn:.3g} rad/s, damping 0.7 (Kp {math.copysign(kc, b):.3g}, "
                        f"Td {td:.3g} s), integral Ti {ti:.3g} s")
        settle = 8 / wn
    else:
        b = model.high_frequency_gain if model is not None else -r.gain * lam   # high-frequency gain of b/(s - λ)
        kc, ti, td = 3.0 * lam / abs(b), 2.0 / lam, 0.0
        why["sample_time"] = f"1/(10 λ): the response grows as e^(λt), λ = {lam:.4g} 1/s (probe)"
        ts = _snap_floor(1 / (10 * lam), fmu_step_s, why, f"the plant grows as e^({lam:.3g} t)")
        why["gains"] = (f"unstable: Kp must exceed λ/b = {lam / abs(b):.3g} to stabilise (b = {b:.4g} per s, "
                        f"λ = {lam:.4g} 1/s)")
        settle = 8 / lam
    if model is not None and _actuator_time(model, headroom, step) > 1 / (2 * lam):
        why["gains"] += (f"; ADJUST: the actuator's range moves a {step:.3g} setpoint step only below "
                         f"{1 / _actuator_time(model, headroom, step):.3g} rad/s, slower than the 2 λ a stabilising loop needs")
    return Design(kc, ti, td, max(3 * td, 0.2 / lam, 2 * ts), math.copysign(1.0, b), ts, max(settle, 4 * ti))
