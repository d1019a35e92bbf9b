"""PID gains in physical units: Kp, Ti [s], Td [s] per loop and the coupling of a coupled PID.

One type, `Gains` (numpy arrays, what results carry); its `values()` is the same gains as `GainValues`, the
plain-list form the loop core steps with every sample and the searches, margins and detuning pass around; `as_dict()`
the form fixed_pid.json and metrics.json record.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


class GainValues(NamedTuple):
    """Gains as float lists: Kp, Ti [s], Td [s] (n_loops,) each, coupling (6,) or None; what LoopCore.step takes. A
    tuple: it unpacks as (Kp, Ti, Td, coupling) and compares and hashes by value."""

    Kp: list
    Ti: list
    Td: list
    coupling: list | None = None

    def as_gains(self) -> "Gains":
        """The same gains as Gains (numpy arrays)."""
        return gains_from_values(*self)


@dataclass(frozen=True)
class Gains:
    """PID parameters for every loop: Kp, Ti (s), Td (s) of shape (n_loops,); coupling (6,) or None."""

    Kp: np.ndarray
    Ti: np.ndarray
    Td: np.ndarray
    coupling: np.ndarray | None = None

    def as_dict(self) -> dict[str, np.ndarray]:
        """{"Kp", "Ti", "Td"[, "coupling"]}: copies of the arrays (fixed_pid.json's "gains")."""
        d = {"Kp": self.Kp.copy(), "Ti": self.Ti.copy(), "Td": self.Td.copy()}
        if self.coupling is not None:
            d["coupling"] = self.coupling.copy()
        return d

    def values(self) -> GainValues:
        """The gains as GainValues (float lists; coupling None when uncoupled): what LoopCore.step takes."""
        return GainValues(self.Kp.tolist(), self.Ti.tolist(), self.Td.tolist(),
                          None if self.coupling is None else self.coupling.tolist())


def gains_from_values(Kp: list, Ti: list, Td: list, coupling: list | None = None) -> Gains:
    """Gains (numpy arrays) from per-loop lists."""
    return Gains(np.array(Kp, float), np.array(Ti, float), np.array(Td, float),
                 None if coupling is None else np.array(coupling, float))


def gains_from_dict(g: dict) -> Gains:
    """Gains from fixed_pid.json's "gains" ({"Kp", "Ti", "Td"[, "coupling"]} lists)."""
    return gains_from_values(g["Kp"], g["Ti"], g["Td"], g.get("coupling"))


def split_values(values: list, n: int, coupled: bool) -> GainValues:
    """A gain map's flat vector [Kp0, Ti0, Td0, Kp1, ..., coupling...] as GainValues."""
    return GainValues(values[0:3 * n:3], values[1:3 * n:3], values[2:3 * n:3], (values[3 * n:] if coupled else None))
