"""The loop a step test suggests: which output to measure and which input drives it, and starting limits,
setpoint range, sample time and gain ranges for a scenario.

An engineer's choice, in this order: a pair is usable when the input moves the output with a nonzero
effect (not "none", not a zero-gain pulse, not an output that is the rate of another output, e.g. a velocity
beside its position), and the input is not on/off (`sweep_input`). Of the outputs with a usable pair, the
first in the FMU's order whose actuator is not disturbance-like is measured (outputs in different units
cannot be compared by size); its actuator is the usable input with the most authority over its range.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

from prlpid_fmi.errors import PlantError
import numpy as np

from prlpid_fmi.probe.step_test import ProbeResult, StepResponse, Sweep, snap_sample_time, sweep_input


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
    """The input moves the output with an effect a PID can use: not "none", not a zero-gain pulse, and the
    output is not the rate of another output (a velocity beside its position)."""
    return r.kind != "none" and not r.zero_gain and not r.rate_of


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
    if r.rate_of:
        return f"{r.input}: the output is the rate of {r.rate_of}"
    return f"{r.input}: {r.kind}"


def choose_loop(results: dict) -> tuple[ProbeResult, str]:
    """The output to measure of a multi-output probe ({output: ProbeResult}, `probe_outputs`): the first output in
    the FMU's order with a usable pair whose input is not disturbance-like, else the first with any usable
    pair. Returns (its ProbeResult, why). PlantError (one line) when no output has a usable input."""
    ordered = list(results.values())
    good = [p for p in ordered if any(usable(r) and not r.disturbance_like for r in p.responses)]
    some = [p for p in ordered if any(usable(r) for r in p.responses)]
    if not some:
        fmu = ordered[0].fmu if ordered else "the FMU"
        hints = _on_off_hints(ordered[0]) if ordered else []  # the first output: one sweep per input
        if hints:
            raise PlantError(f"{fmu}: {'; '.join(hints)}: a PID needs an input with a graded effect")
        raise PlantError(f"{fmu}: no input moves any output with a nonzero gain ("
                         + "; ".join(f"{p.output}: " + ", ".join(_unusable_reason(r) for r in p.responses)
                                     for p in ordered)[:600] + ")")
    chosen = (good or some)[0]
    skipped = [p for p in ordered[:ordered.index(chosen)]]
    why = "the first output an actuator moves with a nonzero gain"
    if skipped:
        why += " (not " + ", ".join(f"{p.output}: " + _output_reason(p) for p in skipped) + ")"
    return chosen, why


def _output_reason(p: ProbeResult) -> str:
    rates = {r.rate_of for r in p.responses if r.rate_of}
    if rates:
        return f"the rate of {', '.join(sorted(rates))}"
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
        if all(np.isfinite(u_limits)) and u_limits[1] > u_limits[0]:
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
    scale = _round(max((sp[1] - sp[0]) / 2, 1e-12))
    ts, kc, ti, td_max, sign = _sample_time_and_gains(r, u_trim, u_limits, sp, result, why)
    if sign > 0:
        kp = (_round(kc / 10), _round(kc * 10), "log")
    else:
        kp = (_round(-kc * 10), _round(-kc / 10), "linear")
        why["gains"] += "; the output falls as the input rises (reverse acting): a negative Kp range"
    gains = {"Kp": kp, "Ti": (_round(ti / 10), _round(ti * 10), "log"), "Td": (0.0, _round(td_max), "linear")}
    others = tuple(
        f"{o.input}: {'looks like a disturbance; ' if o.disturbance_like else ''}"
        + (f"moves {result.output} by {o.output_change_per_unit:.4g} per unit ({o.kind})" if usable(o)
           else _unusable_reason(o).split(': ', 1)[1])
        for o in result.responses if o.input != r.input)
    return LoopProposal(r.input, result.output, (float(u_limits[0]), float(u_limits[1])), sp, scale, ts, gains, why,
                        others, u_trim, sweep, r)


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


def _trim_input(r: StepResponse) -> float:
    """The input that holds the output at its start value, from the trim run's drift and the fitted model."""
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
    why["u_limits"] = (f"ADJUST to the actuator: ±{_round(reach)} around the start value {r.u0:g} (the trim input "
                       f"{u_trim:g} holds {result.output} = {result.y0:.4g}, probe)")
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
                                 f"linear model ({held[0]:.4g} to {held[1]:.4g}: gain {r.gain:.4g} from the probe)")
        if sweep is not None and r.kind != "unstable":  # a slow side did not settle: still inside what it reached
            lo_seen, hi_seen = sweep.reach
            sp = [max(sp[0], lo_seen), min(sp[1], hi_seen)] if sp[0] < hi_seen and sp[1] > lo_seen else sp
    else:
        span = abs(out.nominal) if out.nominal else max(abs(y0), 1.0)
        sp = [y0, y0 + span]
        why["setpoint_range"] = (f"an integrating plant holds any {result.output} while the trim input {u_trim:g} is "
                                 f"inside u_limits; ADJUST (span: {'nominal value' if out.nominal else 'start value'})")
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


