"""Action smoothing (paper eq. 19-21) of the agent's raw actions, vectors of shape (n_params,).

Every smoother is called once per control step with the newest raw action a_t and returns a new
array, the smoothed action; ``reset()`` forgets the history (call it at the start of an episode).

- "none": a copy of the raw action.
- "sma"  (eq. 19): mean of the last M raw actions. The paper defines it for t >= M only; before
  that (fewer than M actions since reset) the mean of the actions seen so far is used.
- "lwma" (eq. 20): w_k = alpha + (1 - alpha)*(k + 1)/M, k = 0..M-1, normalised by sum(w).
  Eq. 20 as printed multiplies a_{t-k} (the action k steps ago) by w_k, which grows with k: the
  OLDEST action would get the largest weight. That contradicts the method's name and calling
  alpha a "weight-decay factor" (weights should decay with age). We implement the conventional
  form: the newest action gets the largest weight, a_{t-k} is weighted by w_{M-1-k}
  = alpha + (1 - alpha)*(M - k)/M (newest 1, oldest alpha + (1 - alpha)/M). Before M actions have
  been seen, the available actions keep these weights, renormalised over the ones present.
- "era"  (eq. 21): a_0 = raw_0, a_t = alpha*raw_t + (1 - alpha)*a_{t-1} (an exponential average).

Defaults (the only place they live): window M = DEFAULT_WINDOW = 5; alpha = DEFAULT_ALPHA[method]
(LWMA 0.2, ERA 0.3, both from the paper section 4.3). Valid alpha: LWMA 0 <= alpha <= 1
(1 = SMA), ERA 0 < alpha <= 1 (1 = no smoothing). "none" and "sma" take no alpha; "none" and
"era" ignore the window.
"""
from __future__ import annotations

import numpy as np

SMOOTHING_METHODS = ("none", "sma", "lwma", "era")
DEFAULT_WINDOW = 5
DEFAULT_ALPHA = {"lwma": 0.2, "era": 0.3}


class NoSmoothing:
    """Returns a copy of the raw action."""

    def __init__(self, n_params: int):
        self.n_params = n_params

    def reset(self) -> None:
        pass

    def __call__(self, raw_action) -> np.ndarray:
        return _checked(raw_action, self.n_params).copy()

    def values(self, raw: list) -> list:
        return list(raw)


class _WindowAverage:
    """Weighted average over the last ``window`` raw actions, ring buffer of shape (window, n_params).

    ``newest_first_weights[k]`` weights the action k steps ago. Row j of the weight tables gives the
    normalised weight of every buffer slot when the newest action sits in slot j: ``_filling`` while
    fewer than ``window`` actions have been seen since reset (slot i holds action i), ``_full`` after.
    """

    def __init__(self, n_params: int, window: int, newest_first_weights: np.ndarray):
        self.n_params = n_params
        self.window = window
        w = np.asarray(newest_first_weights, dtype=float)
        slots = np.arange(window)
        age = (slots[:, None] - slots[None, :]) % window  # age[j, s]: age of slot s when newest is j
        self._full = w[age] / w.sum()
        filling = np.where(slots[None, :] <= slots[:, None], w[age], 0.0)
        self._filling = filling / filling.sum(axis=1, keepdims=True)
        self._full_rows, self._filling_rows = self._full.tolist(), self._filling.tolist()
        self._buffer = [[0.0] * n_params for _ in range(window)]
        self.reset()

    def reset(self) -> None:
        for row in self._buffer:
            row[:] = [0.0] * self.n_params
        self._newest = -1
        self._weights = self._filling_rows

    def __call__(self, raw_action) -> np.ndarray:
        return np.array(self.values(_checked(raw_action, self.n_params).tolist()))

    def values(self, raw: list) -> list:
        """The smoothed action for the newest raw action (list of n_params floats)."""
        j = self._newest + 1
        if j == self.window:
            j = 0
            self._weights = self._full_rows
        self._newest = j
        self._buffer[j] = list(raw)
        weights, buffer = self._weights[j], self._buffer
        return [sum([w * row[p] for w, row in zip(weights, buffer)]) for p in range(self.n_params)]


