"""The loop a step test suggests: which input drives the output, and starting gain ranges for a scenario."""
from __future__ import annotations

import math
from dataclasses import dataclass

from prlpid_fmi.errors import PlantError
from prlpid_fmi.probe.step_test import ProbeResult, StepResponse, snap_sample_time


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


def choose_input(result: ProbeResult) -> tuple[StepResponse, str]:
    """The actuator: the input that moves the output most over its declared range (or per unit), never a
    disturbance-like input while another one moves the output. Returns (response, reason)."""
    from prlpid_fmi.fmu import describe_fmu

    d = describe_fmu(result.fmu)

    def authority(r: StepResponse) -> float:
        v = d.variable(r.input)
        span = (v.max - v.min) if v.min is not None and v.max is not None else 1.0
        return r.output_change_per_unit * span

    moving = [r for r in result.responses if r.kind != "none"]
    if not moving:
        raise PlantError(f"{result.fmu}: no input moves {result.output} (probed: "
                         f"{', '.join(r.input for r in result.responses)})")
    actuators = [r for r in moving if not r.disturbance_like] or moving
    best = max(actuators, key=authority)
    if best.disturbance_like:
        reason = (f"every input that moves {result.output} looks like a disturbance; {best.input} moves it most: "
                  "ADJUST if it is not the actuator")
    elif len(moving) > 1:
        reason = f"moves {result.output} most of the inputs that are not disturbances"
    else:
        reason = f"the only input that moves {result.output}"
    return best, reason


def propose_loop(result: ProbeResult) -> LoopProposal:
    """u_limits, setpoint range, sample time and gain ranges for the chosen input (each with its reason in `why`)."""
    from prlpid_fmi.fmu import describe_fmu

    d = describe_fmu(result.fmu)
    r, reason = choose_input(result)
    v, out = d.variable(r.input), d.variable(result.output)
    why = {"input": reason}
    u_trim = _trim_input(r)
    u_limits = _u_limits(r, v, u_trim, result, why)
    sp = _setpoint_range(r, out, u_trim, u_limits, result, why)
    scale = _round(max((sp[1] - sp[0]) / 2, 1e-12))
    ts, kc, ti, td_max, sign = _sample_time_and_gains(r, u_trim, u_limits, sp, result, why)
    if sign > 0:
        kp = (_round(kc / 10), _round(kc * 10), "log")
    else:
        kp = (_round(-kc * 10), _round(-kc / 10), "linear")
        why["gains"] += "; negative gain: a negative linear Kp range"
    gains = {"Kp": kp, "Ti": (_round(ti / 10), _round(ti * 10), "log"), "Td": (0.0, _round(td_max), "linear")}
    others = tuple(
        f"{o.input}: {'looks like a disturbance; ' if o.disturbance_like else ''}"
        + (f"moves {result.output} by {o.output_change_per_unit:.4g} per unit ({o.kind})" if o.kind != "none"
           else f"does not move {result.output}")
        for o in result.responses if o.input != r.input)
    return LoopProposal(r.input, result.output, (float(u_limits[0]), float(u_limits[1])), sp, scale, ts, gains, why,
                        others, u_trim)


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
    """u_limits: the input's declared min and max, else a reach around the trim input (why["u_limits"])."""
    if v.min is not None and v.max is not None:
        why["u_limits"] = f"{r.input}'s declared min and max"
        return (v.min, v.max)
    nominal = abs(v.nominal) if v.nominal is not None else 0.0
    reach = max(2 * abs(u_trim - r.u0), nominal, abs(r.u0), 10 * abs(r.du))
    lo, hi = u_trim - reach, u_trim + reach
    if v.min is not None:
        lo = max(lo, v.min)
    if v.max is not None:
        hi = min(hi, v.max)
    why["u_limits"] = (f"ADJUST to the actuator: ±{_round(reach)} around the trim input {u_trim:g} that holds "
                       f"{result.output} = {result.y0:.4g} (probe)")
    return (_round(lo), _round(hi))


def _setpoint_range(r: StepResponse, out, u_trim: float, u_limits, result: ProbeResult, why: dict) -> tuple:
    """The setpoint range the actuator can hold at steady state, inside the output's declared range."""
    y0 = result.y0
    if r.kind in ("stable", "unstable", "static"):
        held = sorted(y0 + r.gain * (u - u_trim) for u in u_limits)
        shrink = 0.25 if r.kind == "unstable" else 0.1
        width = held[1] - held[0]
        sp = [held[0] + shrink * width, held[1] - shrink * width]
        why["setpoint_range"] = (f"{100 * (1 - 2 * shrink):.0f} % of what u_limits hold in steady state "
                                 f"({held[0]:.4g} to {held[1]:.4g}: gain {r.gain:.4g} from the probe)")
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


def _sample_time_and_gains(r: StepResponse, u_trim: float, u_limits, sp, result: ProbeResult, why: dict) -> tuple:
    """(sample time [s], Kp, Ti [s], Td upper bound [s], sign of Kp) from the identified model of each kind."""
    sign = 1.0
    if r.kind == "stable":
        T, K, L = r.time_constant_s, r.gain, r.dead_time_s
        ts = snap_sample_time(min(T / 20, L / 2) if L > 0 else T / 20)
        why["sample_time"] = f"time constant {T:.4g} s / 20 (probe){'; dead time ' + format(L, '.3g') + ' s' if L else ''}"
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
