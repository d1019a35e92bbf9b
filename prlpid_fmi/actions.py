"""Map agent actions in [-1, 1] to PID parameters.

Action layout, shape (3 * n_loops [+ 6],): (Kp, Ti, Td) for loop 0, then loop 1, ..., then the six
cross-axis coupling coefficients (c_rp, c_ry, c_pr, c_py, c_yr, c_yp) when the PID is coupled.
A "log" range maps geometrically (equal action steps = equal gain ratios, right for gains that span
decades such as Kp and Ti); a "linear" range maps affinely (needed when the range contains 0 or
negative values, e.g. Td = 0 or a reverse-acting Kp).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import GainRange, LoopConfig

PID_PARAMETERS = ("Kp", "Ti", "Td")


@dataclass(frozen=True)
class Gains:
    """PID parameters for every loop: Kp, Ti (s), Td (s) of shape (n_loops,); coupling (6,) or None."""

    Kp: np.ndarray
    Ti: np.ndarray
    Td: np.ndarray
    coupling: np.ndarray | None = None

    def as_dict(self) -> dict[str, np.ndarray]:
        d = {"Kp": self.Kp.copy(), "Ti": self.Ti.copy(), "Td": self.Td.copy()}
        if self.coupling is not None:
            d["coupling"] = self.coupling.copy()
        return d


def map_range(a: np.ndarray, r: GainRange) -> np.ndarray:
    """Map a in [-1, 1] into r (clipped to the range)."""
    frac = (np.clip(a, -1.0, 1.0) + 1.0) / 2.0
    if r.scale == "log":
        return np.exp(np.log(r.low) + frac * (np.log(r.high) - np.log(r.low)))
    return r.low + frac * (r.high - r.low)


def unmap_range(value: np.ndarray, r: GainRange) -> np.ndarray:
    """Inverse of map_range: the action in [-1, 1] that gives `value`."""
    if r.scale == "log":
        frac = (np.log(value) - np.log(r.low)) / (np.log(r.high) - np.log(r.low))
    else:
        frac = (np.asarray(value) - r.low) / (r.high - r.low)
    return np.clip(2.0 * frac - 1.0, -1.0, 1.0)


class ActionMap:
    """Turns a (smoothed) action vector into Gains for the configured loops."""

    def __init__(self, loops: tuple[LoopConfig, ...], coupled: bool = False, coupling_range: float = 0.5):
        self.loops = loops
        self.coupled = coupled
        self.coupling = GainRange(-coupling_range, coupling_range, "linear")
        self.size = 3 * len(loops) + (6 if coupled else 0)

    def __call__(self, action: np.ndarray) -> Gains:
        n = len(self.loops)
        per_loop = action[: 3 * n].reshape(n, 3)
        kp = np.array([map_range(per_loop[i, 0], l.Kp) for i, l in enumerate(self.loops)])
        ti = np.array([map_range(per_loop[i, 1], l.Ti) for i, l in enumerate(self.loops)])
        td = np.array([map_range(per_loop[i, 2], l.Td) for i, l in enumerate(self.loops)])
        coupling = map_range(action[3 * n:], self.coupling) if self.coupled else None
        return Gains(kp, ti, td, coupling)

    def names(self, loop_names: list[str]) -> list[str]:
        """Column names of the mapped parameters, e.g. Kp[y], Ti[y], Td[y], c_rp, ..."""
        cols = [f"{p}[{name}]" for name in loop_names for p in PID_PARAMETERS]
        if self.coupled:
            cols += ["c_rp", "c_ry", "c_pr", "c_py", "c_yr", "c_yp"]
        return cols