class SimpleMovingAverage(_WindowAverage):
    """Eq. 19: mean of the last ``window`` raw actions (of all seen, while fewer than ``window``)."""

    def __init__(self, n_params: int, window: int = DEFAULT_WINDOW):
        super().__init__(n_params, window, np.ones(window))


class LinearlyWeightedMovingAverage(_WindowAverage):
    """Eq. 20, newest action weighted most: weight of the action k steps ago is alpha + (1-alpha)(M-k)/M."""

    def __init__(self, n_params: int, window: int = DEFAULT_WINDOW, alpha: float = DEFAULT_ALPHA["lwma"]):
        k = np.arange(window)
        eq20_w = alpha + (1.0 - alpha) * (k + 1) / window  # w_k of eq. 20
        super().__init__(n_params, window, eq20_w[::-1])
        self.alpha = alpha


class ExponentialRecursiveAverage:
    """Eq. 21: a_0 = raw_0, a_t = alpha*raw_t + (1 - alpha)*a_{t-1}."""

    def __init__(self, n_params: int, alpha: float = DEFAULT_ALPHA["era"]):
        self.n_params = n_params
        self.alpha = alpha
        self._smoothed = [0.0] * n_params
        self.reset()

    def reset(self) -> None:
        self._started = False

    def __call__(self, raw_action) -> np.ndarray:
        return np.array(self.values(_checked(raw_action, self.n_params).tolist()))

    def values(self, raw: list) -> list:
        """The smoothed action for the newest raw action (list of n_params floats)."""
        if self._started:
            a, b = self.alpha, 1.0 - self.alpha
            self._smoothed = [a * r + b * s for r, s in zip(raw, self._smoothed)]
        else:
            self._smoothed = list(raw)
            self._started = True
        return list(self._smoothed)


def _checked(raw_action, n_params: int) -> np.ndarray:
    raw = np.asarray(raw_action, dtype=float)
    if raw.shape != (n_params,):
        raise ValueError(f"raw action must have shape ({n_params},), got {raw.shape}")
    return raw


def make_smoother(method: str, *, n_params: int, window: int = DEFAULT_WINDOW, alpha: float | None = None):
    """Build the smoother for ``method`` in SMOOTHING_METHODS; alpha None = DEFAULT_ALPHA[method].

    Raises ValueError for an unknown method, window not an integer >= 1 (sma, lwma), an alpha out of
    range or given to a method without one ("none", "sma"), or n_params not an integer >= 1.
    """
    if method not in SMOOTHING_METHODS:
        raise ValueError(f"smoothing method must be one of {SMOOTHING_METHODS}, got {method!r}")
    if isinstance(n_params, bool) or not isinstance(n_params, (int, np.integer)) or n_params < 1:
        raise ValueError(f"n_params must be an integer >= 1, got {n_params!r}")
    if method in ("sma", "lwma") and (
            isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1):
        raise ValueError(f"smoothing window must be an integer >= 1 for {method!r}, got {window!r}")
    if alpha is not None and method not in DEFAULT_ALPHA:
        raise ValueError(f"smoothing method {method!r} takes no alpha, got alpha={alpha!r}")
    if alpha is None and method in DEFAULT_ALPHA:
        alpha = DEFAULT_ALPHA[method]
    if method == "lwma" and not 0.0 <= alpha <= 1.0:
        raise ValueError(f"lwma alpha must be in [0, 1], got {alpha!r}")
    if method == "era" and not 0.0 < alpha <= 1.0:
        raise ValueError(f"era alpha must be in (0, 1], got {alpha!r}")

    n_params = int(n_params)
    if method == "none":
        return NoSmoothing(n_params)
    if method == "sma":
        return SimpleMovingAverage(n_params, int(window))
    if method == "lwma":
        return LinearlyWeightedMovingAverage(n_params, int(window), float(alpha))
    return ExponentialRecursiveAverage(n_params, float(alpha))
