"""The PID law as data: hand-checked cases every implementation must reproduce.

The law is the 2-DOF positional PID of prlpid_fmi/control/pid.py with an output rate limit (paper
eq. 2 when b = c = 1, Tf = 0 and no rate limit, which every case before the 2-DOF law has). One
specification, four implementations: the Python PID (prlpid_fmi/control/pid.py), the C reward
forecast of the bundled plants (plant_sources/common/forecast.c), the exported C controller and the
exported IEC 61131-3 Structured Text (prlpid_fmi/export/templates/). tests/test_pid_law_spec.py runs the cases through
each of them (skipping, with the reason, a case an implementation cannot be given).
Changing the law means changing this file: the equations below,
`exact_u` (the same equations in exact rational arithmetic) and the literal numbers of the cases;
the tests then say which implementation still follows the old law.

The law, per loop i and sample k (dt = sample time [s]; e, ep, ed, I, D in error units, error units
* s and error units / s; all gains are those of sample k; b, c, Tf, the rate limit R per loop and the
filter order n per case, constant)::

    yf(k)    = F(y(k))                            measurement filter (below; Tf = 0: yf = y exactly)
    e(k)     = r(k) - y(k)                        integral error (unfiltered, unweighted)
    ep(k)    = b*r(k) - yf(k)                     proportional error, setpoint weight b in [0, 1]
    ed(k)    = c*r(k) - yf(k)                     derivative error, c in [0, 1] (0: on the measurement)
    D(k)     = (ed(k) - ed(k-1)) / dt             backward difference
    Ki(k)    = Kp(k) / Ti(k)                      Ti = inf: Ki = 0, no integral action
    I_try    = I(k-1) + e(k) * dt                 the error sum includes the current error
    u_try    = Kp(k) * (ep(k) + Td(k) * D(k)) + Ki(k) * I_try
             ( = Kp*(ep + I_try/Ti + Td*D); b = c = 1, Tf = 0: eq. 2 )
    lo(k)    = max(u_min, u(k-1) - R*dt)          the clip band: the limits, narrowed by the rate limit
    hi(k)    = min(u_max, u(k-1) + R*dt)          (R = inf: lo = u_min, hi = u_max)
    u(k)     = clip(u_try, lo(k), hi(k))          the output (u_try exactly at a limit is not saturated)
    I(k)     = I_try, except while saturated (u(k) != u_try; the band is the limits here):
               clamping:          I(k) = I(k-1) when (u_try - u(k)) * Kp*e(k) > 0, i.e. when e(k)
                                  pushes further into the limit (otherwise I_try is kept);
               back_calculation:  I(k) = I_try + g * (u(k) - u_try) / Ki,  g = dt / (Tt + dt),
                                  no correction when Ki = 0;
               none:              I(k) = I_try.

- Measurement filter F, order n = 1 or 2: n sections in series, each of time constant T = Tf/n,
  by backward Euler: x_j(k) = (T * x_j(k-1) + dt * x_{j-1}(k)) / (T + dt), x_0 = y, yf = x_n
  (order 1: 1/(1 + s Tf); order 2: 1/(1 + s Tf/2)^2). On the first sample every section starts at
  the measurement: x_j(0) = y(0), so yf(0) = y(0). Tf = 0: yf = y, no state.
- First sample (k = 0, after a reset): ed(-1) := ed(0), so D(0) = 0 (no derivative kick).
- Bumpless start, before every first sample (LoopCore always presets; u_start = 0 is a start value
  like any other): the PID is balanced at the first measurement y(0) with the output the actuator
  holds, I(-1) = (u_start - Kp(0) * ((b - 1) * y(0))) / Ki(0), so that the first output is u_start
  when r(0) = y(0), whatever b, and a setpoint step at k = 0 acts through b like any later one
  (I(-1) = 0 when Ki(0) = 0; with b = 1 this is u_start / Ki(0)).
- Rate limit R [u units / s] (inf: none): u(-1) := u_start (the preset's output), so the band of the
  first sample is around u_start; lo and hi are Python's max and min (the limit unless the rate
  band lies strictly inside it).
- Derivative filter with N: Tdf = Td/N, Df(-1) = 0 and, by backward Euler,
  Df(k) = (Tdf * Df(k-1) + dt * D(k)) / (Tdf + dt); Df replaces D in u_try (and is the state).
  Without N the derivative is D itself.
- Tracking time of back-calculation: Tt as given, else sqrt(Ti*Td), or Ti when Td = 0 (recomputed
  every sample from that sample's gains).
- Loops are independent (no coupling here: eq. 26-27's coupled error is not part of these cases).
- Gain change (the case's gain_change): "positional" (every case before the bumpless law: nothing happens) or
  "bumpless": at a sample k > 0 whose (Kp, Ti, Td) differ from sample k-1's (Kp', Ti', Td') and whose
  Ki != 0, first I(k-1) := (v - Kp*(ep(k-1) + Td*D(k-1))) / Ki with v = Kp'*(ep(k-1) + Td'*D(k-1)) + Ki'*I(k-1)
  (D as kept: filtered with N); Ki = 0: I kept. Then the law above.
- Imposed output (a loop's `imposed`, per sample None or a value; `imposed_by` names the exports' input, "manual"
  or "track"): at such a sample, after the gain change, u(k) = clip(value, u_min, u_max) (no rate band) and
  I(k) = (u(k) - Kp*(ep(k) + Td*D(k))) / Ki (Ki = 0: I kept); ed, D, the filter and u(k-1) of the rate limit
  advance as at any sample.

Case conventions: the controller's inputs r and y are given (open loop); gains may change from one
sample to the next. The expected u are literal numbers: the exact rational value computed by
`exact_u`, correctly rounded to a double, so they are exact wherever the case's numbers are dyadic
(all cases but one: dt, gains, weights, Tf and signals are multiples of powers of two, and the
floating-point implementations make no rounding error); the comment above each case gives the
arithmetic step by step, to check by hand. Non-dyadic inputs (0.1, 0.3) mean their decimal value. A
case with `static_gain` g set is also a closed loop: y(k+1) = g * u(k) for a static plant (y = g*u,
no dynamics), with constant r and gains, so a forecast rolling that plant out from y(0) must predict
y(1..n) = g * u(0..n-1) (tests/plants/StaticValve with Kv = g).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

INF = math.inf


@dataclass(frozen=True)
class Loop:
    """One loop of a case: per sample the setpoint, measurement, gains (Kp, Ti, Td) and expected u; the
    loop's structure b, c, Tf and rate limit R (constant)."""

    r: tuple
    y: tuple
    gains: tuple          # per sample: (Kp, Ti [s], Td [s])
    u: tuple              # expected saturated output per sample
    u_min: float = -INF
    u_max: float = INF
    u_start: float = 0.0  # the output the actuator holds before the first sample (the preset balances at y(0))
    Tt: float | None = None  # back-calculation tracking time [s]; None: the default rule
    b: float = 1.0        # setpoint weight of the proportional error
    c: float = 1.0        # setpoint weight of the derivative error
    Tf: float = 0.0       # measurement filter [s] (0: none)
    R: float = INF        # output rate limit [u units / s] (inf: none)
    imposed: tuple | None = None  # per sample: None (the law) or the imposed output (manual value / tracked position)
    imposed_by: str = "manual"    # the exports' input that imposes it: "manual" | "track"

    def __post_init__(self):
        n = len(self.r)
        assert len(self.y) == len(self.gains) == len(self.u) == n, "one r, y, gain triple and u per sample"
        assert self.imposed is None or len(self.imposed) == n, "one imposed entry per sample"
        assert self.imposed_by in ("manual", "track")


@dataclass(frozen=True)
class Case:
    """One hand-checked sequence: the PID's settings and its loops (independent of each other)."""

    name: str
    what: str             # what the case pins down
    dt: float
    anti_windup: str      # "clamping" | "back_calculation" | "none"
    loops: tuple
    N: float | None = None          # derivative filter: Tdf = Td/N; None: unfiltered
    static_gain: float | None = None  # see the module docstring (closed loop through y = g*u)
    filter_order: int = 1           # sections of the measurement filter (1 or 2)
    gain_change: str = "positional"  # "positional" | "bumpless" (control.pid)

    @property
    def steps(self) -> int:
        return len(self.loops[0].r)

    @property
    def n_loops(self) -> int:
        return len(self.loops)

    @property
    def constant_gains(self) -> bool:
        return all(len(set(loop.gains)) == 1 for loop in self.loops)

    @property
    def eq2(self) -> bool:
        """b = c = 1, Tf = 0 and no rate limit in every loop: paper eq. 2 (the law before setpoint weights, the
        filter and the rate limit)."""
        return self.gain_change == "positional" and all(
            loop.b == 1.0 and loop.c == 1.0 and loop.Tf == 0.0 and loop.R == INF and loop.imposed is None
            for loop in self.loops)


def constant(gains: tuple, steps: int) -> tuple:
    """The same (Kp, Ti, Td) at every sample."""
    return (tuple(float(g) for g in gains),) * steps


# -- the law in exact arithmetic ----------------------------------------------------------------

MUTATIONS = ("derivative_kick", "sum_without_current_error", "integrate_while_saturated",
             "hold_sum_whenever_saturated", "no_tracking", "tracking_time_is_ti",
             "tracking_time_sqrt_without_td", "unfiltered",
             "cold_start", "first_gains_held", "proportional_on_error", "derivative_on_error",
             "unfiltered_measurement", "integral_on_filtered", "one_filter_section", "filter_from_zero",
             "kick_at_start", "preset_at_setpoint", "preset_only_with_u_start", "no_rate_limit",
             "anti_windup_ignores_rate", "no_rescale", "rescale_without_p", "rescale_without_d",
             "rescale_to_clipped_output", "imposed_without_balance", "imposed_not_clipped")


def _q(x) -> Fraction:
    """A case's number as meant: a double that is a dyadic fraction with a small denominator (<= 2^32,
    e.g. 0.375 or -29/4096) is itself; any other is the decimal it is written as (0.1 is 1/10, not
    the nearest double)."""
    exact = Fraction(float(x))
    return exact if exact.denominator <= 2 ** 32 else Fraction(repr(float(x)))


def _sqrt(x: Fraction) -> Fraction:
    """Exact square root of a rational square (the cases choose Ti*Td so; anything else is a case error)."""
    a, b = math.isqrt(x.numerator), math.isqrt(x.denominator)
    if a * a != x.numerator or b * b != x.denominator:
        raise ValueError(f"sqrt({x}) is not rational: choose Ti*Td as the square of a rational")
    return Fraction(a, b)


def _clip(x: Fraction, lo: Fraction | None, hi: Fraction | None) -> Fraction:
    """x clipped to [lo, hi] (None: unbounded), lo tested first."""
    if lo is not None and x < lo:
        return lo
    if hi is not None and x > hi:
        return hi
    return x


