"""Reward forecast (paper eq. 12-14): roll the prior model N steps ahead with the current gains, through FMI
calls (fmi.py) or one C call (native.py); base.py holds what both share. make_forecast picks one."""
from __future__ import annotations

from prlpid_fmi.control.reward import RewardWeights
from prlpid_fmi.loop.forecast.fmi import FmiForecast


def make_forecast(plant, prior, pid, *, horizon: int, scale, bound, penalty: float, weights: RewardWeights, u_scale,
                  overrides: dict | None = None, state_map: dict | None = None, path: str = "auto"):
    """The reward forecast for this plant and prior.

    path: "auto" = one C call (NativeForecast) when plant and prior are instances of the same FMU file
    loaded once, without a state_map, and its binary exports prlpid_forecast with the ABI this package
    knows (the bundled plants); the FMI path otherwise. "fmi" forces the FMI path (as for a third-party
    FMU); "native" requires the C call (PlantError when it is not available).
    Both paths compute the reward from `weights` and `u_scale` with control.reward, so that they agree
    bit for bit. Other arguments: see Forecast and FmiForecast.
    """
    if path not in ("auto", "fmi", "native"):
        raise ValueError(f"forecast path must be 'auto', 'fmi' or 'native', got {path!r}")
    args = (plant, prior, pid, horizon, scale, bound, penalty, weights, u_scale, overrides)
    if path != "fmi":
        from prlpid_fmi.loop.forecast.native import NativeForecast, native_unavailable

        reason = "a state_map re-initialises the prior" if state_map else native_unavailable(plant, prior)
        if reason is None:
            return NativeForecast(*args)
        if path == "native":
            from prlpid_fmi.errors import PlantError

            raise PlantError(f"{prior.path.name}: the one-call forecast is not available: {reason}")
    return FmiForecast(*args, state_map=state_map)
