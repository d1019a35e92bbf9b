"""Map agent actions in [-1, 1] to PID parameters: the absolute map (paper) and the anchored map (default).

Action layout, shape (3 * n_loops [+ 6],): (Kp, Ti, Td) for loop 0, then loop 1, ..., then the six
cross-axis coupling coefficients (c_rp, c_ry, c_pr, c_py, c_yr, c_yp) when the PID is coupled.
A "log" range maps geometrically (equal action steps = equal gain ratios, right for gains that span
decades such as Kp and Ti); a "linear" range maps affinely (needed when the range contains 0 or
negative values, e.g. Td = 0 or a reverse-acting Kp).

Anchored map (AnchoredActionMap, the default once a fixed PID is tuned): action 0 gives exactly the
anchor gains (the tuned fixed PID); a in [-1, 1] moves each gain within a band around it and the
result is clipped into the loop's gain range::

    Kp = Kp0 * f_Kp**a      Ti = Ti0 * f_Ti**a      (multiplicative bands, factors >= 1)
    Td = Td0 + a * b_Td * (Td.high - Td.low)         (additive, a fraction of the Td range)
    c  = c0 + a * b_c                                (additive, coupling coefficients)

Scheduled anchor (ScheduledActionMap, the default where `tune` builds a classical gain schedule): the same
bands around the schedule's gains at the current value z of its scheduling variable (GainSchedule.gains_at,
the function every replay and export of the table runs), so action 0 gives the classical schedule bit for bit;
a gain is clipped into [min(low, g0(z)), max(high, g0(z))] so that an anchor outside the loop's range is kept.

`values(action list) -> (Kp, Ti, Td, coupling)` lists is the per-step path; `__call__` returns Gains.
"""
from __future__ import annotations

import math

import numpy as np

from prlpid_fmi.config import GainRange, LoopConfig
from prlpid_fmi.loop.gains import Gains, gains_from_values, split_values

PID_PARAMETERS = ("Kp", "Ti", "Td")


class ActionMap:
    """Turns a (smoothed) action vector into Gains for the configured loops."""

    def __init__(self, loops: tuple[LoopConfig, ...], coupled: bool = False, coupling_range: float = 0.5,
                 zero_coupling: bool = False):
        """zero_coupling: a coupled PID whose six coefficients are held at 0, not in the action (size 3 * n_loops)."""
        self.loops = loops
        self.coupled = coupled
        self.coupling = GainRange(-coupling_range, coupling_range, "linear")
        self.zero_coupling = coupled and zero_coupling
        tuned = 6 if coupled and not self.zero_coupling else 0
        self.size = 3 * len(loops) + tuned

        ranges = [r for l in loops for r in (l.Kp, l.Ti, l.Td)] + [self.coupling] * tuned
        # per parameter: (is_log, low or log(low), span or log span, low, high)
        self._maps = [(r.scale == "log",) + ((math.log(r.low), math.log(r.high) - math.log(r.low))
                                             if r.scale == "log" else (r.low, r.high - r.low)) + (r.low, r.high)
                      for r in ranges]

    def __call__(self, action) -> Gains:
        return gains_from_values(*self.values(np.asarray(action, dtype=float).tolist()))

    def values(self, action: list) -> tuple[list, list, list, list | None]:
        """Action (size floats, clipped to [-1, 1]) -> Kp, Ti, Td lists (n_loops,), coupling list (6,) or None."""
        out = []
        for a, (is_log, base, span, low, high) in zip(action, self._maps):
            a = -1.0 if a < -1.0 else 1.0 if a > 1.0 else a
            frac = (a + 1.0) / 2.0
            out.append(math.exp(base + frac * span) if is_log else base + frac * span)
        if self.zero_coupling:
            out += [0.0] * 6
        return split_values(out, len(self.loops), self.coupled)

    def names(self, loop_names: list[str]) -> list[str]:
        """Column names of the mapped parameters, e.g. Kp[y], Ti[y], Td[y], c_rp, ..."""
        cols = [f"{p}[{name}]" for name in loop_names for p in PID_PARAMETERS]
        if self.coupled and not self.zero_coupling:
            cols += ["c_rp", "c_ry", "c_pr", "c_py", "c_yr", "c_yp"]
        return cols