def exact_u(case: Case, mutation: str | None = None) -> list[list[Fraction]]:
    """u[loop][k] of the law above, in exact rational arithmetic (independent of prlpid_fmi).

    mutation: one of MUTATIONS, a deliberately wrong law, to show that the cases tell it apart:
    derivative_kick (ed(-1) := 0), sum_without_current_error (I_try = I(k-1) + e(k-1)*dt),
    integrate_while_saturated (clamping never holds the sum), hold_sum_whenever_saturated (clamping
    holds it also when e pulls out of the limit), no_tracking (back-calculation without correction),
    tracking_time_is_ti (Tt = Ti always), tracking_time_sqrt_without_td (Tt = sqrt(Ti*Td) also when
    Td = 0, i.e. Tt = 0), unfiltered (N ignored), cold_start (no preset: I(-1) = 0, no rate band at the first sample),
    first_gains_held (the gains of sample 0 throughout), proportional_on_error (b ignored: ep = e),
    derivative_on_error (c ignored and unfiltered: ed = e), unfiltered_measurement (Tf ignored),
    integral_on_filtered (e = r - yf), one_filter_section (order 2 as one section of Tf),
    filter_from_zero (the filter starts at 0, not at y(0)), kick_at_start (the bumpless preset ignores b:
    I(-1) = u_start / Ki), preset_at_setpoint (the law before the measurement preset: r(0) in place of y(0)),
    preset_only_with_u_start (the rule before: no preset when every u_start is 0), no_rate_limit (R ignored),
    anti_windup_ignores_rate (the output clipped to the rate band, but the anti-windup sees only the limits
    u_min, u_max: it neither holds nor tracks while only the rate limit binds), no_rescale (bumpless ignored),
    rescale_without_p / rescale_without_d (the rescale leaves out the P or the D term), rescale_to_clipped_output
    (v is the previous saturated u instead of the state's output), imposed_without_balance (an imposed sample keeps
    I(k) = I_try), imposed_not_clipped (the imposed value is not clipped to the limits).
    """
    if mutation is not None and mutation not in MUTATIONS:
        raise ValueError(mutation)
    dt = _q(case.dt)
    preset = mutation != "cold_start" and (mutation != "preset_only_with_u_start"
                                           or any(loop.u_start != 0 for loop in case.loops))
    sections = 1 if mutation == "one_filter_section" else case.filter_order
    out = []
    for loop in case.loops:
        u_out = []
        integral, last_error, derivative = Fraction(0), None, Fraction(0)
        previous_e = Fraction(0)
        b, c, tf = _q(loop.b), _q(loop.c), _q(loop.Tf)
        rate = None if loop.R == INF or mutation == "no_rate_limit" else _q(loop.R)
        limits = (None if loop.u_min == -INF else _q(loop.u_min), None if loop.u_max == INF else _q(loop.u_max))
        last_u = None  # u(k-1) of the rate limit (None: none yet)
        last_p = Fraction(0)  # ep(k-1)
        if mutation == "unfiltered_measurement":
            tf = Fraction(0)
        T = tf / sections
        x = [Fraction(0)] * sections  # the filter sections' outputs
        for k in range(case.steps):
            kp, ti, td = loop.gains[0 if mutation == "first_gains_held" else k]
            kp, td = _q(kp), _q(td)
            ki = Fraction(0) if ti == INF else kp / _q(ti)
            r, y = _q(loop.r[k]), _q(loop.y[k])
            if tf == 0:
                yf = y
            else:
                if k == 0 and mutation != "filter_from_zero":
                    x = [y] * sections
                else:
                    signal = y
                    for j in range(sections):
                        x[j] = (T * x[j] + dt * signal) / (T + dt)
                        signal = x[j]
                yf = x[-1]
            e = r - (yf if mutation == "integral_on_filtered" else y)
            ep = r - y if mutation == "proportional_on_error" else b * r - yf
            ed = r - y if mutation == "derivative_on_error" else c * r - yf
            if k == 0:
                last_error = Fraction(0) if mutation == "derivative_kick" else ed
                if preset:
                    balanced_at = r if mutation == "preset_at_setpoint" else y
                    kick = Fraction(0) if mutation == "kick_at_start" else kp * ((b - 1) * balanced_at)
                    integral = (_q(loop.u_start) - kick) / ki if ki != 0 else Fraction(0)
                    last_u = _q(loop.u_start)
                previous_e = e
            d = (ed - last_error) / dt
            if case.N is not None and mutation != "unfiltered":
                tdf = td / _q(case.N)
                d = (tdf * derivative + dt * d) / (tdf + dt)
            if (case.gain_change == "bumpless" and mutation != "no_rescale" and k > 0 and ki != 0
                    and loop.gains[k] != loop.gains[k - 1]):
                kp0, ti0, td0 = loop.gains[k - 1]
                kp0, td0 = _q(kp0), _q(td0)
                ki0 = Fraction(0) if ti0 == INF else kp0 / _q(ti0)
                p0 = Fraction(0) if mutation == "rescale_without_p" else last_p
                d0 = Fraction(0) if mutation == "rescale_without_d" else derivative
                v = kp0 * (p0 + td0 * d0) + ki0 * integral
                if mutation == "rescale_to_clipped_output":
                    v = last_u
                integral = (v - kp * (p0 + td * d0)) / ki
            imposed = None if loop.imposed is None else loop.imposed[k]
            if imposed is not None:
                u = _q(imposed) if mutation == "imposed_not_clipped" else _clip(_q(imposed), *limits)
                if ki != 0 and mutation != "imposed_without_balance":
                    integral = (u - kp * (ep + td * d)) / ki
                elif mutation == "imposed_without_balance":
                    integral = integral + e * dt
                last_error, derivative, previous_e, last_u, last_p = ed, d, e, u, ep
                u_out.append(u)
                continue
            summed = previous_e if mutation == "sum_without_current_error" else e
            i_try = integral + summed * dt
            u_try = kp * (ep + td * d) + ki * i_try
            lo, hi = limits
            if rate is not None and last_u is not None:  # the band: max(u_min, down), min(u_max, up)
                down, up = last_u - rate * dt, last_u + rate * dt
                lo = down if lo is None or down > lo else lo
                hi = up if hi is None or up < hi else hi
            u = _clip(u_try, lo, hi)
            # what the anti-windup sees as the saturated output
            limited = _clip(u_try, *limits) if mutation == "anti_windup_ignores_rate" else u
            new_integral = i_try
            if limited != u_try:  # saturated
                if case.anti_windup == "clamping":
                    hold = (u_try - limited) * (kp * e) > 0  # e pushes further into the limit
                    if mutation == "hold_sum_whenever_saturated":
                        hold = True
                    elif mutation == "integrate_while_saturated":
                        hold = False
                    if hold:
                        new_integral = integral
                elif case.anti_windup == "back_calculation" and ki != 0 and mutation != "no_tracking":
                    if mutation == "tracking_time_is_ti":
                        tt = _q(ti)
                    elif loop.Tt is not None:
                        tt = _q(loop.Tt)
                    elif mutation == "tracking_time_sqrt_without_td":
                        tt = _sqrt(_q(ti) * td)
                    else:
                        tt = _sqrt(_q(ti) * td) if td > 0 else _q(ti)
                    new_integral = i_try + dt / (tt + dt) * (limited - u_try) / ki
            integral, last_error, derivative, previous_e, last_u, last_p = new_integral, ed, d, e, u, ep
            u_out.append(u)
        out.append(u_out)
    return out


# -- the cases ------------------------------------------------------------------------------------
# Above each case: its arithmetic, sample by sample (the numbers as exact decimals or fractions).
# Closed-loop cases (static_gain = 1) have y(k+1) = u(k).

# k=0: [Kp 0.5, Ti inf, Td 0] e = 1 - 4 = -3; D = 0 (e(-1) := e(0));
#      I_try = 0 + (-3)*0.5 = -1.5; u_try = 0.5*(-3 + 0*0) + 0*(-1.5) = -1.5; u = -1; saturated: I = I_try = -1.5
# k=1: e = 1 - (-1) = 2; D = (2 - (-3))/0.5 = 10;
#      I_try = -1.5 + 2*0.5 = -0.5; u_try = 0.5*(2 + 0*10) + 0*(-0.5) = 1; u = 1; I = -0.5
# k=2: e = 1 - 1 = 0; D = (0 - 2)/0.5 = -4;
#      I_try = -0.5 + 0*0.5 = -0.5; u_try = 0.5*(0 + 0*(-4)) + 0*(-0.5) = 0; u = 0; I = -0.5
# k=3: e = 1 - 0 = 1; D = (1 - 0)/0.5 = 2;
#      I_try = -0.5 + 1*0.5 = 0; u_try = 0.5*(1 + 0*2) + 0*0 = 0.5; u = 0.5; I = 0
# k=4: e = 1 - 0.5 = 0.5; D = (0.5 - 1)/0.5 = -1;
#      I_try = 0 + 0.5*0.5 = 0.25; u_try = 0.5*(0.5 + 0*(-1)) + 0*0.25 = 0.25; u = 0.25; I = 0.25
# k=5: e = 1 - 0.25 = 0.75; D = (0.75 - 0.5)/0.5 = 0.5;
#      I_try = 0.25 + 0.75*0.5 = 0.625; u_try = 0.5*(0.75 + 0*0.5) + 0*0.625 = 0.375; u = 0.375; I = 0.625
P_ONLY = Case(
    name='p_only',
    what='P only (Ti = inf, Td = 0): u = clip(Kp*e), saturating low then high',
    dt=0.5, anti_windup='none', static_gain=1.0,
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
             y=(4.0, -1.0, 1.0, 0.0, 0.5, 0.25),
             gains=constant((0.5, INF, 0.0), 6),
             u=(-1.0, 1.0, 0.0, 0.5, 0.25, 0.375), u_min=-1.0, u_max=1.0),
    ))

# k=0: [Kp 1, Ti 2, Td 0, Ki 0.5] e = 2 - 0 = 2; D = 0 (e(-1) := e(0));
#      I_try = 0 + 2*0.5 = 1; u_try = 1*(2 + 0*0) + 0.5*1 = 2.5; u = 1.5; saturated, e pushes further: I = 0 (held)
# k=1: e = 2 - 1.5 = 0.5; D = (0.5 - 2)/0.5 = -3;
#      I_try = 0 + 0.5*0.5 = 0.25; u_try = 1*(0.5 + 0*(-3)) + 0.5*0.25 = 0.625; u = 0.625; I = 0.25
# k=2: e = 2 - 0.625 = 1.375; D = (1.375 - 0.5)/0.5 = 1.75;
#      I_try = 0.25 + 1.375*0.5 = 0.9375; u_try = 1*(1.375 + 0*1.75) + 0.5*0.9375 = 1.84375; u = 1.5;
#      saturated, e pushes further: I = 0.25 (held)
# k=3: e = 2 - 1.5 = 0.5; D = (0.5 - 1.375)/0.5 = -1.75;
#      I_try = 0.25 + 0.5*0.5 = 0.5; u_try = 1*(0.5 + 0*(-1.75)) + 0.5*0.5 = 0.75; u = 0.75; I = 0.5
# k=4: e = 2 - 0.75 = 1.25; D = (1.25 - 0.5)/0.5 = 1.5;
#      I_try = 0.5 + 1.25*0.5 = 1.125; u_try = 1*(1.25 + 0*1.5) + 0.5*1.125 = 1.8125; u = 1.5;
#      saturated, e pushes further: I = 0.5 (held)
# k=5: e = 2 - 1.5 = 0.5; D = (0.5 - 1.25)/0.5 = -1.5;
#      I_try = 0.5 + 0.5*0.5 = 0.75; u_try = 1*(0.5 + 0*(-1.5)) + 0.5*0.75 = 0.875; u = 0.875; I = 0.75
# k=6: e = 2 - 0.875 = 1.125; D = (1.125 - 0.5)/0.5 = 1.25;
#      I_try = 0.75 + 1.125*0.5 = 1.3125; u_try = 1*(1.125 + 0*1.25) + 0.5*1.3125 = 1.78125; u = 1.5;
#      saturated, e pushes further: I = 0.75 (held)
# k=7: e = 2 - 1.5 = 0.5; D = (0.5 - 1.125)/0.5 = -1.25;
#      I_try = 0.75 + 0.5*0.5 = 1; u_try = 1*(0.5 + 0*(-1.25)) + 0.5*1 = 1; u = 1; I = 1
PI_CLAMPING = Case(
    name='pi_clamping',
    what='PI with clamping: saturated with e > 0, the error sum stops (I held), then resumes',
    dt=0.5, anti_windup='clamping', static_gain=1.0,
    loops=(
        Loop(r=(2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0),
             y=(0.0, 1.5, 0.625, 1.5, 0.75, 1.5, 0.875, 1.5),
             gains=constant((1.0, 2.0, 0.0), 8),
             u=(1.5, 0.625, 1.5, 0.75, 1.5, 0.875, 1.5, 1.0), u_min=0.0, u_max=1.5),
    ))

