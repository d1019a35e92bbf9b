"""What a robustness-margin estimate says about a controller: verified, failed or impossible (one rule).

A margin estimate (robustness.margins.Margins at one operating point) is

- **failed**: the loop is not deployable there, whatever the limit: it diverged or was held at an actuator
  limit (Ms = inf), the control signal reached a limit under the smallest multisine ("saturated"), or the
  response did not become periodic while the change between periods kept falling ("lightly_damped": a
  linear loop too lightly damped to settle within the experiment) or while its swing grew over the periods
  ("growing": an unstable loop not yet out of its divergence bound);
- **impossible**: the response did not become periodic and the change between periods did not fall
  ("varying"): the plant varies faster than the experiment can measure it, so no margin exists to check.
  The verdict says so, and the choice rests on the closed-loop replays;
- **verified** otherwise: the estimate stands and the controller meets the Ms limit there or not by it. A
  response that bends a little ("distorted") or a loop that drifted while settling ("not_settled") keeps
  its note as a caveat, but its periodic estimate is the loop's linearisation at the point.

Every part of the tool that judges margins asks `status` or `meets_limit` (the fixed-PID search, the
schedule's rows, the deliverable's rule, the verdict).
"""
from __future__ import annotations

import enum
import math


class Robustness(str, enum.Enum):
    """The three states; `.value` is the word the report and metrics.json write."""

    VERIFIED = "verified"
    FAILED = "failed"
    IMPOSSIBLE = "impossible"


def status(margins) -> Robustness:
    """The state of one Margins estimate (module docstring)."""
    if not math.isfinite(margins.Ms) or {"saturated", "lightly_damped", "growing"} & set(margins.problems):
        return Robustness.FAILED
    if "varying" in margins.problems:
        return Robustness.IMPOSSIBLE
    return Robustness.VERIFIED


def meets_limit(margins, limit: float) -> bool:
    """Deployable at this point: verified within the limit, or impossible to measure (not a failure)."""
    state = status(margins)
    return state == Robustness.IMPOSSIBLE or (state == Robustness.VERIFIED and margins.Ms <= limit)


INFINITE_MS = "∞"  # the one word for an infinite Ms (a diverged loop) in tables, verdict and notes


def ms_text(value: float, digits: int = 3) -> str:
    """An Ms as text: INFINITE_MS for +inf, "not verified" for NaN (no estimate counts), else `digits` significant
    digits."""
    if math.isnan(value):
        return "not verified"
    return INFINITE_MS if math.isinf(value) else f"{value:.{digits}g}"


def why(margins, limit: float) -> str:
    """One sentence on the state, for the report."""
    state = status(margins)
    if state == Robustness.VERIFIED:
        text = f"verified: Ms {margins.Ms:.2f} " + ("within" if margins.Ms <= limit else "above") + f" the limit {limit:g}"
        return text + (f" (caveat: {margins.note})" if margins.note else "")
    if state == Robustness.FAILED:
        if not math.isfinite(margins.Ms):
            return ("failed: in the margin measurement the loop diverged or was held at an actuator limit (Ms = "
                    f"{INFINITE_MS}" + (f"; {margins.note}" if margins.note else "") + ")")
        return f"failed: {margins.note}"
    return f"impossible: {margins.note}"