def _sample_time_and_gains(r: StepResponse, u_trim: float, u_limits, sp, result: ProbeResult, why: dict) -> tuple:
    """(sample time [s], Kp, Ti [s], Td upper bound [s], sign of Kp) from the identified model of each kind."""
    sign = 1.0
    if r.kind == "stable" and _oscillation_dominates(r):
        P, zeta, K, L = r.period_s, r.damping_ratio, r.gain, r.dead_time_s
        wn = 2 * math.pi / P / math.sqrt(1 - zeta ** 2)
        ts = snap_sample_time(min(P / 40, L / 2) if L > 0 else P / 40)
        why["sample_time"] = (f"oscillation period {P:.4g} s / 40 (probe: damping ratio {zeta:.3g}; its decay "
                              f"envelope is {r.time_constant_s:.4g} s)")
        # PD stiffens to twice the natural frequency with damping 0.7, slow integral action on top
        wc = 2 * wn
        kc = (wc ** 2 / wn ** 2 - 1) / abs(K)
        td = max((2 * 0.7 * wc - 2 * zeta * wn) / (wn ** 2 * abs(K) * kc), 0.0)
        ti = 4 / (0.7 * wc)
        td_max = max(3 * td, 2 * ts, L)
        sign = math.copysign(1.0, K)
        why["gains"] = (f"a lightly damped oscillator (gain {K:.4g}, period {P:.4g} s, damping {zeta:.3g}): PD that "
                        f"doubles its natural frequency at damping 0.7 (Kp {kc:.3g}, Td {td:.3g} s, Ti {ti:.3g} s)")
    elif r.kind == "stable":
        T, K, L = r.time_constant_s, r.gain, r.dead_time_s
        fast = [T / 20] + ([L / 2] if L > 0 else []) + ([r.period_s / 20] if r.period_s else [])
        ts = snap_sample_time(min(fast))
        why["sample_time"] = (f"time constant {T:.4g} s / 20 (probe)"
                              + (f"; dead time {L:.3g} s" if L else "")
                              + (f"; oscillation period {r.period_s:.4g} s / 20" if r.period_s else ""))
        tau_c = max(L, T / 4, 2 * ts)                       # SIMC closed-loop time constant
        kc, ti = T / (abs(K) * (tau_c + L)), min(T, 4 * (tau_c + L))
        td_max = max(L, 2 * ts)
        sign = math.copysign(1.0, K)
        why["gains"] = f"around SIMC for gain {K:.4g}, T = {T:.4g} s, dead time {L:.3g} s (Kp {kc:.3g}, Ti {ti:.3g} s)"
    elif r.kind == "static":
        K = r.gain
        ts = snap_sample_time(r.sample_time_s)
        why["sample_time"] = (f"the probe's step: {result.output} follows {r.input} within one step, so there is no "
                              "time scale to choose it from; ADJUST to the controller's period")
        if r.dead_time_s > 0:  # a gain behind a delay: low-gain integral action, slower the longer the delay
            kc, ti, td_max = 0.15 / abs(K), 2 * (r.dead_time_s + ts), ts
        else:  # with the step's one-sample delay: closed-loop poles 0.78 and -0.38
            kc, ti, td_max = 0.3 / abs(K), ts, ts
        sign = math.copysign(1.0, K)
        why["gains"] = (f"a static gain {K:.4g}{f' behind a {r.dead_time_s:.3g} s delay' if r.dead_time_s else ''}: "
                        f"integral action does the work (Kp {kc:.3g}, Ti {ti:.3g} s)")
    elif r.kind == "unstable":
        lam = r.growth_rate_per_s
        b = -r.gain * lam
        ts = snap_sample_time(1 / (10 * lam))
        why["sample_time"] = f"1/(10 λ): the response grows as e^(λt), λ = {lam:.4g} 1/s (probe)"
        kc, ti, td_max = 3.0 * lam / abs(b), 2.0 / lam, 0.2 / lam
        sign = math.copysign(1.0, b)
        why["gains"] = (f"unstable: Kp must exceed λ/b = {lam / abs(b):.3g} to stabilise (b = {b:.4g} per s, "
                        f"λ = {lam:.4g} 1/s)")
    else:
        authority = abs(r.rate) * max(u_limits[1] - u_trim, u_trim - u_limits[0], 1e-12)
        traverse = (sp[1] - sp[0]) / authority
        ts = snap_sample_time(traverse / 20)
        why["sample_time"] = (f"1/20 of the {traverse:.3g} s the actuator needs to move {result.output} across the "
                              f"setpoint range (rate {r.rate:.4g} per s per input unit, probe)")
        tau_c = 10 * ts
        kc, ti, td_max = 1 / (abs(r.rate) * tau_c), 4 * tau_c, tau_c
        sign = math.copysign(1.0, r.rate)
        why["gains"] = f"around SIMC for an integrator with rate {r.rate:.4g} (Kp {kc:.3g}, Ti {ti:.3g} s)"
    return ts, kc, ti, td_max, sign