# k=0: [Kp 1, Ti 1, Td 0.25, Ki 1] e = 2 - 0 = 2; D = 0 (e(-1) := e(0));
#      I_try = 0 + 2*0.5 = 1; u_try = 1*(2 + 0.25*0) + 1*1 = 3; u = 1.5;
#      saturated, Tt 0.5, g 0.5: I = 1 + 0.5*(1.5 - 3)/1 = 0.25
# k=1: e = 2 - 1.5 = 0.5; D = (0.5 - 2)/0.5 = -3;
#      I_try = 0.25 + 0.5*0.5 = 0.5; u_try = 1*(0.5 + 0.25*(-3)) + 1*0.5 = 0.25; u = 0.25; I = 0.5
# k=2: e = 2 - 0.25 = 1.75; D = (1.75 - 0.5)/0.5 = 2.5;
#      I_try = 0.5 + 1.75*0.5 = 1.375; u_try = 1*(1.75 + 0.25*2.5) + 1*1.375 = 3.75; u = 1.5;
#      saturated, Tt 0.5, g 0.5: I = 1.375 + 0.5*(1.5 - 3.75)/1 = 0.25
# k=3: e = 2 - 1.5 = 0.5; D = (0.5 - 1.75)/0.5 = -2.5;
#      I_try = 0.25 + 0.5*0.5 = 0.5; u_try = 1*(0.5 + 0.25*(-2.5)) + 1*0.5 = 0.375; u = 0.375; I = 0.5
# k=4: e = 2 - 0.375 = 1.625; D = (1.625 - 0.5)/0.5 = 2.25;
#      I_try = 0.5 + 1.625*0.5 = 1.3125; u_try = 1*(1.625 + 0.25*2.25) + 1*1.3125 = 3.5; u = 1.5;
#      saturated, Tt 0.5, g 0.5: I = 1.3125 + 0.5*(1.5 - 3.5)/1 = 0.3125
# k=5: e = 2 - 1.5 = 0.5; D = (0.5 - 1.625)/0.5 = -2.25;
#      I_try = 0.3125 + 0.5*0.5 = 0.5625; u_try = 1*(0.5 + 0.25*(-2.25)) + 1*0.5625 = 0.5; u = 0.5; I = 0.5625
# k=6: e = 2 - 0.5 = 1.5; D = (1.5 - 0.5)/0.5 = 2;
#      I_try = 0.5625 + 1.5*0.5 = 1.3125; u_try = 1*(1.5 + 0.25*2) + 1*1.3125 = 3.3125; u = 1.5;
#      saturated, Tt 0.5, g 0.5: I = 1.3125 + 0.5*(1.5 - 3.3125)/1 = 0.40625
PID_BACK_CALCULATION = Case(
    name='pid_back_calculation',
    what='PID, back-calculation with the default Tt = sqrt(Ti*Td) = 0.5 s, saturated every other sample',
    dt=0.5, anti_windup='back_calculation', static_gain=1.0,
    loops=(
        Loop(r=(2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0),
             y=(0.0, 1.5, 0.25, 1.5, 0.375, 1.5, 0.5),
             gains=constant((1.0, 1.0, 0.25), 7),
             u=(1.5, 0.25, 1.5, 0.375, 1.5, 0.5, 1.5), u_min=-1.5, u_max=1.5),
    ))

# k=0: [Kp 1, Ti 1, Td 0, Ki 1] e = 2 - 0 = 2; D = 0 (e(-1) := e(0));
#      I_try = 0 + 2*0.5 = 1; u_try = 1*(2 + 0*0) + 1*1 = 3; u = 1.5;
#      saturated, Tt 1.5, g 0.25: I = 1 + 0.25*(1.5 - 3)/1 = 0.625
# k=1: e = 2 - 1.5 = 0.5; D = (0.5 - 2)/0.5 = -3;
#      I_try = 0.625 + 0.5*0.5 = 0.875; u_try = 1*(0.5 + 0*(-3)) + 1*0.875 = 1.375; u = 1.375; I = 0.875
# k=2: e = 2 - 1.375 = 0.625; D = (0.625 - 0.5)/0.5 = 0.25;
#      I_try = 0.875 + 0.625*0.5 = 1.1875; u_try = 1*(0.625 + 0*0.25) + 1*1.1875 = 1.8125; u = 1.5;
#      saturated, Tt 1.5, g 0.25: I = 1.1875 + 0.25*(1.5 - 1.8125)/1 = 1.109375
# k=3: e = 2 - 1.5 = 0.5; D = (0.5 - 0.625)/0.5 = -0.25;
#      I_try = 1.109375 + 0.5*0.5 = 1.359375; u_try = 1*(0.5 + 0*(-0.25)) + 1*1.359375 = 1.859375; u = 1.5;
#      saturated, Tt 1.5, g 0.25: I = 1.359375 + 0.25*(1.5 - 1.859375)/1 = 1.26953125
# k=4: e = 2 - 1.5 = 0.5; D = (0.5 - 0.5)/0.5 = 0;
#      I_try = 1.26953125 + 0.5*0.5 = 1.51953125; u_try = 1*(0.5 + 0*0) + 1*1.51953125 = 2.01953125; u = 1.5;
#      saturated, Tt 1.5, g 0.25: I = 1.51953125 + 0.25*(1.5 - 2.01953125)/1 = 1.3896484375
# k=5: e = 2 - 1.5 = 0.5; D = (0.5 - 0.5)/0.5 = 0;
#      I_try = 1.3896484375 + 0.5*0.5 = 1.6396484375; u_try = 1*(0.5 + 0*0) + 1*1.6396484375 = 2.1396484375; u = 1.5;
#      saturated, Tt 1.5, g 0.25: I = 1.6396484375 + 0.25*(1.5 - 2.1396484375)/1 = 1.479736328125
# k=6: e = 2 - 1.5 = 0.5; D = (0.5 - 0.5)/0.5 = 0;
#      I_try = 1.479736328125 + 0.5*0.5 = 1.729736328125; u_try = 1*(0.5 + 0*0) + 1*1.729736328125 = 2.229736328125;
#      u = 1.5; saturated, Tt 1.5, g 0.25: I = 1.729736328125 + 0.25*(1.5 - 2.229736328125)/1 = 25351/16384
PI_BACK_CALCULATION_GIVEN_TT = Case(
    name='pi_back_calculation_given_tt',
    what='PI, back-calculation with a given Tt = 1.5 s (the default would be Ti = 1 s)',
    dt=0.5, anti_windup='back_calculation', static_gain=1.0,
    loops=(
        Loop(r=(2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0),
             y=(0.0, 1.5, 1.375, 1.5, 1.5, 1.5, 1.5),
             gains=constant((1.0, 1.0, 0.0), 7),
             u=(1.5, 1.375, 1.5, 1.5, 1.5, 1.5, 1.5), u_min=-1.5, u_max=1.5, Tt=1.5),
    ))

# k=0: [Kp 0.5, Ti 1, Td 0.25, Ki 0.5] e = 1 - 0 = 1; D = 0 (e(-1) := e(0));
#      I_try = 0 + 1*0.5 = 0.5; u_try = 0.5*(1 + 0.25*0) + 0.5*0.5 = 0.75; u = 0.75; I = 0.5
# k=1: e = 1 - 0.75 = 0.25; D = (0.25 - 1)/0.5 = -1.5;
#      I_try = 0.5 + 0.25*0.5 = 0.625; u_try = 0.5*(0.25 + 0.25*(-1.5)) + 0.5*0.625 = 0.25; u = 0.25; I = 0.625
# k=2: e = 1 - 0.25 = 0.75; D = (0.75 - 0.25)/0.5 = 1;
#      I_try = 0.625 + 0.75*0.5 = 1; u_try = 0.5*(0.75 + 0.25*1) + 0.5*1 = 1; u = 1; I = 1
# k=3: e = 1 - 1 = 0; D = (0 - 0.75)/0.5 = -1.5;
#      I_try = 1 + 0*0.5 = 1; u_try = 0.5*(0 + 0.25*(-1.5)) + 0.5*1 = 0.3125; u = 0.3125; I = 1
# k=4: e = 1 - 0.3125 = 0.6875; D = (0.6875 - 0)/0.5 = 1.375;
#      I_try = 1 + 0.6875*0.5 = 1.34375; u_try = 0.5*(0.6875 + 0.25*1.375) + 0.5*1.34375 = 1.1875; u = 1.1875;
#      I = 1.34375
# k=5: e = 1 - 1.1875 = -0.1875; D = (-0.1875 - 0.6875)/0.5 = -1.75;
#      I_try = 1.34375 + (-0.1875)*0.5 = 1.25; u_try = 0.5*(-0.1875 + 0.25*(-1.75)) + 0.5*1.25 = 0.3125; u = 0.3125;
#      I = 1.25
PID_FIRST_SAMPLE = Case(
    name='pid_first_sample',
    what='PID without limits: D(0) = 0 by e(-1) := e(0), then the derivative of a changing error',
    dt=0.5, anti_windup='none', static_gain=1.0,
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.0, 0.75, 0.25, 1.0, 0.3125, 1.1875),
             gains=constant((0.5, 1.0, 0.25), 6),
             u=(0.75, 0.25, 1.0, 0.3125, 1.1875, 0.3125)),
    ))

# k=0: [Kp 0.5, Ti 1, Td 0.5, Ki 0.5] e = 1 - 0 = 1; D = 0 (e(-1) := e(0)), Df = (0.25*0 + 0.25*D)/0.5 = 0;
#      I_try = 0 + 1*0.25 = 0.25; u_try = 0.5*(1 + 0.5*0) + 0.5*0.25 = 0.625; u = 0.625; I = 0.25
# k=1: e = 1 - 0.625 = 0.375; D = (0.375 - 1)/0.25 = -2.5, Df = (0.25*0 + 0.25*D)/0.5 = -1.25;
#      I_try = 0.25 + 0.375*0.25 = 0.34375; u_try = 0.5*(0.375 + 0.5*(-1.25)) + 0.5*0.34375 = 0.046875; u = 0.046875;
#      I = 0.34375
# k=2: e = 1 - 0.046875 = 0.953125; D = (0.953125 - 0.375)/0.25 = 2.3125, Df = (0.25*(-1.25) + 0.25*D)/0.5 = 0.53125;
#      I_try = 0.34375 + 0.953125*0.25 = 0.58203125;
#      u_try = 0.5*(0.953125 + 0.5*0.53125) + 0.5*0.58203125 = 0.900390625; u = 0.900390625; I = 0.58203125
# k=3: e = 1 - 0.900390625 = 0.099609375; D = (0.099609375 - 0.953125)/0.25 = -3.4140625;
#      Df = (0.25*0.53125 + 0.25*D)/0.5 = -1.44140625;
#      I_try = 0.58203125 + 0.099609375*0.25 = 0.60693359375;
#      u_try = 0.5*(0.099609375 + 0.5*(-1.44140625)) + 0.5*0.60693359375 = -29/4096; u = -29/4096; I = 0.60693359375
# k=4: e = 1 - (-29/4096) = 1.007080078125; D = (1.007080078125 - 0.099609375)/0.25 = 3.6298828125;
#      Df = (0.25*(-1.44140625) + 0.25*D)/0.5 = 1.09423828125;
#      I_try = 0.60693359375 + 1.007080078125*0.25 = 14069/16384;
#      u_try = 0.5*(1.007080078125 + 0.5*1.09423828125) + 0.5*(14069/16384) = 39533/32768; u = 39533/32768;
#      I = 14069/16384
# k=5: e = 1 - (39533/32768) = -6765/32768; D = (-6765/32768 - 1.007080078125)/0.25 = -39765/8192;
#      Df = (0.25*1.09423828125 + 0.25*D)/0.5 = -30801/16384;
#      I_try = 14069/16384 + (-6765/32768)*0.25 = 105787/131072;
#      u_try = 0.5*(-6765/32768 + 0.5*(-30801/16384)) + 0.5*(105787/131072) = -44477/262144; u = -44477/262144;
#      I = 105787/131072
PID_DERIVATIVE_FILTER = Case(
    name='pid_derivative_filter',
    what='PID with the derivative filter N = 2 (Tf = Td/N = dt, so Df = (Df(k-1) + D)/2), clamping',
    dt=0.25, anti_windup='clamping', N=2.0, static_gain=1.0,
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.0, 0.625, 0.046875, 0.900390625, -0.007080078125, 1.206451416015625),
             gains=constant((0.5, 1.0, 0.5), 6),
             u=(0.625, 0.046875, 0.900390625, -0.007080078125, 1.206451416015625, -0.16966629028320312),
             u_min=-2.0, u_max=2.0),
    ))