class AnchoredActionMap(ActionMap):
    """Action 0 -> exactly the anchor gains; each gain moves within a band around them (see module docstring).

    Args:
        loops, coupled, coupling_range: as ActionMap (the gain ranges the result is clipped into).
        anchor: the tuned fixed PID's Gains (inside the ranges).
        bands: object with Kp, Ti (factors >= 1), Td (fraction of the Td range), coupling (additive).
    """

    def __init__(self, loops: tuple[LoopConfig, ...], anchor: Gains, bands, coupled: bool = False,
                 coupling_range: float = 0.5):
        super().__init__(loops, coupled, coupling_range)
        self.anchor = anchor
        anchor_values = [float(x) for i in range(len(loops))
                         for x in (anchor.Kp[i], anchor.Ti[i], anchor.Td[i])]
        anchor_values += [float(x) for x in anchor.coupling] if coupled else []
        ranges = [r for l in loops for r in (l.Kp, l.Ti, l.Td)] + [self.coupling] * (6 if coupled else 0)
        kinds = ["Kp", "Ti", "Td"] * len(loops) + ["coupling"] * (6 if coupled else 0)
        self._anchored = []
        for value, r, kind in zip(anchor_values, ranges, kinds):
            if kind in ("Kp", "Ti"):   # multiplicative: value * exp(a * log(f))
                self._anchored.append((True, value, math.log(getattr(bands, kind)), r.low, r.high))
            elif kind == "Td":
                self._anchored.append((False, value, bands.Td * (r.high - r.low), r.low, r.high))
            else:
                self._anchored.append((False, value, bands.coupling, r.low, r.high))

    def values(self, action: list) -> tuple[list, list, list, list | None]:
        out = []
        for a, (multiplicative, value, band, low, high) in zip(action, self._anchored):
            a = -1.0 if a < -1.0 else 1.0 if a > 1.0 else a
            g = value * math.exp(a * band) if multiplicative else value + a * band
            out.append(low if g < low else high if g > high else g)
        return split_values(out, len(self.loops), self.coupled)


class ScheduledActionMap(AnchoredActionMap):
    """Action 0 -> exactly a gain table's gains at the scheduling value z; the bands of AnchoredActionMap around them.

    Args:
        loops, bands, coupled, coupling_range: as AnchoredActionMap.
        schedule: the anchor table (tuning.schedule.table.GainSchedule: breakpoints, Kp, Ti, Td, its variable).
    `values_at(action, z)` is the per-step path (z read before the step, as a replay of the table reads it);
    `values(action)` looks the table up at its first breakpoint.
    """

    def __init__(self, loops: tuple[LoopConfig, ...], schedule, bands, coupled: bool = False,
                 coupling_range: float = 0.5):
        self.schedule = schedule
        super().__init__(loops, schedule.gains_object(float(schedule.breakpoints[0])), bands, coupled, coupling_range)
        self._z, self._anchor = None, None  # the last lookup: a setpoint changes at its steps only

    def values(self, action: list) -> tuple[list, list, list, list | None]:
        return self.values_at(action, float(self.schedule.breakpoints[0]))

    def values_at(self, action: list, z: float) -> tuple[list, list, list, list | None]:
        """Action (size floats) at scheduling value z -> Kp, Ti, Td lists (n_loops,), coupling (6,) or None."""
        if z != self._z:
            g = self.schedule.gains_at(z)
            anchor = [float(x) for i in range(len(self.loops)) for x in (g[0][i], g[1][i], g[2][i])]
            self._z, self._anchor = z, anchor + ([float(x) for x in g[3]] if self.coupled else [])
        anchor = self._anchor
        out = []
        for a, value, (multiplicative, _, band, low, high) in zip(action, anchor, self._anchored):
            a = -1.0 if a < -1.0 else 1.0 if a > 1.0 else a
            v = value * math.exp(a * band) if multiplicative else value + a * band
            low, high = min(low, value), max(high, value)
            out.append(low if v < low else high if v > high else v)
        return split_values(out, len(self.loops), self.coupled)
