"""A plant's measured frequency response at one operating point, and what any PID would achieve on it.

The closed-loop experiment of robustness.identification measures P(e^{j w Ts}) on the FMU with some
stabilising PID in the loop; around an operating point where the plant is linear, P does not depend on
that PID. So the sensitivity peak and the noise gain of *another* PID C follow from P alone, without a
new experiment (Astrom & Hagglund's loop-shaping view of PID design):

- Ms(C) = max_w |1 / (1 + C P)| over a fine grid: log|P| and the unwrapped phase of P interpolated
  linearly in log w between the measured frequencies (INTERPOLATED_POINTS points);
- noise gain(C) = std(u) / std(n) for white measurement noise n on every sample, u = -C S n:
  sqrt((1/pi) * integral_0^pi |C S(e^{j theta})|^2 d theta), theta = w Ts, by the trapezoid rule on that
  grid (below the lowest measured frequency |C S| is taken as flat at its lowest value);
- increment noise gain(C) = std(u_k - u_{k-1}) / std(n): the same integral weighted by |1 - e^{-j theta}|^2 =
  2 - 2 cos theta (what the chatter metric counts: sample-to-sample moves of u, which a derivative on noise makes
  large while std(u) stays small).

- stability: a bounded |S| on the unit circle does not make the loop stable (a huge gain keeps |S| small
  and still destabilises a sampled loop). By Nyquist, the closed loop of C is stable when 1 + C P winds around
  0 as often as it does for a PID known to stabilise the plant (the one the response was measured with): the
  open-loop unstable poles are the plant's, the same for both. `winding` gives the phase change to compare.

Both hold for the feedback part of the PID (robustness.margins.pid_frequency_response); the setpoint
weights b, c do not enter. They are estimates for the search: a deployed controller's margins are measured
with that controller in the loop (robustness.margins.loop_margins).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INTERPOLATED_POINTS = 600  # log-spaced frequencies of the interpolated grid
RELIABLE_SENSITIVITY = 0.1  # |S| of the measuring loop from which a frequency's estimate has full weight in a fit


@dataclass(frozen=True, eq=False)
class MeasuredPlant:
    """P at one operating point: frequencies_rad_s (K,) ascending, response (K,) complex; sample_time_s [s];
    point: the setpoints per loop; control_signal: u there per loop (from the experiment's settling);
    own_response (K,) complex: with several coupled loops, the loop's own measurement over its input (y_i / u_i,
    robustness.margins.Margins.own_response), else None; sensitivity (K,): |S| = |1 / (1 + C P)| of the loop the
    response was measured in, None where not known (`reliability`)."""

    frequencies_rad_s: np.ndarray
    response: np.ndarray
    sample_time_s: float
    point: tuple
    control_signal: tuple
    own_response: np.ndarray | None = None
    sensitivity: np.ndarray | None = None

    def own(self) -> "MeasuredPlant":
        """The loop's own measurement's response y_i / u_i as a MeasuredPlant (this one where it is the same)."""
        if self.own_response is None:
            return self
        return MeasuredPlant(self.frequencies_rad_s, self.own_response, self.sample_time_s, self.point,
                             self.control_signal, sensitivity=self.sensitivity)

    def reliability(self) -> np.ndarray:
        """(K,) in (0, 1]: min(1, |S| / RELIABLE_SENSITIVITY), the weight of each frequency's estimate in a fit (all 1
        without `sensitivity`). In the closed loop the plant input at a frequency is the multisine times S, so where
        the loop gain is high (|S| small) the estimate is a ratio of small signals whose relative error (transients,
        the nonlinear part) grows as 1 / |S|: two_tank's at |S| 0.004-0.02 missed by 13-76 %, where |S| > 0.05 by
        under 1 %."""
        if self.sensitivity is None:
            return np.ones(len(self.frequencies_rad_s))
        return np.clip(np.asarray(self.sensitivity, float) / RELIABLE_SENSITIVITY, np.finfo(float).tiny, 1.0)

    def grid(self) -> tuple[np.ndarray, np.ndarray]:
        """(w, P) on the interpolated grid: INTERPOLATED_POINTS log-spaced frequencies from the lowest to the
        highest measured one, plus the measured ones (computed once)."""
        cached = self.__dict__.get("_grid")
        if cached is None:
            cached = self._interpolated()
            object.__setattr__(self, "_grid", cached)
        return cached

    def _interpolated(self) -> tuple[np.ndarray, np.ndarray]:
        w0, P0 = self.frequencies_rad_s, self.response
        w = np.union1d(np.geomspace(w0[0], w0[-1], INTERPOLATED_POINTS), w0)
        logw = np.log(w0)
        mag = np.interp(np.log(w), logw, np.log(np.maximum(np.abs(P0), np.finfo(float).tiny)))  # |P| = 0: ZOH zeros
        phase = np.interp(np.log(w), logw, np.unwrap(np.angle(P0)))
        return w, np.exp(mag + 1j * phase)

    def sensitivity_peak(self, controller) -> float:
        """Ms of the PID whose feedback response is controller(w) (w [rad/s] -> complex array)."""
        w, P = self.grid()
        return float(np.max(np.abs(1.0 / (1.0 + controller(w) * P))))

    def noise_gain(self, controller, increments: bool = False) -> float:
        """std(u) / std(n) for white measurement noise on every sample; increments: std(u_k - u_{k-1}) / std(n)
        (module docstring)."""
        return self.noise_gains(controller)[1 if increments else 0]

    def noise_gains(self, controller) -> tuple[float, float]:
        """(std(u), std(u_k - u_{k-1})) / std(n) from one evaluation of the controller on the grid (`noise_scan` with
        K = 1)."""
        noise, increments = self.noise_scan(np.ones(1), controller)
        return float(noise[0]), float(increments[0])

    def winding(self, controller) -> float:
        """The phase change [rad] of 1 + C P from the lowest grid frequency to Nyquist (unwrapped): twice it over
        2 pi is the Nyquist encirclement count, up to the arc at w = 0 that PIDs with the same integrator share."""
        w, P = self.grid()
        return float(np.diff(np.unwrap(np.angle(1.0 + controller(w) * P))[[0, -1]])[0])

    def ms_forbidden(self, shape, limit: float) -> np.ndarray:
        """The open intervals of K > 0, shape (n, 2), where the PID K * shape(w) has |1 + C P| < 1/limit at some grid
        frequency (Ms > limit there; `scan`'s Ms on the same grid): per frequency the roots of the quadratic
        |g|^2 K^2 + 2 Re(g) K + 1 - 1/limit^2 = 0, g = shape(w) P(w), where both are positive. limit > 1; shape: a
        function of w or its values on `grid`'s frequencies."""
        w, P = self.grid()
        g = (shape(w) if callable(shape) else shape) * P
        a, b, c = g.real ** 2 + g.imag ** 2, 2.0 * g.real, 1.0 - 1.0 / limit ** 2
        disc = b * b - 4.0 * a * c
        m = (a > 0) & (b < 0) & (disc > 0)  # real roots, both positive (product c/a > 0, sum -b/a > 0)
        q = 0.5 * (np.sqrt(disc[m]) - b[m])  # the larger root times a, without cancellation
        return np.column_stack([c / q, q / a[m]])

    def scan(self, gains: np.ndarray, shape) -> tuple[np.ndarray, np.ndarray]:
        """(Ms, winding) of the PIDs K * shape(w) for every K in `gains` (m,) at once: shape(w) is the feedback response
        of the PID with Kp = 1 (Kp scales C as a whole). Arrays of shape (m,). shape: a function of w or its values on
        `grid`'s frequencies."""
        w, P = self.grid()
        G = shape(w) if callable(shape) else shape
        R = 1.0 + np.asarray(gains, float)[:, None] * (G * P)[None, :]  # 1 + C P, (m, K)
        with np.errstate(divide="ignore"):
            ms = 1.0 / np.sqrt(np.min(R.real ** 2 + R.imag ** 2, axis=1))
        # the unwrapped phase change: the sum of the phase steps between neighbouring frequencies, each in (-pi, pi]
        return ms, np.sum(np.angle(R[:, 1:] * np.conj(R[:, :-1])), axis=1)

    def noise_scan(self, gains: np.ndarray, shape) -> tuple[np.ndarray, np.ndarray]:
        """(noise gain, increment noise gain) of the PIDs K * shape(w) for every K in `gains` (m,) (`scan`'s
        arguments): std(u) / std(n) and std(u_k - u_{k-1}) / std(n), arrays (m,)."""
        w, P = self.grid()
        G = shape(w) if callable(shape) else shape
        K = np.asarray(gains, float)[:, None]
        cs2, theta = np.abs(K * G[None, :] / (1.0 + K * (G * P)[None, :])) ** 2, w * self.sample_time_s
        return _noise_gains(cs2, theta, False), _noise_gains(cs2, theta, True)



def _noise_gains(cs2: np.ndarray, theta: np.ndarray, increments: bool) -> np.ndarray:
    """sqrt((1/pi) integral_0^pi |C S|^2 (x (2 - 2 cos theta) for increments) d theta) per row of cs2 (m, K), by the
    trapezoid rule on theta (K,) [rad/sample]; |C S| flat below the grid and from its end to Nyquist."""
    weight = 2.0 - 2.0 * np.cos(theta) if increments else np.ones_like(theta)
    f = cs2 * weight[None, :]
    integral = (cs2[:, 0] * (theta[0] - np.sin(theta[0])) * 2.0 if increments else f[:, 0] * theta[0]) \
        + np.sum(0.5 * (f[:, 1:] + f[:, :-1]) * np.diff(theta)[None, :], axis=1)
    if theta[-1] < np.pi:  # the grid stops short of Nyquist: |C S| flat from there
        tail = (np.pi - theta[-1]) if not increments else 2.0 * (np.pi - theta[-1]) + 2.0 * np.sin(theta[-1])
        integral = integral + cs2[:, -1] * tail
    return np.sqrt(integral / np.pi)