# k=0: [Kp 1, Ti inf, Td 0.5] e = 1 - 0 = 1; D = 0 (e(-1) := e(0));
#      I_try = 0 + 1*0.5 = 0.5; u_try = 1*(1 + 0.5*0) + 0*0.5 = 1; u = 1; I = 0.5
# k=1: e = 1 - 1 = 0; D = (0 - 1)/0.5 = -2;
#      I_try = 0.5 + 0*0.5 = 0.5; u_try = 1*(0 + 0.5*(-2)) + 0*0.5 = -1; u = -1; I = 0.5
# k=2: e = 1 - (-1) = 2; D = (2 - 0)/0.5 = 4;
#      I_try = 0.5 + 2*0.5 = 1.5; u_try = 1*(2 + 0.5*4) + 0*1.5 = 4; u = 1; saturated, Ki = 0: I = I_try = 1.5
# k=3: e = 1 - 1 = 0; D = (0 - 2)/0.5 = -4;
#      I_try = 1.5 + 0*0.5 = 1.5; u_try = 1*(0 + 0.5*(-4)) + 0*1.5 = -2; u = -1; saturated, Ki = 0: I = I_try = 1.5
# k=4: e = 1 - (-1) = 2; D = (2 - 0)/0.5 = 4;
#      I_try = 1.5 + 2*0.5 = 2.5; u_try = 1*(2 + 0.5*4) + 0*2.5 = 4; u = 1; saturated, Ki = 0: I = I_try = 2.5
# k=5: e = 1 - 1 = 0; D = (0 - 2)/0.5 = -4;
#      I_try = 2.5 + 0*0.5 = 2.5; u_try = 1*(0 + 0.5*(-4)) + 0*2.5 = -2; u = -1; saturated, Ki = 0: I = I_try = 2.5
PD_WITHOUT_INTEGRAL = Case(
    name='pd_without_integral',
    what='PD with Ti = inf under back-calculation: saturated, but Ki = 0 so no correction (and no division by Ki)',
    dt=0.5, anti_windup='back_calculation', static_gain=1.0,
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.0, 1.0, -1.0, 1.0, -1.0, 1.0),
             gains=constant((1.0, INF, 0.5), 6),
             u=(1.0, -1.0, 1.0, -1.0, 1.0, -1.0), u_min=-1.0, u_max=1.0),
    ))

# k=0: [Kp 1, Ti 0.5, Td 0, Ki 2] I(-1) = u_start/Ki = 1.5/2 = 0.75
#      e = 0.5 - 0.5 = 0; D = 0 (e(-1) := e(0));
#      I_try = 0.75 + 0*0.5 = 0.75; u_try = 1*(0 + 0*0) + 2*0.75 = 1.5; u = 1.5; I = 0.75
# k=1: e = 0.5 - 1.5 = -1; D = (-1 - 0)/0.5 = -2;
#      I_try = 0.75 + (-1)*0.5 = 0.25; u_try = 1*(-1 + 0*(-2)) + 2*0.25 = -0.5; u = 0;
#      saturated, Tt 0.5, g 0.5: I = 0.25 + 0.5*(0 - (-0.5))/2 = 0.375
# k=2: e = 0.5 - 0 = 0.5; D = (0.5 - (-1))/0.5 = 3;
#      I_try = 0.375 + 0.5*0.5 = 0.625; u_try = 1*(0.5 + 0*3) + 2*0.625 = 1.75; u = 1.75; I = 0.625
# k=3: e = 0.5 - 1.75 = -1.25; D = (-1.25 - 0.5)/0.5 = -3.5;
#      I_try = 0.625 + (-1.25)*0.5 = 0; u_try = 1*(-1.25 + 0*(-3.5)) + 2*0 = -1.25; u = 0;
#      saturated, Tt 0.5, g 0.5: I = 0 + 0.5*(0 - (-1.25))/2 = 0.3125
# k=4: e = 0.5 - 0 = 0.5; D = (0.5 - (-1.25))/0.5 = 3.5;
#      I_try = 0.3125 + 0.5*0.5 = 0.5625; u_try = 1*(0.5 + 0*3.5) + 2*0.5625 = 1.625; u = 1.625; I = 0.5625
# k=5: e = 0.5 - 1.625 = -1.125; D = (-1.125 - 0.5)/0.5 = -3.25;
#      I_try = 0.5625 + (-1.125)*0.5 = 0; u_try = 1*(-1.125 + 0*(-3.25)) + 2*0 = -1.125; u = 0;
#      saturated, Tt 0.5, g 0.5: I = 0 + 0.5*(0 - (-1.125))/2 = 0.28125
# k=6: e = 0.5 - 0 = 0.5; D = (0.5 - (-1.125))/0.5 = 3.25;
#      I_try = 0.28125 + 0.5*0.5 = 0.53125; u_try = 1*(0.5 + 0*3.25) + 2*0.53125 = 1.5625; u = 1.5625; I = 0.53125
# k=7: e = 0.5 - 1.5625 = -1.0625; D = (-1.0625 - 0.5)/0.5 = -3.125;
#      I_try = 0.53125 + (-1.0625)*0.5 = 0; u_try = 1*(-1.0625 + 0*(-3.125)) + 2*0 = -1.0625; u = 0;
#      saturated, Tt 0.5, g 0.5: I = 0 + 0.5*(0 - (-1.0625))/2 = 0.265625
BUMPLESS_START = Case(
    name='bumpless_start',
    what='bumpless start u_start = 1.5 with e(0) = 0: u(0) = u_start; then back-calculation with Tt = Ti (Td = 0)',
    dt=0.5, anti_windup='back_calculation', static_gain=1.0,
    loops=(
        Loop(r=(0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5),
             y=(0.5, 1.5, 0.0, 1.75, 0.0, 1.625, 0.0, 1.5625),
             gains=constant((1.0, 0.5, 0.0), 8),
             u=(1.5, 0.0, 1.75, 0.0, 1.625, 0.0, 1.5625, 0.0), u_min=0.0, u_max=2.0, u_start=1.5),
    ))

# k=0: [Kp 1, Ti 1, Td 0.25, Ki 1] e = 1 - 0 = 1; D = 0 (e(-1) := e(0));
#      I_try = 0 + 1*0.5 = 0.5; u_try = 1*(1 + 0.25*0) + 1*0.5 = 1.5; u = 1;
#      saturated, Tt 0.5, g 0.5: I = 0.5 + 0.5*(1 - 1.5)/1 = 0.25
# k=1: e = 1 - 0.5 = 0.5; D = (0.5 - 1)/0.5 = -1;
#      I_try = 0.25 + 0.5*0.5 = 0.5; u_try = 1*(0.5 + 0.25*(-1)) + 1*0.5 = 0.75; u = 0.75; I = 0.5
# k=2: e = 1 - 1.5 = -0.5; D = (-0.5 - 0.5)/0.5 = -2;
#      I_try = 0.5 + (-0.5)*0.5 = 0.25; u_try = 1*(-0.5 + 0.25*(-2)) + 1*0.25 = -0.75; u = -0.75; I = 0.25
# k=3: e = 1 - 1 = 0; D = (0 - (-0.5))/0.5 = 1;
#      I_try = 0.25 + 0*0.5 = 0.25; u_try = 1*(0 + 0.25*1) + 1*0.25 = 0.5; u = 0.5; I = 0.25
# k=4: [Kp 2, Ti 0.5, Td 0, Ki 4] e = 2 - 1 = 1; D = (1 - 0)/0.5 = 2;
#      I_try = 0.25 + 1*0.5 = 0.75; u_try = 2*(1 + 0*2) + 4*0.75 = 5; u = 1;
#      saturated, Tt 0.5, g 0.5: I = 0.75 + 0.5*(1 - 5)/4 = 0.25
# k=5: e = 2 - 3 = -1; D = (-1 - 1)/0.5 = -4;
#      I_try = 0.25 + (-1)*0.5 = -0.25; u_try = 2*(-1 + 0*(-4)) + 4*(-0.25) = -3; u = -1;
#      saturated, Tt 0.5, g 0.5: I = -0.25 + 0.5*(-1 - (-3))/4 = 0
# k=6: e = 2 - 2.5 = -0.5; D = (-0.5 - (-1))/0.5 = 1;
#      I_try = 0 + (-0.5)*0.5 = -0.25; u_try = 2*(-0.5 + 0*1) + 4*(-0.25) = -2; u = -1;
#      saturated, Tt 0.5, g 0.5: I = -0.25 + 0.5*(-1 - (-2))/4 = -0.125
# k=7: e = 2 - 1.5 = 0.5; D = (0.5 - (-0.5))/0.5 = 2;
#      I_try = -0.125 + 0.5*0.5 = 0.125; u_try = 2*(0.5 + 0*2) + 4*0.125 = 1.5; u = 1;
#      saturated, Tt 0.5, g 0.5: I = 0.125 + 0.5*(1 - 1.5)/4 = 0.0625
GAIN_CHANGE = Case(
    name='gain_change',
    what=('gains change between samples 3 and 4 (Kp 1 -> 2, Ti 1 -> 0.5, Td 0.25 -> 0) with the setpoint; '
          'back-calculation with Tt = sqrt(Ti*Td), then Tt = Ti'),
    dt=0.5, anti_windup='back_calculation',
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0),
             y=(0.0, 0.5, 1.5, 1.0, 1.0, 3.0, 2.5, 1.5),
             gains=constant((1.0, 1.0, 0.25), 4) + constant((2.0, 0.5, 0.0), 4),
             u=(1.0, 0.75, -0.75, 0.5, 1.0, -1.0, -1.0, 1.0), u_min=-1.0, u_max=1.0),
    ))

# loop 1:
# k=0: [Kp 2, Ti 0.3, Td 0.05, Ki 20/3] e = 1 - 0 = 1; D = 0 (e(-1) := e(0));
#      I_try = 0 + 1*0.1 = 0.1; u_try = 2*(1 + 0.05*0) + (20/3)*0.1 = 8/3; u = 1;
#      saturated, e pushes further: I = 0 (held)
# k=1: e = 1 - 0.2 = 0.8; D = (0.8 - 1)/0.1 = -2;
#      I_try = 0 + 0.8*0.1 = 0.08; u_try = 2*(0.8 + 0.05*(-2)) + (20/3)*0.08 = 29/15; u = 1;
#      saturated, e pushes further: I = 0 (held)
# k=2: e = 1 - 0.5 = 0.5; D = (0.5 - 0.8)/0.1 = -3;
#      I_try = 0 + 0.5*0.1 = 0.05; u_try = 2*(0.5 + 0.05*(-3)) + (20/3)*0.05 = 31/30; u = 1;
#      saturated, e pushes further: I = 0 (held)
# k=3: e = 1 - 0.9 = 0.1; D = (0.1 - 0.5)/0.1 = -4;
#      I_try = 0 + 0.1*0.1 = 0.01; u_try = 2*(0.1 + 0.05*(-4)) + (20/3)*0.01 = -2/15; u = -2/15; I = 0.01
# k=4: e = 1 - 1.1 = -0.1; D = (-0.1 - 0.1)/0.1 = -2;
#      I_try = 0.01 + (-0.1)*0.1 = 0; u_try = 2*(-0.1 + 0.05*(-2)) + (20/3)*0 = -0.4; u = -0.4; I = 0
# k=5: e = 1 - 1 = 0; D = (0 - (-0.1))/0.1 = 1;
#      I_try = 0 + 0*0.1 = 0; u_try = 2*(0 + 0.05*1) + (20/3)*0 = 0.1; u = 0.1; I = 0
# loop 2:
# k=0: [Kp 1, Ti 0.5, Td 0.1, Ki 2] e = 0 - 2 = -2; D = 0 (e(-1) := e(0));
#      I_try = 0 + (-2)*0.1 = -0.2; u_try = 1*(-2 + 0.1*0) + 2*(-0.2) = -2.4; u = -0.5;
#      saturated, e pushes further: I = 0 (held)
# k=1: e = 0 - 0.5 = -0.5; D = (-0.5 - (-2))/0.1 = 15;
#      I_try = 0 + (-0.5)*0.1 = -0.05; u_try = 1*(-0.5 + 0.1*15) + 2*(-0.05) = 0.9; u = 0.5;
#      saturated, e pulls back: I = I_try = -0.05
# k=2: e = 0 - 0.3 = -0.3; D = (-0.3 - (-0.5))/0.1 = 2;
#      I_try = -0.05 + (-0.3)*0.1 = -0.08; u_try = 1*(-0.3 + 0.1*2) + 2*(-0.08) = -0.26; u = -0.26; I = -0.08
# k=3: e = 0 - 0.1 = -0.1; D = (-0.1 - (-0.3))/0.1 = 2;
#      I_try = -0.08 + (-0.1)*0.1 = -0.09; u_try = 1*(-0.1 + 0.1*2) + 2*(-0.09) = -0.08; u = -0.08; I = -0.09
# k=4: e = 0 - (-0.1) = 0.1; D = (0.1 - (-0.1))/0.1 = 2;
#      I_try = -0.09 + 0.1*0.1 = -0.08; u_try = 1*(0.1 + 0.1*2) + 2*(-0.08) = 0.14; u = 0.14; I = -0.08
# k=5: e = 0 - 0 = 0; D = (0 - 0.1)/0.1 = -1;
#      I_try = -0.08 + 0*0.1 = -0.08; u_try = 1*(0 + 0.1*(-1)) + 2*(-0.08) = -0.26; u = -0.26; I = -0.08
TWO_LOOPS = Case(
    name='two_loops',
    what=('two independent loops, dt = 0.1 s (not dyadic: the expected values are rounded decimals), clamping; '
          'loop 2 saturates high while e < 0, so its sum keeps integrating'),
    dt=0.1, anti_windup='clamping',
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.0, 0.2, 0.5, 0.9, 1.1, 1.0),
             gains=constant((2.0, 0.3, 0.05), 6),
             u=(1.0, 1.0, 1.0, -0.13333333333333333, -0.4, 0.1), u_min=-1.0, u_max=1.0),
        Loop(r=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
             y=(2.0, 0.5, 0.3, 0.1, -0.1, 0.0),
             gains=constant((1.0, 0.5, 0.1), 6),
             u=(-0.5, 0.5, -0.26, -0.08, 0.14, -0.26), u_min=-0.5, u_max=0.5),
    ))

# -- the 2-DOF law: setpoint weights, the measurement filter, the bumpless preset with b != 1 ------------
# Lines show ep = b*r - yf and ed = c*r - yf where they differ from e, and yf where the measurement is filtered.

# k=0: [Kp 0.5, Ti 1, Td 0, Ki 0.5] e = 1 - 0 = 1, ep = 0.5*1 - 0 = 0.5; D = 0 (e(-1) := e(0));
#      I_try = 0 + 1*0.5 = 0.5; u_try = 0.5*(0.5 + 0*0) + 0.5*0.5 = 0.5; u = 0.5; I = 0.5
# k=1: e = 1 - 0.5 = 0.5, ep = 0.5*1 - 0.5 = 0; D = (0.5 - 1)/0.5 = -1; I_try = 0.5 + 0.5*0.5 = 0.75;
#      u_try = 0.5*(0 + 0*(-1)) + 0.5*0.75 = 0.375; u = 0.375; I = 0.75
# k=2: e = 1 - 0.375 = 0.625, ep = 0.5*1 - 0.375 = 0.125; D = (0.625 - 0.5)/0.5 = 0.25;
#      I_try = 0.75 + 0.625*0.5 = 1.0625; u_try = 0.5*(0.125 + 0*0.25) + 0.5*1.0625 = 0.59375; u = 0.59375; I = 1.0625
# k=3: e = 1 - 0.59375 = 0.40625, ep = 0.5*1 - 0.59375 = -0.09375; D = (0.40625 - 0.625)/0.5 = -0.4375;
#      I_try = 1.0625 + 0.40625*0.5 = 1.265625; u_try = 0.5*(-0.09375 + 0*(-0.4375)) + 0.5*1.265625 = 0.5859375;
#      u = 0.5859375; I = 1.265625
# k=4: e = 1 - 0.5859375 = 0.4140625, ep = 0.5*1 - 0.5859375 = -0.0859375; D = (0.4140625 - 0.40625)/0.5 = 0.015625;
#      I_try = 1.265625 + 0.4140625*0.5 = 1.47265625;
#      u_try = 0.5*(-0.0859375 + 0*0.015625) + 0.5*1.47265625 = 0.693359375; u = 0.693359375; I = 1.47265625
# k=5: e = 1 - 0.693359375 = 0.306640625, ep = 0.5*1 - 0.693359375 = -0.193359375;
#      D = (0.306640625 - 0.4140625)/0.5 = -0.21484375; I_try = 1.47265625 + 0.306640625*0.5 = 1.6259765625;
#      u_try = 0.5*(-0.193359375 + 0*(-0.21484375)) + 0.5*1.6259765625 = 0.71630859375; u = 0.71630859375;
#      I = 1.6259765625
SETPOINT_WEIGHT = Case(
    name='setpoint_weight',
    what=('setpoint weight b = 0.5 on a setpoint step from rest (closed loop): P acts on b*r - y, I on r - y '
          '(u(0) = 0.5; b = 1 would give 0.75)'),
    dt=0.5, anti_windup='clamping', static_gain=1.0,
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.0, 0.5, 0.375, 0.59375, 0.5859375, 0.693359375),
             gains=constant((0.5, 1.0, 0.0), 6),
             u=(0.5, 0.375, 0.59375, 0.5859375, 0.693359375, 0.71630859375), u_min=-2.0, u_max=2.0, b=0.5),
    ))

# k=0: [Kp 1, Ti 2, Td 0.5, Ki 0.5] e = 0 - 0 = 0, ed = 0*0 - 0 = 0; D = 0 (ed(-1) := ed(0)); I_try = 0 + 0*0.5 = 0;
#      u_try = 1*(0 + 0.5*0) + 0.5*0 = 0; u = 0; I = 0
# k=1: e = 0 - 0 = 0, ed = 0*0 - 0 = 0; D = (0 - 0)/0.5 = 0; I_try = 0 + 0*0.5 = 0; u_try = 1*(0 + 0.5*0) + 0.5*0 = 0;
#      u = 0; I = 0
# k=2: e = 1 - 0 = 1, ed = 0*1 - 0 = 0; D = (0 - 0)/0.5 = 0; I_try = 0 + 1*0.5 = 0.5;
#      u_try = 1*(1 + 0.5*0) + 0.5*0.5 = 1.25; u = 1.25; I = 0.5
# k=3: e = 1 - 0.25 = 0.75, ed = 0*1 - 0.25 = -0.25; D = ((-0.25) - 0)/0.5 = -0.5; I_try = 0.5 + 0.75*0.5 = 0.875;
#      u_try = 1*(0.75 + 0.5*(-0.5)) + 0.5*0.875 = 0.9375; u = 0.9375; I = 0.875
# k=4: e = 1 - 0.5 = 0.5, ed = 0*1 - 0.5 = -0.5; D = ((-0.5) - (-0.25))/0.5 = -0.5; I_try = 0.875 + 0.5*0.5 = 1.125;
#      u_try = 1*(0.5 + 0.5*(-0.5)) + 0.5*1.125 = 0.8125; u = 0.8125; I = 1.125
# k=5: e = 1 - 0.5 = 0.5, ed = 0*1 - 0.5 = -0.5; D = ((-0.5) - (-0.5))/0.5 = 0; I_try = 1.125 + 0.5*0.5 = 1.375;
#      u_try = 1*(0.5 + 0.5*0) + 0.5*1.375 = 1.1875; u = 1.1875; I = 1.375
DERIVATIVE_ON_MEASUREMENT = Case(
    name='derivative_on_measurement',
    what=('c = 0, derivative on the measurement: the setpoint step at k = 2 gives no derivative kick (D = 0 '
          'there; c = 1 would add Kp*Td*1/dt = 1)'),
    dt=0.5, anti_windup='none',
    loops=(
        Loop(r=(0.0, 0.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.0, 0.0, 0.0, 0.25, 0.5, 0.5),
             gains=constant((1.0, 2.0, 0.5), 6),
             u=(0.0, 0.0, 1.25, 0.9375, 0.8125, 1.1875), c=0.0),
    ))

# k=0: [Kp 0.5, Ti 1, Td 0.25, Ki 0.5] yf = y(0) = 0.5 (filter starts at y);
#      e = 1 - 0.5 = 0.5, ep = 1*1 - 0.5 = 0.5, ed = 1*1 - 0.5 = 0.5; D = 0 (ed(-1) := ed(0));
#      I_try = 0 + 0.5*0.5 = 0.25; u_try = 0.5*(0.5 + 0.25*0) + 0.5*0.25 = 0.375; u = 0.375; I = 0.25
# k=1: yf = (0.5*0.5 + 0.5*0.375)/1 = 0.4375;
#      e = 1 - 0.375 = 0.625, ep = 1*1 - 0.4375 = 0.5625, ed = 1*1 - 0.4375 = 0.5625; D = (0.5625 - 0.5)/0.5 = 0.125;
#      I_try = 0.25 + 0.625*0.5 = 0.5625; u_try = 0.5*(0.5625 + 0.25*0.125) + 0.5*0.5625 = 0.578125; u = 0.578125;
#      I = 0.5625
# k=2: yf = (0.5*0.4375 + 0.5*0.578125)/1 = 0.5078125;
#      e = 1 - 0.578125 = 0.421875, ep = 1*1 - 0.5078125 = 0.4921875, ed = 1*1 - 0.5078125 = 0.4921875;
#      D = (0.4921875 - 0.5625)/0.5 = -0.140625; I_try = 0.5625 + 0.421875*0.5 = 0.7734375;
#      u_try = 0.5*(0.4921875 + 0.25*(-0.140625)) + 0.5*0.7734375 = 0.615234375; u = 0.615234375; I = 0.7734375
# k=3: yf = (0.5*0.5078125 + 0.5*0.615234375)/1 = 0.5615234375; e = 1 - 0.615234375 = 0.384765625,
#      ep = 1*1 - 0.5615234375 = 0.4384765625, ed = 1*1 - 0.5615234375 = 0.4384765625;
#      D = (0.4384765625 - 0.4921875)/0.5 = -0.107421875; I_try = 0.7734375 + 0.384765625*0.5 = 0.9658203125;
#      u_try = 0.5*(0.4384765625 + 0.25*(-0.107421875)) + 0.5*0.9658203125 = 0.688720703125; u = 0.688720703125;
#      I = 0.9658203125
# k=4: yf = (0.5*0.5615234375 + 0.5*0.688720703125)/1 = 0.6251220703125; e = 1 - 0.688720703125 = 0.311279296875,
#      ep = 1*1 - 0.6251220703125 = 0.3748779296875, ed = 1*1 - 0.6251220703125 = 0.3748779296875;
#      D = (0.3748779296875 - 0.4384765625)/0.5 = -0.127197265625;
#      I_try = 0.9658203125 + 0.311279296875*0.5 = 1.1214599609375;
#      u_try = 0.5*(0.3748779296875 + 0.25*(-0.127197265625)) + 0.5*1.1214599609375 = 23995/32768; u = 23995/32768;
#      I = 1.1214599609375
MEASUREMENT_FILTER_FIRST_ORDER = Case(
    name='measurement_filter_first_order',
    what=('measurement filter Tf = 0.5 s, order 1 (T = Tf = dt: yf = (yf(k-1) + y)/2), started at y(0) = 0.5; '
          'P and D on yf, I on the unfiltered r - y'),
    dt=0.5, anti_windup='none', static_gain=1.0,
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.5, 0.375, 0.578125, 0.615234375, 0.688720703125),
             gains=constant((0.5, 1.0, 0.25), 5),
             u=(0.375, 0.578125, 0.615234375, 0.688720703125, 0.732269287109375), Tf=0.5),
    ))

# k=0: [Kp 0.5, Ti 1, Td 0.25, Ki 0.5] yf = y(0) = 0.25 (filter starts at y);
#      e = 1 - 0.25 = 0.75, ep = 1*1 - 0.25 = 0.75, ed = 0*1 - 0.25 = -0.25; D = 0 (ed(-1) := ed(0));
#      I_try = 0 + 0.75*0.5 = 0.375; u_try = 0.5*(0.75 + 0.25*0) + 0.5*0.375 = 0.5625; u = 0.5625; I = 0.375
# k=1: x1 = (0.5*0.25 + 0.5*0.5625)/1 = 0.40625; yf = (0.5*0.25 + 0.5*0.40625)/1 = 0.328125;
#      e = 1 - 0.5625 = 0.4375, ep = 1*1 - 0.328125 = 0.671875, ed = 0*1 - 0.328125 = -0.328125;
#      D = ((-0.328125) - (-0.25))/0.5 = -0.15625; I_try = 0.375 + 0.4375*0.5 = 0.59375;
#      u_try = 0.5*(0.671875 + 0.25*(-0.15625)) + 0.5*0.59375 = 0.61328125; u = 0.61328125; I = 0.59375
# k=2: x1 = (0.5*0.40625 + 0.5*0.61328125)/1 = 0.509765625; yf = (0.5*0.328125 + 0.5*0.509765625)/1 = 0.4189453125;
#      e = 1 - 0.61328125 = 0.38671875, ep = 1*1 - 0.4189453125 = 0.5810546875,
#      ed = 0*1 - 0.4189453125 = -0.4189453125; D = ((-0.4189453125) - (-0.328125))/0.5 = -0.181640625;
#      I_try = 0.59375 + 0.38671875*0.5 = 0.787109375;
#      u_try = 0.5*(0.5810546875 + 0.25*(-0.181640625)) + 0.5*0.787109375 = 0.661376953125; u = 0.661376953125;
#      I = 0.787109375
# k=3: x1 = (0.5*0.509765625 + 0.5*0.661376953125)/1 = 0.5855712890625;
#      yf = (0.5*0.4189453125 + 0.5*0.5855712890625)/1 = 0.50225830078125; e = 1 - 0.661376953125 = 0.338623046875,
#      ep = 1*1 - 0.50225830078125 = 0.49774169921875, ed = 0*1 - 0.50225830078125 = -8229/16384;
#      D = ((-8229/16384) - (-0.4189453125))/0.5 = -0.1666259765625;
#      I_try = 0.787109375 + 0.338623046875*0.5 = 0.9564208984375;
#      u_try = 0.5*(0.49774169921875 + 0.25*(-0.1666259765625)) + 0.5*0.9564208984375 = 46285/65536; u = 46285/65536;
#      I = 0.9564208984375
# k=4: x1 = (0.5*0.5855712890625 + 0.5*46285/65536)/1 = 84661/131072;
#      yf = (0.5*0.50225830078125 + 0.5*84661/131072)/1 = 150493/262144; e = 1 - 46285/65536 = 19251/65536,
#      ep = 1*1 - 150493/262144 = 111651/262144, ed = 0*1 - 150493/262144 = -150493/262144;
#      D = ((-150493/262144) - (-8229/16384))/0.5 = -18829/131072;
#      I_try = 0.9564208984375 + 19251/65536*0.5 = 144611/131072;
#      u_try = 0.5*(111651/262144 + 0.25*(-18829/131072)) + 0.5*144611/131072 = 782917/1048576; u = 782917/1048576;
#      I = 144611/131072
MEASUREMENT_FILTER_SECOND_ORDER = Case(
    name='measurement_filter_second_order',
    what=('measurement filter Tf = 1 s, order 2 (two sections of Tf/2 = dt: x = (x(k-1) + in)/2 each), started '
          'at y(0) = 0.25, with c = 0 (D on -yf)'),
    dt=0.5, anti_windup='none', static_gain=1.0, filter_order=2,
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.25, 0.5625, 0.61328125, 0.661376953125, 0.7062530517578125),
             gains=constant((0.5, 1.0, 0.25), 5),
             u=(0.5625, 0.61328125, 0.661376953125, 0.7062530517578125, 0.746647834777832), c=0.0, Tf=1.0),
    ))

# k=0: [Kp 1, Ti 0.5, Td 0, Ki 2] I(-1) = (u_start - Kp*((b - 1)*y(0)))/Ki = (1.5 - 1*((0.5 - 1)*0.75))/2 = 0.9375;
#      e = 0.75 - 0.75 = 0, ep = 0.5*0.75 - 0.75 = -0.375; D = 0 (e(-1) := e(0)); I_try = 0.9375 + 0*0.5 = 0.9375;
#      u_try = 1*(-0.375 + 0*0) + 2*0.9375 = 1.5; u = 1.5; I = 0.9375
# k=1: e = 0.75 - 0.75 = 0, ep = 0.5*0.75 - 0.75 = -0.375; D = (0 - 0)/0.5 = 0; I_try = 0.9375 + 0*0.5 = 0.9375;
#      u_try = 1*(-0.375 + 0*0) + 2*0.9375 = 1.5; u = 1.5; I = 0.9375
# k=2: e = 0.75 - 0.75 = 0, ep = 0.5*0.75 - 0.75 = -0.375; D = (0 - 0)/0.5 = 0; I_try = 0.9375 + 0*0.5 = 0.9375;
#      u_try = 1*(-0.375 + 0*0) + 2*0.9375 = 1.5; u = 1.5; I = 0.9375
# k=3: e = 0.75 - 0.75 = 0, ep = 0.5*0.75 - 0.75 = -0.375; D = (0 - 0)/0.5 = 0; I_try = 0.9375 + 0*0.5 = 0.9375;
#      u_try = 1*(-0.375 + 0*0) + 2*0.9375 = 1.5; u = 1.5; I = 0.9375
BUMPLESS_SETPOINT_WEIGHT = Case(
    name='bumpless_setpoint_weight',
    what=('bumpless start u_start = 1.5 with b = 0.5 and r(0) = y(0) = 0.75 != 0: '
          'I(-1) = (u_start - Kp*(b - 1)*y(0))/Ki gives u(0) = u_start (u_start/Ki would give 1.125), '
          'and the steady closed loop y = 0.5*u holds it'),
    dt=0.5, anti_windup='clamping', static_gain=0.5,
    loops=(
        Loop(r=(0.75, 0.75, 0.75, 0.75),
             y=(0.75, 0.75, 0.75, 0.75),
             gains=constant((1.0, 0.5, 0.0), 4),
             u=(1.5, 1.5, 1.5, 1.5), u_min=0.0, u_max=2.0, u_start=1.5, b=0.5),
    ))

# loop 1:
# k=0: [Kp 1, Ti 1, Td 0.5, Ki 1] yf = y(0) = 0 (filter starts at y);
#      e = 0 - 0 = 0, ep = 0.5*0 - 0 = 0, ed = 0*0 - 0 = 0; D = 0 (ed(-1) := ed(0)); I_try = 0 + 0*0.5 = 0;
#      u_try = 1*(0 + 0.5*0) + 1*0 = 0; u = 0; I = 0
# k=1: yf = (0.5*0 + 0.5*0)/1 = 0; e = 1 - 0 = 1, ep = 0.5*1 - 0 = 0.5, ed = 0*1 - 0 = 0; D = (0 - 0)/0.5 = 0;
#      I_try = 0 + 1*0.5 = 0.5; u_try = 1*(0.5 + 0.5*0) + 1*0.5 = 1; u = 1; I = 0.5
# k=2: yf = (0.5*0 + 0.5*0.5)/1 = 0.25; e = 1 - 0.5 = 0.5, ep = 0.5*1 - 0.25 = 0.25, ed = 0*1 - 0.25 = -0.25;
#      D = ((-0.25) - 0)/0.5 = -0.5; I_try = 0.5 + 0.5*0.5 = 0.75; u_try = 1*(0.25 + 0.5*(-0.5)) + 1*0.75 = 0.75;
#      u = 0.75; I = 0.75
# k=3: yf = (0.5*0.25 + 0.5*0.75)/1 = 0.5; e = 1 - 0.75 = 0.25, ep = 0.5*1 - 0.5 = 0, ed = 0*1 - 0.5 = -0.5;
#      D = ((-0.5) - (-0.25))/0.5 = -0.5; I_try = 0.75 + 0.25*0.5 = 0.875;
#      u_try = 1*(0 + 0.5*(-0.5)) + 1*0.875 = 0.625; u = 0.625; I = 0.875
# loop 2:
# k=0: [Kp 0.5, Ti 2, Td 0.25, Ki 0.25] e = 1 - 0 = 1; D = 0 (e(-1) := e(0)); I_try = 0 + 1*0.5 = 0.5;
#      u_try = 0.5*(1 + 0.25*0) + 0.25*0.5 = 0.625; u = 0.625; I = 0.5
# k=1: e = 1 - 0.5 = 0.5; D = (0.5 - 1)/0.5 = -1; I_try = 0.5 + 0.5*0.5 = 0.75;
#      u_try = 0.5*(0.5 + 0.25*(-1)) + 0.25*0.75 = 0.3125; u = 0.3125; I = 0.75
# k=2: e = 1 - 0.25 = 0.75; D = (0.75 - 0.5)/0.5 = 0.5; I_try = 0.75 + 0.75*0.5 = 1.125;
#      u_try = 0.5*(0.75 + 0.25*0.5) + 0.25*1.125 = 0.71875; u = 0.71875; I = 1.125
# k=3: e = 1 - 1 = 0; D = (0 - 0.75)/0.5 = -1.5; I_try = 1.125 + 0*0.5 = 1.125;
#      u_try = 0.5*(0 + 0.25*(-1.5)) + 0.25*1.125 = 0.09375; u = 0.09375; I = 1.125
TWO_LOOPS_STRUCTURE = Case(
    name='two_loops_structure',
    what=('two loops with their own structure: loop 1 b = 0.5, c = 0, Tf = 0.5 s (setpoint step at k = 1), '
          'loop 2 b = c = 1, Tf = 0 (eq. 2: yf = y although the PID filters loop 1)'),
    dt=0.5, anti_windup='none',
    loops=(
        Loop(r=(0.0, 1.0, 1.0, 1.0),
             y=(0.0, 0.0, 0.5, 0.75),
             gains=constant((1.0, 1.0, 0.5), 4),
             u=(0.0, 1.0, 0.75, 0.625), b=0.5, c=0.0, Tf=0.5),
        Loop(r=(1.0, 1.0, 1.0, 1.0),
             y=(0.0, 0.5, 0.25, 1.0),
             gains=constant((0.5, 2.0, 0.25), 4),
             u=(0.625, 0.3125, 0.71875, 0.09375)),
    ))

# -- the measurement preset at every start, and the rate limit --------------------------------------------
# The preset balances the PID at y(0) before every first sample (u_start = 0 too); "band" is [lo(k), hi(k)].

# k=0: [Kp 1, Ti 1, Td 0, Ki 1] I(-1) = (u_start - Kp*((b - 1)*y(0)))/Ki = (1 - 1*((0.5 - 1)*0.5))/1 = 1.25;
#      e = 1 - 0.5 = 0.5, ep = 0.5*1 - 0.5 = 0; D = 0 (e(-1) := e(0)); I_try = 1.25 + 0.5*0.5 = 1.5;
#      u_try = 1*(0 + 0*0) + 1*1.5 = 1.5; u = 1.5; I = 1.5
#      (= u_start + Kp*b*(r - y) + Ki*e*dt = 1 + 0.25 + 0.25; the preset at r(0) would give I(-1) = 1.5, u = 1.75)
# k=1: e = 1 - 0.75 = 0.25, ep = 0.5*1 - 0.75 = -0.25; D = (0.25 - 0.5)/0.5 = -0.5; I_try = 1.5 + 0.25*0.5 = 1.625;
#      u_try = 1*(-0.25 + 0*(-0.5)) + 1*1.625 = 1.375; u = 1.375; I = 1.625
# k=2: e = 1 - 0.6875 = 0.3125, ep = 0.5*1 - 0.6875 = -0.1875; D = (0.3125 - 0.25)/0.5 = 0.125;
#      I_try = 1.625 + 0.3125*0.5 = 1.78125; u_try = 1*(-0.1875 + 0*0.125) + 1*1.78125 = 1.59375; u = 1.59375;
#      I = 1.78125
# k=3: e = 1 - 0.796875 = 0.203125, ep = 0.5*1 - 0.796875 = -0.296875; D = (0.203125 - 0.3125)/0.5 = -0.21875;
#      I_try = 1.78125 + 0.203125*0.5 = 1.8828125; u_try = 1*(-0.296875 + 0*(-0.21875)) + 1*1.8828125 = 1.5859375;
#      u = 1.5859375; I = 1.8828125
# k=4: e = 1 - 0.79296875 = 0.20703125, ep = 0.5*1 - 0.79296875 = -0.29296875;
#      D = (0.20703125 - 0.203125)/0.5 = 0.0078125; I_try = 1.8828125 + 0.20703125*0.5 = 1.986328125;
#      u_try = 1*(-0.29296875 + 0*0.0078125) + 1*1.986328125 = 1.693359375; u = 1.693359375; I = 1.986328125
PRESET_SETPOINT_STEP = Case(
    name='preset_setpoint_step',
    what=('a setpoint step at t = 0 from a steady state (u_start = 1 holds y = 0.5 through y = 0.5*u) with b = 0.5: '
          'the preset at y(0) lets the step act through b, u(0) = u_start + Kp*b*(r - y) + Ki*e*dt = 1.5 '
          '(the preset at r(0) would give 1.75)'),
    dt=0.5, anti_windup='clamping', static_gain=0.5,
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.5, 0.75, 0.6875, 0.796875, 0.79296875),
             gains=constant((1.0, 1.0, 0.0), 5),
             u=(1.5, 1.375, 1.59375, 1.5859375, 1.693359375), u_min=0.0, u_max=4.0, u_start=1.0, b=0.5),
    ))

# k=0: [Kp 1, Ti 1, Td 0, Ki 1] I(-1) = (0 - 1*((0.5 - 1)*1))/1 = 0.5; e = 1 - 1 = 0, ep = 0.5*1 - 1 = -0.5;
#      D = 0 (e(-1) := e(0)); I_try = 0.5 + 0*0.5 = 0.5; u_try = 1*(-0.5 + 0*0) + 1*0.5 = 0; u = 0; I = 0.5
#      (without a preset, the rule before for u_start = 0: I(-1) = 0, u = -0.5)
# k=1: e = 0, ep = -0.5; D = (0 - 0)/0.5 = 0; I_try = 0.5; u_try = 1*(-0.5 + 0*0) + 1*0.5 = 0; u = 0; I = 0.5
# k=2: e = 1 - 0.5 = 0.5, ep = 0.5*1 - 0.5 = 0; D = (0.5 - 0)/0.5 = 1; I_try = 0.5 + 0.5*0.5 = 0.75;
#      u_try = 1*(0 + 0*1) + 1*0.75 = 0.75; u = 0.75; I = 0.75
PRESET_ZERO_START = Case(
    name='preset_zero_start',
    what=('the preset happens also when u_start = 0: with b = 0.5 and r(0) = y(0) = 1, I(-1) = Kp*(1 - b)*y(0)/Ki '
          'gives u(0) = u_start = 0 (no preset would give -0.5)'),
    dt=0.5, anti_windup='none',
    loops=(
        Loop(r=(1.0, 1.0, 1.0),
             y=(1.0, 1.0, 0.5),
             gains=constant((1.0, 1.0, 0.0), 3),
             u=(0.0, 0.0, 0.75), b=0.5),
    ))

# R*dt = 0.5*0.5 = 0.25; u(-1) = u_start = 0.
# k=0: [Kp 2, Ti 1, Td 0, Ki 2] I(-1) = (0 - 2*((1 - 1)*0))/2 = 0; e = 1 - 0 = 1; D = 0 (e(-1) := e(0));
#      I_try = 0 + 1*0.5 = 0.5; u_try = 2*(1 + 0*0) + 2*0.5 = 3; band [max(-2, 0 - 0.25), min(2, 0 + 0.25)] =
#      [-0.25, 0.25]; u = 0.25; saturated, e pushes further: I = 0 (held)
# k=1: e = 1 - 0.25 = 0.75; D = (0.75 - 1)/0.5 = -0.5; I_try = 0 + 0.75*0.5 = 0.375;
#      u_try = 2*(0.75 + 0*(-0.5)) + 2*0.375 = 2.25; band [0, 0.5]; u = 0.5; held: I = 0
# k=2: e = 1 - 0.5 = 0.5; D = (0.5 - 0.75)/0.5 = -0.5; I_try = 0 + 0.5*0.5 = 0.25;
#      u_try = 2*(0.5 + 0*(-0.5)) + 2*0.25 = 1.5; band [0.25, 0.75]; u = 0.75; held: I = 0
#      (u_try lies within [u_min, u_max]: only the rate limit binds, and the anti-windup holds all the same)
# k=3: e = 1 - 0.75 = 0.25; D = (0.25 - 0.5)/0.5 = -0.5; I_try = 0 + 0.25*0.5 = 0.125;
#      u_try = 2*(0.25 + 0*(-0.5)) + 2*0.125 = 0.75; band [0.5, 1]; u = 0.75; I = 0.125
# k=4: e = 1 - 0.75 = 0.25; D = (0.25 - 0.25)/0.5 = 0; I_try = 0.125 + 0.25*0.5 = 0.25;
#      u_try = 2*(0.25 + 0*0) + 2*0.25 = 1; band [0.5, 1]; u = 1 (at the band's edge: not saturated); I = 0.25
# k=5: e = 1 - 1 = 0; D = (0 - 0.25)/0.5 = -0.5; I_try = 0.25 + 0*0.5 = 0.25; u_try = 2*(0 + 0*(-0.5)) + 2*0.25 = 0.5;
#      band [0.75, 1.25]; u = 0.75; saturated, but e = 0 does not push: I = I_try = 0.25
# k=6: e = 1 - 0.75 = 0.25; D = (0.25 - 0)/0.5 = 0.5; I_try = 0.25 + 0.25*0.5 = 0.375;
#      u_try = 2*(0.25 + 0*0.5) + 2*0.375 = 1.25; band [0.5, 1]; u = 1; held: I = 0.25
# k=7: e = 1 - 1 = 0; D = (0 - 0.25)/0.5 = -0.5; I_try = 0.25 + 0*0.5 = 0.25; u_try = 2*(0 + 0*(-0.5)) + 2*0.25 = 0.5;
#      band [0.75, 1.25]; u = 0.75; I = 0.25
RATE_LIMIT_CLAMPING = Case(
    name='rate_limit_clamping',
    what=('rate limit R = 0.5/s (0.25 per sample) from u_start = 0 on a setpoint step, clamping: the band '
          'binds inside [u_min, u_max] = [-2, 2] and the sum is held as at a limit'),
    dt=0.5, anti_windup='clamping', static_gain=1.0,
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.0, 0.25, 0.5, 0.75, 0.75, 1.0, 0.75, 1.0),
             gains=constant((2.0, 1.0, 0.0), 8),
             u=(0.25, 0.5, 0.75, 0.75, 1.0, 0.75, 1.0, 0.75), u_min=-2.0, u_max=2.0, R=0.5),
    ))

# R*dt = 1*0.5 = 0.5; u(-1) = u_start = 0.5; Tt = Ti = 0.5 (Td = 0), g = dt/(Tt + dt) = 0.5.
# k=0: [Kp 1, Ti 0.5, Td 0, Ki 2] I(-1) = (0.5 - 1*((1 - 1)*0.5))/2 = 0.25; e = 1.5 - 0.5 = 1; D = 0 (e(-1) := e(0));
#      I_try = 0.25 + 1*0.5 = 0.75; u_try = 1*(1 + 0*0) + 2*0.75 = 2.5; band [max(-4, 0.5 - 0.5), min(4, 0.5 + 0.5)] =
#      [0, 1]; u = 1; saturated: I = 0.75 + 0.5*(1 - 2.5)/2 = 0.375
# k=1: e = 1.5 - 1 = 0.5; D = (0.5 - 1)/0.5 = -1; I_try = 0.375 + 0.5*0.5 = 0.625;
#      u_try = 1*(0.5 + 0*(-1)) + 2*0.625 = 1.75; band [0.5, 1.5]; u = 1.5; I = 0.625 + 0.5*(1.5 - 1.75)/2 = 0.5625
# k=2: e = 1.5 - 1.5 = 0; D = (0 - 0.5)/0.5 = -1; I_try = 0.5625 + 0*0.5 = 0.5625;
#      u_try = 1*(0 + 0*(-1)) + 2*0.5625 = 1.125; band [1, 2]; u = 1.125; I = 0.5625
# k=3: e = 1.5 - 1.125 = 0.375; D = (0.375 - 0)/0.5 = 0.75; I_try = 0.5625 + 0.375*0.5 = 0.75;
#      u_try = 1*(0.375 + 0*0.75) + 2*0.75 = 1.875; band [0.625, 1.625]; u = 1.625;
#      I = 0.75 + 0.5*(1.625 - 1.875)/2 = 0.6875
# k=4: e = 1.5 - 1.625 = -0.125; D = (-0.125 - 0.375)/0.5 = -1; I_try = 0.6875 + (-0.125)*0.5 = 0.625;
#      u_try = 1*(-0.125 + 0*(-1)) + 2*0.625 = 1.125; band [1.125, 2.125]; u = 1.125 (at the band's edge); I = 0.625
# k=5: e = 1.5 - 1.125 = 0.375; D = (0.375 - (-0.125))/0.5 = 1; I_try = 0.625 + 0.375*0.5 = 0.8125;
#      u_try = 1*(0.375 + 0*1) + 2*0.8125 = 2; band [0.625, 1.625]; u = 1.625; I = 0.8125 + 0.5*(1.625 - 2)/2 = 0.71875
RATE_LIMIT_BACK_CALCULATION = Case(
    name='rate_limit_back_calculation',
    what=('rate limit R = 1/s (0.5 per sample) from a steady u_start = 0.5 on a setpoint step 0.5 -> 1.5, '
          'back-calculation: the band binds inside [u_min, u_max] = [-4, 4] and the sum tracks the band'),
    dt=0.5, anti_windup='back_calculation', static_gain=1.0,
    loops=(
        Loop(r=(1.5, 1.5, 1.5, 1.5, 1.5, 1.5),
             y=(0.5, 1.0, 1.5, 1.125, 1.625, 1.125),
             gains=constant((1.0, 0.5, 0.0), 6),
             u=(1.0, 1.5, 1.125, 1.625, 1.125, 1.625), u_min=-4.0, u_max=4.0, u_start=0.5, R=1.0),
    ))

# -- the bumpless gain change and the imposed output (manual / tracking) ------------------------------------
# gain_change "bumpless": at a change, "v" is the output the old gains give on sample k-1's ep, D and sum, and
# I(k-1) := (v - Kp*(ep(k-1) + Td*D(k-1)))/Ki is what the new gains need to give v there.

# k=0: [Kp 1, Ti 1, Td 0.5, Ki 1] I(-1) = (0.5 - 1*((0.5 - 1)*0.25))/1 = 0.625; e = 1 - 0.25 = 0.75,
#      ep = 0.5*1 - 0.25 = 0.25, ed = 0*1 - 0.25 = -0.25; D = 0; I_try = 0.625 + 0.75*0.5 = 1;
#      u_try = 1*(0.25 + 0.5*0) + 1*1 = 1.25; u = 1.25; I = 1
# k=1: e = 1 - 0.375 = 0.625, ep = 0.5 - 0.375 = 0.125, ed = -0.375; D = (-0.375 - (-0.25))/0.5 = -0.25;
#      I_try = 1 + 0.625*0.5 = 1.3125; u_try = 1*(0.125 + 0.5*(-0.25)) + 1*1.3125 = 1.3125; u = 1.3125; I = 1.3125
# k=2: [Kp 2, Ti 0.5, Td 0.5, Ki 4] gain change: v = 1*(0.125 + 0.5*(-0.25)) + 1*1.3125 = 1.3125,
#      I(1) := (1.3125 - 2*(0.125 + 0.5*(-0.25)))/4 = 0.328125; e = 1.5 - 0.75 = 0.75, ep = 0.75 - 0.75 = 0,
#      ed = -0.75; D = (-0.75 - (-0.375))/0.5 = -0.75; I_try = 0.328125 + 0.75*0.5 = 0.703125;
#      u_try = 2*(0 + 0.5*(-0.75)) + 4*0.703125 = 2.0625; u = 2.0625; I = 0.703125
#      (positional: I_try = 1.3125 + 0.375 = 1.6875, u = -0.75 + 6.75 = 6)
# k=3: e = 1.5 - 1 = 0.5, ep = 0.75 - 1 = -0.25, ed = -1; D = (-1 - (-0.75))/0.5 = -0.5;
#      I_try = 0.703125 + 0.5*0.5 = 0.953125; u_try = 2*(-0.25 + 0.5*(-0.5)) + 4*0.953125 = 2.8125; u = 2.8125
BUMPLESS_GAIN_STEP = Case(
    name='bumpless_gain_step',
    what=('bumpless gain change Kp 1 -> 2, Ti 1 -> 0.5 with a setpoint step at k = 2, b = 0.5, c = 0: the sum is '
          'rescaled so that the new gains give the old output on sample 1 (its P and D terms absorbed)'),
    dt=0.5, anti_windup='none', gain_change='bumpless',
    loops=(
        Loop(r=(1.0, 1.0, 1.5, 1.5),
             y=(0.25, 0.375, 0.75, 1.0),
             gains=constant((1.0, 1.0, 0.5), 2) + constant((2.0, 0.5, 0.5), 2),
             u=(1.25, 1.3125, 2.0625, 2.8125), u_start=0.5, b=0.5, c=0.0),
    ))

# k=0: [Kp 1, Ti 1, Td 0, Ki 1] I(-1) = 0.5/1 = 0.5; e = 1 - 0 = 1; D = 0; I_try = 0.5 + 1*0.5 = 1;
#      u_try = 1*1 + 1*1 = 2; u = 1; saturated, e pushes further: I = 0.5 (held)
# k=1: e = 1 - 0.25 = 0.75; D = -0.5; I_try = 0.5 + 0.375 = 0.875; u_try = 0.75 + 0.875 = 1.625; u = 1; I = 0.5
# k=2: [Kp 2, Ti 0.5, Td 0, Ki 4] gain change: v = 1*(0.75 + 0*(-0.5)) + 1*0.5 = 1.25 (beyond the limit: the
#      state's output, not the clipped u), I(1) := (1.25 - 2*(0.75 + 0))/4 = -0.0625; e = 2 - 0.5 = 1.5; D = 1.5;
#      I_try = -0.0625 + 0.75 = 0.6875; u_try = 2*1.5 + 4*0.6875 = 5.75; u = 1; held: I = -0.0625
# k=3: e = 2 - 0.75 = 1.25; D = -0.5; I_try = -0.0625 + 0.625 = 0.5625; u_try = 2.5 + 2.25 = 4.75; u = 1;
#      held: I = -0.0625
# k=4: e = 2 - 1.75 = 0.25; D = -2; I_try = -0.0625 + 0.125 = 0.0625; u_try = 0.5 + 0.25 = 0.75; u = 0.75
#      (positional: the sum is held at 0.5, u_try = 0.5 + 4*0.625 = 3, still at the limit)
BUMPLESS_SATURATED = Case(
    name='bumpless_saturated',
    what=('a bumpless gain change while saturated, clamping: u stays at the limit, the change neither winds the sum '
          'up nor down (v = 1.25 is kept, not the clipped 1), and the loop leaves the limit as the new controller'),
    dt=0.5, anti_windup='clamping', gain_change='bumpless',
    loops=(
        Loop(r=(1.0, 1.0, 2.0, 2.0, 2.0),
             y=(0.0, 0.25, 0.5, 0.75, 1.75),
             gains=constant((1.0, 1.0, 0.0), 2) + constant((2.0, 0.5, 0.0), 3),
             u=(1.0, 1.0, 1.0, 1.0, 0.75), u_min=-1.0, u_max=1.0, u_start=0.5),
    ))

# k=0: [Kp 1, Ti 1, Td 0, Ki 1] I(-1) = (0.5 - 1*((0.5 - 1)*1))/1 = 1; e = 0, ep = 0.5*1 - 1 = -0.5; D = 0;
#      I_try = 1; u_try = -0.5 + 1 = 0.5; u = 0.5; I = 1
# k=1: the same: u = 0.5; I = 1
# k=2: [Kp -1, Ti 0.5, Td 0, Ki -2] gain change: v = 1*(-0.5) + 1*1 = 0.5, I(1) := (0.5 - (-1)*(-0.5))/(-2) = 0;
#      e = 2 - 1 = 1, ep = 0.5*2 - 1 = 0; D = (1 - 0)/0.5 = 2; I_try = 0 + 0.5 = 0.5;
#      u_try = -1*(0 + 0*2) + (-2)*0.5 = -1; u = -1; I = 0.5
# k=3: e = 1, ep = 0; D = 0; I_try = 1; u_try = 0 + (-2)*1 = -2; u = -2
BUMPLESS_SIGN_CHANGE = Case(
    name='bumpless_sign_change',
    what=('Kp changes sign (1 -> -1, Ti 1 -> 0.5; Ki -2 has its sign) at a setpoint step from an equilibrium with '
          'b = 0.5: the same rescale, u(1) = 0.5 continued, then the reverse-acting law'),
    dt=0.5, anti_windup='none', gain_change='bumpless',
    loops=(
        Loop(r=(1.0, 1.0, 2.0, 2.0),
             y=(1.0, 1.0, 1.0, 1.0),
             gains=constant((1.0, 1.0, 0.0), 2) + constant((-1.0, 0.5, 0.0), 2),
             u=(0.5, 0.5, -1.0, -2.0), u_start=0.5, b=0.5),
    ))

# k=0: [Kp 1, Ti 1, Td 0, Ki 1] I(-1) = 0.25; e = 0.5; D = 0; I_try = 0.5; u_try = 0.5 + 0.5 = 1; u = 1; I = 0.5
# k=1: e = 0.5; I_try = 0.75; u_try = 0.5 + 0.75 = 1.25; u = 1.25; I = 0.75
# k=2: [Kp 2, Ti inf, Td 0, Ki 0] gain change, Ki = 0: I kept (0.75); e = 0.5; I_try = 1; u_try = 2*0.5 + 0*1 = 1;
#      u = 1 (the jump -0.25: no integral term can hold the output); I = 1
# k=3: I_try = 1.25; u_try = 1; u = 1; I = 1.25
# k=4: [Kp 1, Ti 0.5, Td 0, Ki 2] gain change: v = 2*(0.5 + 0) + 0*1.25 = 1, I(3) := (1 - 1*0.5)/2 = 0.25;
#      e = 0.5; I_try = 0.25 + 0.25 = 0.5; u_try = 0.5 + 2*0.5 = 1.5; u = 1.5 (from 1 by Ki*e*dt only)
BUMPLESS_WITHOUT_INTEGRAL = Case(
    name='bumpless_without_integral',
    what=('bumpless, a change to Ti = inf (Ki = 0): the sum is kept and u jumps by the P term change and the lost '
          'integral term; the change back to Ki = 2 is bumpless'),
    dt=0.5, anti_windup='none', gain_change='bumpless',
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.5, 0.5, 0.5, 0.5, 0.5),
             gains=constant((1.0, 1.0, 0.0), 2) + constant((2.0, INF, 0.0), 2) + constant((1.0, 0.5, 0.0), 1),
             u=(1.0, 1.25, 1.0, 1.0, 1.5), u_start=0.25),
    ))

# k=0: [Kp 1, Ti 1, Td 0.5, Ki 1] I(-1) = (0 - 1*((0.5 - 1)*0.25))/1 = 0.125; e = 0.75, ep = 0.25, ed = -0.25;
#      D = 0; manual 1.5: u = 1.5; I = (1.5 - 1*(0.25 + 0.5*0))/1 = 1.25
# k=1: e = 0.5, ep = 0, ed = -0.5; D = -0.5; manual 1: u = 1; I = (1 - 1*(0 + 0.5*(-0.5)))/1 = 1.25
# k=2 (automatic): e = 0.5, ep = 0, ed = -0.5; D = 0; I_try = 1.25 + 0.25 = 1.5; u_try = 1*(0 + 0) + 1.5 = 1.5;
#      u = 1.5 (= 1 + Kp*Td*(D(2) - D(1)) + Ki*e*dt = 1 + 0.25 + 0.25: no bump); I = 1.5
# k=3: e = 0.25, ep = -0.25, ed = -0.75; D = -0.5; I_try = 1.625; u_try = (-0.25 - 0.25) + 1.625 = 1.125; u = 1.125
# k=4: e = 0.25, ep = -0.25, ed = -0.75; D = 0; I_try = 1.75; u_try = -0.25 + 1.75 = 1.5; u = 1.5
MANUAL_TO_AUTO = Case(
    name='manual_to_auto',
    what=('manual output 1.5 then 1 (k = 0, 1), then automatic: the sum balanced to the manual value every manual '
          'sample, so u continues from 1 with the controller\'s answer to the signals only'),
    dt=0.5, anti_windup='clamping', gain_change='bumpless',
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 1.0),
             y=(0.25, 0.5, 0.5, 0.75, 0.75),
             gains=constant((1.0, 1.0, 0.5), 5),
             u=(1.5, 1.0, 1.5, 1.125, 1.5), u_min=-2.0, u_max=2.0, b=0.5, c=0.0,
             imposed=(1.5, 1.0, None, None, None)),
    ))

# R*dt = 0.5; Tt = Ti (Td = 0).
# k=0: [Kp 1, Ti 0.5, Td 0, Ki 2] I(-1) = 0; e = 0.5; D = 0; I_try = 0.25; u_try = 0.5 + 0.5 = 1; band [-0.5, 0.5];
#      u = 0.5; g = 0.5/(0.5 + 0.5) = 0.5: I = 0.25 + 0.5*(0.5 - 1)/2 = 0.125
# k=1: tracking 3 (beyond u_max = 2): u = 2 (clipped, no rate band); I = (2 - 1*0.5)/2 = 0.75
# k=2 (automatic): e = 1 - 1.25 = -0.25; D = -1.5; I_try = 0.75 - 0.125 = 0.625; u_try = -0.25 + 1.25 = 1;
#      band [2 - 0.5, 2 + 0.5] within the limits: [1.5, 2]; u = 1.5; I = 0.625 + 0.5*(1.5 - 1)/2 = 0.75
# k=3: e = 0; D = 0.5; I_try = 0.75; u_try = 0 + 1.5 = 1.5; band [1, 2]; u = 1.5; I = 0.75
# k=4: [Kp 2, Ti 0.25, Td 0, Ki 8] gain change: v = 1*0 + 2*0.75 = 1.5, I(3) := (1.5 - 2*0)/8 = 0.1875;
#      e = 2 - 1 = 1; D = 2; I_try = 0.6875; u_try = 2*1 + 8*0.6875 = 7.5; band [1, 2]; u = 2
TRACK_TO_AUTO = Case(
    name='track_to_auto',
    what=('tracking the actuator at 3 (clipped to u_max = 2) at k = 1, then automatic with back-calculation and the '
          'rate limit from the tracked value, and a bumpless gain change at k = 4'),
    dt=0.5, anti_windup='back_calculation', gain_change='bumpless',
    loops=(
        Loop(r=(1.0, 1.0, 1.0, 1.0, 2.0),
             y=(0.5, 0.5, 1.25, 1.0, 1.0),
             gains=constant((1.0, 0.5, 0.0), 4) + constant((2.0, 0.25, 0.0), 1),
             u=(0.5, 2.0, 1.5, 1.5, 2.0), u_min=-1.0, u_max=2.0, R=1.0,
             imposed=(None, 3.0, None, None, None), imposed_by='track'),
    ))

CASES = (P_ONLY, PI_CLAMPING, PID_BACK_CALCULATION, PI_BACK_CALCULATION_GIVEN_TT, PID_FIRST_SAMPLE,
         PID_DERIVATIVE_FILTER, PD_WITHOUT_INTEGRAL, BUMPLESS_START, GAIN_CHANGE, TWO_LOOPS,
         SETPOINT_WEIGHT, DERIVATIVE_ON_MEASUREMENT, MEASUREMENT_FILTER_FIRST_ORDER, MEASUREMENT_FILTER_SECOND_ORDER,
         BUMPLESS_SETPOINT_WEIGHT, TWO_LOOPS_STRUCTURE, PRESET_SETPOINT_STEP, PRESET_ZERO_START, RATE_LIMIT_CLAMPING,
         RATE_LIMIT_BACK_CALCULATION, BUMPLESS_GAIN_STEP, BUMPLESS_SATURATED, BUMPLESS_SIGN_CHANGE,
         BUMPLESS_WITHOUT_INTEGRAL, MANUAL_TO_AUTO, TRACK_TO_AUTO)
