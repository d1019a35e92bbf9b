"""The fixed PID's searches: the load search (Kp, Ti, Td, Tf under the Ms and noise limits), the setpoint weight b,
and the setpoint search within a load limit. tuning.design_rule orders them; tuning.load_experiment is the cost.

1. The load search (`LoadDesign`): feedback gains Kp, Ti, Td (and the measurement filter Tf, when tuned and the
   scenario has measurement noise) minimise J_load (tuning.load_experiment) by differential evolution inside the
   scenario's gain ranges widened by baseline.widen_ranges (log ranges [low/f, high*f], Td's high end * f), then a
   Nelder-Mead polish, subject to, at every point, Ms <= deploy.max_sensitivity, a stable closed loop and std(u)
   from the scenario's measurement noise <= deploy.max_noise_gain x the control span, std(u_k - u_{k-1}) from it
   <= deploy.max_noise_increment x the span, all from the plant's frequency response measured at that point
   (robustness.plant_response; measured once, with a stabilising PID; stability by Nyquist: the same winding as
   that PID's). Every candidate meets them by construction: Ti, Td (Tf) are searched, and Kp as a position inside
   the interval of Kp that meets the limits for them (`LoadDesign.kp_interval`, a scan: Kp scales C as a whole, so
   Ms <= limit is a quadratic inequality in Kp per frequency, solved once per Ti, Td, Tf). A loop whose u reverses
   on more than MAX_CHATTER of the load experiment's samples (a saturating limit cycle, which the linear Ms cannot
   see) has its cost raised (CHATTER_PENALTY). With training.randomize set, the limits hold on the Monte-Carlo
   parameter draws too. A point without a verified estimate (robustness.status) gives no constraint; the Ms check
   on the FMU (tuning.fixed_pid.detune_over) covers it. Where no Kp meets the noise-increment limit with Ms for the
   stabilising PID's Ti, Td and any filter, the limit is dropped (`relax_increment_limit`).
   With baseline.design_model "identified", the search scores its candidates on local models instead
   (`identify_models`: robustness.local_model fitted to each loop's response measured at each point; the load
   response per unit load by lfilter, with several loops by robustness.loop_models' closed loop on the loops' models,
   whose Ms with the candidate's other loops closed is then a limit too (`models_ms`); the fixed PID's decoupled loops
   searched one at a time, `search_loops`; the chatter of the PID output's response): microseconds of numpy instead
   of an FMU simulation. The choice is verified on the FMU (`validate_models`) and the search reruns on the FMU
   (`use_fmu`) where the two differ by more than MODEL_TOLERANCE (`search_verified`). The setpoint search's load cost
   follows the same path (`search_load_cost`; tuning.design_rule verifies its result on the FMU too).
2. b (`setpoint_weight`): on noise-free training episodes (setpoint steps), the b in B_GRID with the lowest ISE
   among those with overshoot <= deploy.max_overshoot. b changes neither Ms nor the load response.
3. The setpoint search (`SetpointDesign`): (Kp, Ti, Td[, Tf], b) minimise the setpoint ISE of those episodes
   subject to the limits of 1, J_load <= a load limit (baseline.load_tolerance x the load optimum, or none) and
   overshoot <= deploy.max_overshoot; with on_models, the setpoint ISE and overshoot of a unit step on the local
   models instead of the episodes on the FMU (`LoadDesign.model_setpoint_response`), and the load cost on the models.
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import math

import numpy as np
from scipy.optimize import NonlinearConstraint, OptimizeResult, differential_evolution, minimize

from prlpid_fmi.config import GainRange, TuningConfig
from prlpid_fmi.control.pid import coupling_matrix
from prlpid_fmi.loop.actions import ActionMap
from prlpid_fmi.loop.core import LoopCore, control_scales, pid_structure
from prlpid_fmi.loop.evaluation import gains_rollout
from prlpid_fmi.loop.gains import GainValues
from prlpid_fmi.metrics import chatter_fraction
from prlpid_fmi.progress import QUIET, Steps, batch_counted, counted
from prlpid_fmi.robustness.local_model import (closed_loop_stable, feedback_polynomials, identify, load_responses,
                                              reference_polynomial)
from prlpid_fmi.robustness.local_model import setpoint_response as model_step_response
from prlpid_fmi.robustness.loop_models import closed_loop as loop_closed_loop
from prlpid_fmi.robustness.loop_models import loop_plants
from prlpid_fmi.robustness.loop_models import stable as loop_stable
from prlpid_fmi.robustness.loop_models import step_responses
from prlpid_fmi.robustness.margins import pid_frequency_response, setpoint_range_points
from prlpid_fmi.tuning.design_result import ModelPath
from prlpid_fmi.tuning.load_experiment import (DIVERGED_COST, load_config, load_iae, open_core, parameter_samples,
                                               plant_responses, signed_loads, start_measurement)
from prlpid_fmi.tuning.search_pool import SearchPool, search_fmus, search_workers

B_GRID = tuple(i / 20 for i in range(21))  # setpoint weights tried
MODEL_GENERATIONS = 2  # a search on the local models runs this many x baseline.maxiter generations, ...
STABILITY_KEPT = 100_000  # LoadDesign._stable's answers kept at most (then forgotten)
POLYNOMIALS_KEPT = 4096  # LoadDesign._feedback's polynomials kept at most (then forgotten)
MODEL_MIN_GENERATIONS, MODEL_MIN_POPSIZE = 20, 10  # ... and popsize, at least these (a model candidate costs ~0.1 ms)
SETPOINT_MODEL_MINIMUM = (30, 15)  # the setpoint search on the models at least (its 5 parameters, no Kp-interval scans)
TF_RANGE = (0.1, 100.0)  # measurement filter search range [sample times], log
FILTER_PROBES = 13  # Tf values over TF_RANGE the noise-increment relaxation test tries (relax_increment_limit)
INIT_SPREAD = 0.15  # std of SetpointDesign's initial population around its start [search coordinates]
POLISH_EVALUATIONS = 60  # Nelder-Mead evaluations per searched parameter after differential evolution, at most ...
POLISH_PER_GENERATION = 3  # ... and at most this many per parameter and DE generation (a token search, a token polish)
MAX_CHATTER = 0.05  # fraction of samples where u may reverse in the load experiment (metrics.chatter_fraction)
ACTIVE_TOLERANCE = 0.01  # an estimate this close (relative) to its limit holds the design (LoadDesign.active_limits)
CHATTER_PENALTY = 10.0  # the load cost grows by this x the chatter above MAX_CHATTER (relative to it)
KP_SCAN = 48  # |Kp| values scanned for the interval that meets the limits
KP_REFINE = 24  # |Kp| values on the finer grid at each end of that interval
STABILITY_CHECKS = 5  # |Kp| values along an interval that meets the Ms limit, checked for stability
MODEL_FIT_LIMIT = 0.05  # RMS relative misfit of a local model to its measured response above which it is not used
MODEL_TOLERANCE = 0.10  # |FMU - model| / FMU load cost of the search's result above which the search reruns on the FMU


def penalised(load: float, chatter: float) -> float:
    """The load cost of a J_load and a worst chatter: J_load x (1 + CHATTER_PENALTY x the chatter above MAX_CHATTER,
    relative to it)."""
    return load * (1.0 + CHATTER_PENALTY * max(0.0, chatter - MAX_CHATTER) / MAX_CHATTER)


def columns(population) -> np.ndarray:
    """The vectors of a population in scipy's vectorized form, (n, S) or one vector (n,): an (S, n) array."""
    population = np.asarray(population, float)
    return population[None, :] if population.ndim == 1 else population.T


def polish_evaluations(maxiter: int) -> int:
    """Nelder-Mead evaluations per searched parameter after a DE of maxiter generations: POLISH_PER_GENERATION x
    (maxiter + 1), at most POLISH_EVALUATIONS (reached at the default 20 generations, so the polish costs at most 3 /
    popsize of the DE's evaluations; a short search does not spend most of its evaluations polishing)."""
    return min(POLISH_EVALUATIONS, POLISH_PER_GENERATION * (int(maxiter) + 1))


def widened(config: TuningConfig, factor: float) -> TuningConfig:
    """config with every loop's log gain ranges widened to [low/f, high*f] and Td's high end to high*f."""
    def wider(r: GainRange, name: str) -> GainRange:
        if r.scale == "log":
            return GainRange(r.low / factor, r.high * factor, "log")
        if name == "Td":
            return GainRange(r.low, r.low + (r.high - r.low) * factor, r.scale)
        return r
    loops = tuple(dataclasses.replace(l, Kp=wider(l.Kp, "Kp"), Ti=wider(l.Ti, "Ti"), Td=wider(l.Td, "Td"))
                  for l in config.loops)
    return dataclasses.replace(config, loops=loops)


def search_map(config: TuningConfig, search_config: TuningConfig | None = None) -> ActionMap:
    """The fixed-PID searches' map of [-1, 1]^n onto Kp, Ti, Td per loop over search_config's ranges (config's). A
    coupled PID's six coefficients are held at 0: constant coefficients leave r - y = -C y wherever the other loops'
    outputs are not 0 (eq. 27's integral drives the coupled error to 0), so no fixed coupled PID settles every
    setpoint; the agent sets them sample by sample around 0."""
    loops = (search_config or config).loops
    return ActionMap(loops, config.coupled, config.coupling_range, zero_coupling=True)


class OutcomeCache:
    """What a search evaluates, once per vector: `outcome(vector)` is `new_outcome(vector)` (the subclass's), kept for
    the objective, the constraints and the polish, which ask again; `evaluate_new(population, pool)` computes the
    population's new vectors on a tuning.search_pool.SearchPool (their workers run `new_outcome`)."""

    _seen: dict

    def outcome(self, vector):
        key = tuple(float(v) for v in vector)
        if key not in self._seen:
            self._remember(key, self.new_outcome(vector))
        return self._seen[key]

    def _remember(self, key: tuple, value) -> None:
        self._seen[key] = value
        if len(self._seen) > 4096:
            self._seen.pop(next(iter(self._seen)))

    def evaluate_new(self, population, pool: SearchPool) -> list[np.ndarray]:
        """The vectors of population (scipy's vectorized form, `columns`), those not seen before evaluated on `pool`."""
        vectors = list(columns(population))
        keys = [tuple(float(x) for x in v) for v in vectors]
        new = list({k: v for k, v in zip(keys, vectors) if k not in self._seen}.items())
        for (key, _), value in zip(new, pool.map("new_outcome", [v for _, v in new])):
            self._remember(key, value)
        return vectors


@functools.lru_cache(maxsize=64)
def _kp_grid(lo: float, hi: float) -> np.ndarray:
    """KP_SCAN log-spaced |Kp| in [lo, hi] (read-only: shared by every scan of a loop's range)."""
    grid = np.geomspace(lo, hi, KP_SCAN)
    grid.flags.writeable = False
    return grid


def _scanned_interval(ok, sign: float, lo: float, hi: float):
    """LoadDesign.kp_interval by a scan: KP_SCAN log-spaced |Kp| in [lo, hi] through ok (|Kp| (m,) -> passes (m,)),
    the passing run with the largest |Kp|, its ends refined on a finer grid (KP_REFINE); None when none passes."""
    grid = _kp_grid(lo, hi)
    good = ok(grid)
    if not good.any():
        return None
    j_hi = int(np.flatnonzero(good)[-1])
    j_lo = j_hi
    while j_lo > 0 and good[j_lo - 1]:
        j_lo -= 1
    low, high = grid[j_lo], grid[j_hi]
    if j_lo > 0:  # the edges once more, on a finer grid between the last failing and first passing |Kp|
        fine = np.geomspace(grid[j_lo - 1], grid[j_lo], KP_REFINE)
        low = fine[int(np.argmax(ok(fine)))]
    if j_hi + 1 < KP_SCAN:
        fine = np.geomspace(grid[j_hi], grid[j_hi + 1], KP_REFINE)
        passing = np.flatnonzero(ok(fine))
        high = fine[int(passing[-1])] if passing.size else grid[j_hi]
    return sign, float(low), float(max(high, low))


def _exact_ok(plants, shapes: list[np.ndarray], sign: float, lo: float, hi: float, limit: float):
    """Without measurement noise, `ok` of LoadDesign.kp_interval from the exact |Kp| intervals in [lo, hi] where Ms <=
    limit at every plant response on its grid (MeasuredPlant.ms_forbidden), each checked once for stability at
    STABILITY_CHECKS |Kp| along it (Nyquist against the reference winding: constant along such an interval, as the
    curve crosses -1 only where Ms is infinite): |Kp| (m,) -> passes (m,). None where the grid's winding still
    varies along one (then the scan decides). shapes: the PID with Kp = 1 on each plant response's grid."""
    forbidden = np.concatenate([plant.ms_forbidden(sign * g, limit) for (plant, _), g in zip(plants, shapes)])
    forbidden = forbidden[(forbidden[:, 1] > lo) & (forbidden[:, 0] < hi)]
    forbidden = forbidden[np.argsort(forbidden[:, 0])]
    ends = np.maximum.accumulate(forbidden[:, 1]) if len(forbidden) else forbidden[:, 1]
    starts = np.concatenate([[lo], np.maximum(ends, lo)])      # an allowed piece starts where the covered run ends
    stops = np.concatenate([np.minimum(forbidden[:, 0], hi), [hi]])   # and stops where the next interval starts
    pieces = stops >= starts
    starts, stops = starts[pieces], stops[pieces]
    if not len(starts):
        return lambda mags: np.zeros(len(mags), bool)
    # every piece's checks at once: one scan per plant response
    k = sign * np.geomspace(starts, stops, STABILITY_CHECKS, axis=1).ravel()  # the pieces' checks, piece after piece
    stable = np.all([np.abs(plant.scan(k, g)[1] - reference) < 0.5 * math.pi
                     for (plant, reference), g in zip(plants, shapes)], axis=0).reshape(len(starts), STABILITY_CHECKS)
    if np.any(stable.any(axis=1) & ~stable.all(axis=1)):
        return None
    kept = stable.all(axis=1)
    if not kept.any():
        return lambda mags: np.zeros(len(mags), bool)
    low, high = starts[kept], stops[kept]
    return lambda mags: np.any((mags[:, None] >= low[None, :]) & (mags[:, None] <= high[None, :]), axis=1)


class LoadDesign(OutcomeCache):
    """The load cost, its constraints and the setpoint-weight choice for one tuning problem (module docstring).

    Args: config (the scenario's tuning problem, forecast off), load_step (fraction of the control span),
    max_sensitivity, max_noise_gain and max_noise_increment (fractions of the span), widen (factor on the gain
    ranges). Tf is searched
    (`tune_filter`) when controller.measurement_filter is "tuned" and the scenario has measurement noise. Call
    `prepare(gains)` with a stabilising PID first; `close()` at the end.
    """

    def __init__(self, config: TuningConfig, load_step: float, max_sensitivity: float | None, max_noise_gain: float,
                 widen: float, max_noise_increment: float = math.inf, workers: int = 1, design_model: str = "fmu"):
        self.config = dataclasses.replace(config, forecast_horizon=0)
        self.design_model = design_model  # "identified": the search's load cost on local models (`identify_models`)
        self.models: list | None = None  # per nominal point: a LocalModel per loop, while the search uses them
        self.loop_models: list | None = None  # the same with several loops, kept for their Ms (`models_ms`)
        self.model_note = ""  # why the local models are not used ("" where they are or were not asked for)
        self.workers = int(workers)  # processes `search` evaluates on (tuning.search_pool)
        self.args = (config, load_step, max_sensitivity, max_noise_gain, widen, max_noise_increment)
        self.load_step = float(load_step)
        self.limit = max_sensitivity
        self.max_noise = float(max_noise_gain)
        self.max_increment = float(max_noise_increment)
        self.increment_relaxed = False  # set by prepare: the increment limit dropped (relax_increment_limit)
        self.points = setpoint_range_points(self.config)
        self.search_config = widened(self.config, widen)
        self.gain_map = search_map(config, self.search_config)
        self.b, self.c, self.tf = pid_structure(self.config)
        self.tune_filter = config.measurement_filter == "tuned" and config.measurement_noise_std > 0
        self.n = self.gain_map.size + (config.n_loops if self.tune_filter else 0)
        self.spans = control_scales(self.config)
        self.cores: list[LoopCore] = []  # per point: the load experiment ...
        self.quiet_cores: list[LoopCore] = []  # ... and the same without the load (load_iae's reference)
        self.plants: list = []
        self._seen: dict = {}
        self._intervals: dict = {}
        self._stability: dict = {}  # `_stable`'s answers (keyed by the model's id: the models live as long)
        self._polynomials: dict = {}  # `_feedback`'s (Nc, Dc) per (Kp, Ti, Td, Tf)
        self.reference: list = []
        self.loads: list = []  # per point: the load per loop [input units]
        self.start: list | None = None  # the FMU start state's measurement per loop

    # -- the structure a vector stands for -------------------------------------------------------------------
    def gains(self, vector) -> GainValues:
        """The GainValues of a search vector. Ti, Td (a coupling: 0, search_map) map like the absolute gain map over
        the widened ranges; each loop's Kp entry is a position in [-1, 1] within the Kp interval where that loop
        meets the Ms and noise limits for its Ti, Td, Tf (`kp_interval`, log-spaced), so every candidate with an
        interval meets them by construction. Without one, Kp maps over the whole widened range."""
        head = list(vector)[:self.gain_map.size]
        Kp, Ti, Td, coupling = self.gain_map.values(head)
        tf = self.filters(vector)
        for i in range(self.config.n_loops):
            found = self.kp_interval(i, Ti[i], Td[i], tf[i])
            if found is not None:
                sign, lo, hi = found
                frac = (min(max(float(head[3 * i]), -1.0), 1.0) + 1.0) / 2.0
                Kp[i] = sign * lo * (hi / lo) ** frac
        return GainValues(Kp, Ti, Td, coupling)

    def feasible(self, vector) -> bool:
        """Every loop has a Kp interval for the vector's Ti, Td, Tf (no measured response: always)."""
        Kp, Ti, Td, _ = self.gain_map.values(list(vector)[:self.gain_map.size])
        tf = self.filters(vector)
        return all(self.kp_interval(i, Ti[i], Td[i], tf[i]) is not None for i in range(self.config.n_loops))

    def kp_interval(self, loop: int, Ti: float, Td: float, tf: float):
        """(sign, |Kp| low, |Kp| high) of the Kp range where loop `loop` meets Ms <= limit and the noise bound at every
        point, for these Ti, Td, Tf: a scan of KP_SCAN log-spaced |Kp| over the widened range, the feasible run with
        the largest |Kp|, its ends refined on a finer grid (`_scanned_interval`); each |Kp| checked against the exact
        Ms intervals without measurement noise (`_exact_ok`), else by robustness.plant_response.MeasuredPlant.scan
        (Nyquist stability included), and the noise bounds (MeasuredPlant.noise_scan) where those hold; None when no
        Kp meets them. The whole range where nothing was measured."""
        r = self.search_config.loops[loop].Kp
        sign = -1.0 if r.high <= 0 else 1.0
        lo, hi = (abs(r.high), abs(r.low)) if sign < 0 else (r.low if r.low > 0 else r.high * 1e-3, r.high)
        plants = [(p[loop], ref[loop]) for p, ref in zip(self.plants, self.reference) if p is not None]
        if not plants or (self.limit is None and not self.config.measurement_noise_std > 0):
            return sign, lo, hi
        key = (loop, Ti, Td, tf)
        if key in self._intervals:
            return self._intervals[key]
        c = self.config
        shape = lambda w: pid_frequency_response(1.0, Ti, Td, c.sample_time_s, w, c.derivative_filter_N, tf,  # noqa: E731
                                                 c.measurement_filter_order)
        limit = self.limit if self.limit is not None else math.inf
        sigma = c.measurement_noise_std

        shapes = [shape(plant.grid()[0]) for plant, _ in plants]  # the PID with Kp = 1 on each response's grid

        def ok(mags: np.ndarray) -> np.ndarray:
            good = np.ones(len(mags), bool)
            for (plant, reference), g in zip(plants, shapes):
                ms, winding = plant.scan(sign * mags, g)
                good &= (ms <= limit) & (np.abs(winding - reference) < 0.5 * math.pi)  # stable: Nyquist
            if sigma > 0 and good.any():  # the noise bounds where Ms and stability hold
                kept = np.flatnonzero(good)
                for (plant, _), g in zip(plants, shapes):
                    noise, increments = plant.noise_scan(sign * mags[kept], g)
                    good[kept] &= (sigma * noise / self.spans[loop] <= self.max_noise) & \
                        (sigma * increments / self.spans[loop] <= self.max_increment)
            return good

        exact = _exact_ok(plants, shapes, sign, lo, hi, limit) if sigma == 0 and 1.0 < limit < math.inf else None
        found = _scanned_interval(exact or ok, sign, lo, hi)
        if len(self._intervals) > 65536:
            self._intervals.clear()
        self._intervals[key] = found
        return found

    def filters(self, vector) -> list[float]:
        """Tf per loop [s] of a search vector (the fixed ones when Tf is not searched)."""
        if not self.tune_filter:
            return list(self.tf)
        lo, hi = (math.log(x * self.config.sample_time_s) for x in TF_RANGE)
        tail = list(vector)[self.gain_map.size:]
        return [math.exp(lo + (min(max(a, -1.0), 1.0) + 1.0) / 2.0 * (hi - lo)) for a in tail]

    def controller(self, gains: GainValues, tf: list[float], loop: int):
        """w -> C(e^{j w Ts}) of loop `loop` (feedback part)."""
        c = self.config
        Kp, Ti, Td, _ = gains
        return lambda w: pid_frequency_response(Kp[loop], Ti[loop], Td[loop], c.sample_time_s, w,
                                                c.derivative_filter_N, tf[loop], c.measurement_filter_order)

    # -- constraints -------------------------------------------------------------------------------------------
    def constraint_values(self, vector) -> np.ndarray:
        """[max Ms - limit, max noise share - max_noise_gain, max increment share - max_noise_increment] over points
        and loops (<= 0: feasible); with several loops' local models, Ms also with the candidate's other loops closed
        (`models_ms`)."""
        gains, tf = self.gains(vector), self.filters(vector)
        ms, noise, increment = self.limit_values(gains, tf)
        limit = self.limit if self.limit is not None else math.inf
        if self.loop_models is not None and self.limit is not None:
            ms = max(ms, min(self.models_ms(gains, tf), DIVERGED_COST))  # unstable on the models: inf
        extra = increment - self.max_increment if math.isfinite(self.max_increment) else -1.0
        return np.array([ms - limit, noise - self.max_noise, extra])

    def meets_noise_limits(self, gains: GainValues, tf: list[float]) -> bool:
        """std(u) and std(u_k - u_(k-1)) from the measurement noise within their limits at every point and loop."""
        _, noise, increment = self.limit_values(gains, tf)
        return noise <= self.max_noise and (increment <= self.max_increment or not math.isfinite(self.max_increment))

    def limit_values(self, gains: GainValues, tf: list[float]) -> tuple[float, float, float]:
        """(max Ms, max std(u) share, max std(u_k - u_(k-1)) share) of the measurement noise over the points and loops
        with a measured response (shares of the loop's control span; 0 without noise)."""
        ms, noise, increment = 0.0, 0.0, 0.0
        sigma = self.config.measurement_noise_std
        for plants in self.plants:
            if plants is None:
                continue
            for i, plant in enumerate(plants):
                C = self.controller(gains, tf, i)
                ms = max(ms, plant.sensitivity_peak(C))
                if sigma > 0:
                    std_u, std_du = plant.noise_gains(C)
                    noise = max(noise, sigma * std_u / self.spans[i])
                    increment = max(increment, sigma * std_du / self.spans[i])
        return ms, noise, increment

    def estimates(self, gains: GainValues, tf: list[float]) -> list[dict]:
        """Per point: {"point", "Ms", "noise_gain"} estimated from the measured plant responses (None: none)."""
        out = []
        for p, plants in zip(self.points, self.plants):  # the nominal plant's points (the samples' follow them)
            if plants is None:
                out.append({"point": p, "Ms": None, "noise_gain": None})
                continue
            Cs = [self.controller(gains, tf, i) for i in range(len(plants))]
            out.append({"point": p, "Ms": max(pl.sensitivity_peak(C) for pl, C in zip(plants, Cs)),
                        "noise_gain": max(pl.noise_gain(C) for pl, C in zip(plants, Cs))})
        return out

    def active_limits(self, gains: GainValues, tf: list[float]) -> list[dict]:
        """The limits that hold the design: per nominal operating point and loop, the Ms and noise estimates (as
        constraint_values computes them) within ACTIVE_TOLERANCE (relative) of their limits. Each {"limit":
        "max_sensitivity" | "max_noise_gain" | "max_noise_increment", "point", "loop" (index), "value", "bound"};
        noise values are std(u) or std(u_k - u_{k-1}) from the measurement noise as a fraction of the loop's span."""
        out, sigma = [], self.config.measurement_noise_std
        for p, plants in zip(self.points, self.plants):  # the nominal plant's points come first
            for i, plant in enumerate(plants or ()):
                C = self.controller(gains, tf, i)
                values = [("max_sensitivity", plant.sensitivity_peak(C), self.limit)]
                if sigma > 0:
                    std_u, std_du = plant.noise_gains(C)
                    values += [("max_noise_gain", sigma * std_u / self.spans[i], self.max_noise),
                               ("max_noise_increment", sigma * std_du / self.spans[i], self.max_increment)]
                out += [{"limit": name, "point": list(p), "loop": i, "value": float(v), "bound": float(bound)}
                        for name, v, bound in values
                        if bound is not None and math.isfinite(bound) and v >= (1.0 - ACTIVE_TOLERANCE) * bound]
        return out

    # -- the load cost -----------------------------------------------------------------------------------------
    def prepare(self, gains: GainValues, measured: dict | None = None) -> None:
        """Measure the plant responses with `gains` in the loop (or take them from another design's `measured()`
        with the same gains) and open one load-experiment core per point, the load signed away from the actuator
        limit nearer to u at the point (as `gains` hold it)."""
        if measured is not None:
            self.plants, self.reference = measured["plants"], measured["reference"]
        else:
            self.plants = plant_responses(self.config, gains, self.points)
            for sample in parameter_samples(self.config):  # the Monte-Carlo plants constrain Kp too (not `estimates`)
                self.plants += plant_responses(sample, gains, self.points)
            # the windings of the PID that was measured stable there, the reference of every candidate's (kp_interval)
            self.reference = [None if plants is None else
                              [pl.winding(self.controller(gains, list(self.tf), i)) for i, pl in enumerate(plants)]
                              for plants in self.plants]
        self.relax_increment_limit(gains)
        self.start = start = start_measurement(self.config)
        for p in self.points:  # per point: the unloaded run (kept open: every candidate's reference) and the loaded
            quiet = load_config(self.config, p, [0.0] * self.config.n_loops, start)
            core = open_core(quiet)
            self.quiet_cores.append(core)
            probe = gains_rollout(lambda c: gains, quiet, seed=0, core=core)
            self.loads.append(signed_loads(self.config, probe, self.load_step))
            self.cores.append(open_core(load_config(self.config, p, self.loads[-1], start)))
        self.identify_models()

    def measured(self) -> dict:
        """The plant responses `prepare` measured and their reference windings (picklable), for another design's
        `prepare` with the same stabilising PID."""
        return {"plants": self.plants, "reference": self.reference}

    def prepared(self) -> dict:
        """What `prepare` measured and decided (picklable): a replica (`replica`) evaluates exactly as this design."""
        return {"plants": self.plants, "reference": self.reference, "max_increment": self.max_increment,
                "increment_relaxed": self.increment_relaxed, "loads": self.loads, "start": self.start,
                "models": self.models, "loop_models": self.loop_models, "model_note": self.model_note}

    @classmethod
    def replica(cls, args: tuple, prepared: dict) -> "LoadDesign":
        """A design built with the constructor's `args` and a prepared design's `prepared()`, its cores open (a search
        worker's copy: tuning.search_pool)."""
        design = cls(*args)
        for name, value in prepared.items():
            setattr(design, name, value)
        for p, loads in zip(design.points, design.loads):
            design.quiet_cores.append(open_core(load_config(design.config, p, [0.0] * design.config.n_loops,
                                                              design.start)))
            design.cores.append(open_core(load_config(design.config, p, loads, design.start)))
        return design

    def pool_workers(self) -> int:
        """Processes a search on this design may use (tuning.search_pool.search_workers of self.workers and its cores)."""
        return search_workers(self.workers, self.cores)

    def filter_candidates(self, loop: int) -> list[float]:
        """Tf [s] of loop `loop` the relaxation test tries: the fixed one, or (Tf searched) the untuned one and
        FILTER_PROBES log-spaced values over TF_RANGE."""
        if not self.tune_filter:
            return [self.tf[loop]]
        ts = self.config.sample_time_s
        return [self.tf[loop]] + [float(x) for x in np.geomspace(TF_RANGE[0] * ts, TF_RANGE[1] * ts, FILTER_PROBES)]

    def relax_increment_limit(self, gains: GainValues) -> None:
        """The noise-increment limit is a preference, Ms the requirement: where no Kp meets both for the stabilising
        PID's Ti, Td on some loop with any measurement filter the search may choose (`filter_candidates`), but one
        meets Ms and std(u) alone, the limit is dropped for this design and `increment_relaxed` says so. (The
        exothermic reactor: Ms <= 2 takes Kp >= 3 K/K there, and with its stabilising PI no first-order filter from
        0.1 to 100 s brings the 0.1 K noise's sample-to-sample move of the jacket under 0.5 % of its span (0.53 % at
        best, measured): the limit is dropped.)"""
        self.increment_relaxed = False
        if not (self.config.measurement_noise_std > 0 and math.isfinite(self.max_increment)):
            return
        Kp, Ti, Td, _ = gains
        blocked = [i for i in range(self.config.n_loops)
                   if all(self.kp_interval(i, Ti[i], Td[i], tf) is None for tf in self.filter_candidates(i))]
        if not blocked:
            return
        limit, self.max_increment = self.max_increment, math.inf
        self._intervals.clear()
        if all(self.kp_interval(i, Ti[i], Td[i], self.tf[i]) is not None for i in blocked):
            self.increment_relaxed = True
        else:
            self.max_increment = limit
        self._intervals.clear()

    def load_response(self, gains: GainValues, tf: list[float]) -> tuple[float, float]:
        """(J_load, worst chatter) of constant gains with measurement filter tf: the load cost of the module
        docstring and the largest fraction of samples from the first load on where a loop's u reverses
        (metrics.chatter_fraction)."""
        total, chatter = 0.0, 0.0
        for core, quiet in zip(self.cores, self.quiet_cores):
            core.set_structure(self.b, self.c, tf)
            quiet.set_structure(self.b, self.c, tf)
            traj = gains_rollout(lambda c: gains, core.config, seed=0, core=core)
            unloaded = gains_rollout(lambda c: gains, quiet.config, seed=0, core=quiet)
            total += load_iae(traj, core.config, unloaded)
            if not traj.terminated:  # from the first load on: the approach's setpoint ramp is not the loop's doing
                first = self.config.setpoint_hold_steps
                chatter = max(chatter, max(chatter_fraction(traj.pid_output[first:, i], self.spans[i])
                                           for i in range(self.config.n_loops)))
        return total / max(len(self.cores), 1), chatter

    def load_cost(self, gains: GainValues, tf: list[float]) -> float:
        """J_load (module docstring) of constant gains with measurement filter tf."""
        return self.load_response(gains, tf)[0]

    def search_load_cost(self, gains: GainValues, tf: list[float]) -> float:
        """J_load as the searches see it: on the local models while they are used, else on the FMU (load_cost)."""
        return self.model_load_response(gains, tf)[0] if self.models is not None else self.load_cost(gains, tf)

    def new_outcome(self, vector) -> tuple[float, float] | None:
        """load_response of a vector (model_load_response while `models` are used), None when a loop has no Kp
        interval for it or, with several loops' models, its Ms on them exceeds the limit (`models_ms`; not
        simulated); `outcome` keeps it."""
        if not self.feasible(vector):
            return None
        if self.loop_models is not None and self.limit is not None and \
                self.models_ms(self.gains(vector), self.filters(vector)) > self.limit:
            return None
        if self.models is not None:
            return self.model_load_response(self.gains(vector), self.filters(vector))
        return self.load_response(self.gains(vector), self.filters(vector))

    # -- the load cost on local models -------------------------------------------------------------------------
    def identify_models(self) -> None:
        """With design_model "identified": per nominal operating point, a LocalModel (robustness.local_model.identify)
        per loop from its own measurement's measured response (MeasuredPlant.own), used by the search (`models`), or
        the reason they cannot be (`model_note`): a point without a verified response, a fit worse than
        MODEL_FIT_LIMIT."""
        self.models, self.loop_models, self.model_note = None, None, ""
        self._stability.clear()
        if self.design_model != "identified":
            return
        models = []
        for p, plants in zip(self.points, self.plants):
            if plants is None:
                self.model_note = f"no verified frequency response at the operating point {list(p)}"
                return
            fitted = tuple(identify(plant.own()) for plant in plants)  # y_i / u_i: diag(P), not the coupled error's
            for i, model in enumerate(fitted):
                if not model.fit_error <= MODEL_FIT_LIMIT:
                    where = f"the local model at {list(p)}" + (f" of loop {i + 1}" if len(fitted) > 1 else "")
                    self.model_note = (f"{where} misses the measured response by {100 * model.fit_error:.1f} % RMS "
                                       f"(limit {100 * MODEL_FIT_LIMIT:.0f} %)")
                    return
            models.append(fitted)
        self.models = models
        if self.config.n_loops > 1 or self.config.coupled:
            self.loop_models = models

    def model_records(self) -> list[dict]:
        """The local models as fixed_pid.json records: LocalModel.as_dict per point (and "loop", 0-based, with
        several loops)."""
        if self.models is None:
            return []
        if self.config.n_loops == 1:
            return [loops[0].as_dict() for loops in self.models]
        return [{**model.as_dict(), "loop": i} for loops in self.models for i, model in enumerate(loops)]

    def model_load_response(self, gains: GainValues, tf: list[float]) -> tuple[float, float]:
        """(J_load, worst chatter) as load_response defines them, on the local models: one loop, the load response
        of robustness.local_model.load_responses over the load experiment's samples after the load, per unit load;
        several loops (or the coupled PID), the closed loop of robustness.loop_models on diag(the loops' models)
        with the experiment's loads one loop after another by superposition. Chatter of the PID outputs' responses
        to the point's loads. A closed loop unstable on a model: DIVERGED_COST."""
        c = self.config
        if c.n_loops > 1 or c.coupled:
            return self._loops_load_response(gains, tf)
        Nc, Dc = self._feedback(gains, tf, 0)
        total, chatter = 0.0, 0.0
        for (model,), loads in zip(self.models, self.loads):
            if not self._stable(model, Nc, Dc):
                return DIVERGED_COST, 0.0
            dy, du = load_responses(model, Nc, Dc, c.setpoint_hold_steps)
            iae = float(np.sum(np.abs(dy)) * c.sample_time_s)
            total += iae
            chatter = max(chatter, chatter_fraction(abs(loads[0]) * du, self.spans[0]))
        return total / len(self.models), chatter

    def _decoupled(self, gains: GainValues) -> bool:
        """No coupling between the loops' PIDs (uncoupled, or every coefficient 0: the fixed PID's, search_map): on
        diag(the models) each loop is then closed on its own model alone."""
        _, _, _, coupling = gains
        return not self.config.coupled or not any(coupling)

    def _loops_load_response(self, gains: GainValues, tf: list[float]) -> tuple[float, float]:
        """model_load_response with several loops: loop i loaded with loads[i] from hold * i samples after the first
        load (tuning.load_experiment.load_config), J_load = Ts sum_k sum_i |y_i,k| / |d_i| / n. Decoupled PIDs: each
        loop's own closed loop (robustness.local_model.load_responses), the same sums."""
        c = self.config
        n, hold = c.n_loops, c.setpoint_hold_steps
        total, chatter = 0.0, 0.0
        decoupled = self._decoupled(gains)
        for models, loads in zip(self.models, self.loads):
            u = np.zeros((n * hold, n))
            if decoupled:
                iae = 0.0
                for i in range(n):
                    dy, du = self._loop_response(models[i], loads[i], i, gains, tf)
                    if dy is None:
                        return DIVERGED_COST, 0.0
                    iae += float(np.sum(np.abs(dy)))
                    u[:, i] = du
                total += iae * c.sample_time_s / n
            else:
                A, B, Y, U = loop_closed_loop(list(models), *self._loop_args(gains, tf))
                if not loop_stable(A):
                    return DIVERGED_COST, 0.0
                dy, du = step_responses(A, B, Y, U, n * hold)
                y = np.zeros((n * hold, n))
                for i, load in enumerate(loads):
                    y[i * hold:] += load * dy[:(n - i) * hold, :, i]
                    u[i * hold:] += load * du[:(n - i) * hold, :, i]
                total += float(np.sum(np.abs(y) / np.abs(np.asarray(loads))[None, :]) * c.sample_time_s) / n
            chatter = max(chatter, max(chatter_fraction(u[:, i], self.spans[i]) for i in range(n)))
        return total / len(self.models), chatter

    def _loop_response(self, model, load: float, loop: int, gains: GainValues, tf: list[float]):
        """Decoupled loop `loop` of the several-loop load experiment on its own model: (dy (steps,) per unit load from
        its load on, the PID output over the whole experiment (n * hold,) [input units], 0 before that load), or
        (None, None) where the closed loop is unstable on the model."""
        c = self.config
        n, hold = c.n_loops, c.setpoint_hold_steps
        Nc, Dc = self._feedback(gains, tf, loop)
        if not self._stable(model, Nc, Dc):
            return None, None
        dy, du = load_responses(model, Nc, Dc, (n - loop) * hold)
        u = np.zeros(n * hold)
        u[loop * hold:] = load * du
        return dy, u

    def loop_load_response(self, loop: int, gains: GainValues, tf: list[float]) -> tuple[float, float]:
        """Loop `loop`'s share of the several-loop J_load on the models with decoupled PIDs, and its chatter
        (model_load_response's J_load is the sum of these over the loops, its chatter their largest)."""
        c = self.config
        total, chatter = 0.0, 0.0
        for models, loads in zip(self.models, self.loads):
            dy, u = self._loop_response(models[loop], loads[loop], loop, gains, tf)
            if dy is None:
                return DIVERGED_COST, 0.0
            total += float(np.sum(np.abs(dy))) * c.sample_time_s / c.n_loops
            chatter = max(chatter, chatter_fraction(u, self.spans[loop]))
        return total / len(self.models), chatter

    def _stable(self, model, Nc: np.ndarray, Dc: np.ndarray) -> bool:
        """robustness.local_model.closed_loop_stable, kept per model and PID (a candidate's load cost, Ms and setpoint
        step each ask for every loop and point)."""
        key = (id(model), Nc.tobytes(), Dc.tobytes())
        found = self._stability.get(key)
        if found is None:
            if len(self._stability) > STABILITY_KEPT:
                self._stability.clear()
            found = self._stability[key] = closed_loop_stable(model, Nc, Dc)
        return found

    def _feedback(self, gains: GainValues, tf: list[float], loop: int) -> tuple[np.ndarray, np.ndarray]:
        """(Nc, Dc) of loop `loop`'s PID (robustness.local_model.feedback_polynomials), kept per PID (a candidate asks
        for them at every point; read-only arrays)."""
        c = self.config
        Kp, Ti, Td, _ = gains
        key = (Kp[loop], Ti[loop], Td[loop], tf[loop])
        found = self._polynomials.get(key)
        if found is None:
            if len(self._polynomials) > POLYNOMIALS_KEPT:
                self._polynomials.clear()
            found = feedback_polynomials(*key[:3], c.sample_time_s, c.derivative_filter_N, key[3],
                                         c.measurement_filter_order)
            for a in found:
                a.flags.writeable = False
            self._polynomials[key] = found
        return found

    def _loop_args(self, gains: GainValues, tf: list[float]) -> tuple:
        """The arguments after the models of robustness.loop_models.closed_loop and loop_plants for these gains."""
        c = self.config
        Kp, Ti, Td, coupling = gains
        matrix = coupling_matrix(coupling) if c.coupled else None
        return Kp, Ti, Td, c.sample_time_s, c.derivative_filter_N, tf, c.measurement_filter_order, matrix

    def _loops_ms(self, models: tuple, plants: list, gains: GainValues, tf: list[float]) -> float:
        """The largest Ms over the loops at one point on the models: each loop's effective plant with the candidate's
        other loops closed (robustness.loop_models.loop_plants) and its own PID, at the frequencies measured for that
        loop there."""
        worst = 0.0
        for i, plant in enumerate(plants):
            w = plant.frequencies_rad_s
            P = loop_plants(list(models), *self._loop_args(gains, tf), w)[i]
            worst = max(worst, float(np.max(np.abs(1.0 / (1.0 + self.controller(gains, tf, i)(w) * P)))))
        return worst

    def _loop_ms(self, model, plant, gains: GainValues, tf: list[float], loop: int) -> float:
        """Ms of decoupled loop `loop` on its own model at the frequencies measured for it (plant); inf where the
        closed loop is unstable on the model."""
        if not self._stable(model, *self._feedback(gains, tf, loop)):
            return math.inf
        w = plant.frequencies_rad_s
        return float(np.max(np.abs(1.0 / (1.0 + self.controller(gains, tf, loop)(w) * model.response(w)))))

    def loop_models_ms(self, loop: int, gains: GainValues, tf: list[float]) -> float:
        """`_loop_ms` of loop `loop` over the nominal points (decoupled PIDs: models_ms is the largest over loops)."""
        return max(self._loop_ms(models[loop], plants[loop], gains, tf, loop)
                   for models, plants in zip(self.loop_models, self.plants))

    def models_ms(self, gains: GainValues, tf: list[float]) -> float:
        """The largest Ms on the local models over the nominal points and loops, each loop with the candidate's
        other loops closed (`_loops_ms`); inf where the closed loop is unstable on a model."""
        worst = 0.0
        decoupled = self._decoupled(gains)
        for models, plants in zip(self.loop_models, self.plants):
            if decoupled:  # each loop on its own model: P_i itself is its effective plant
                for i in range(len(models)):
                    worst = max(worst, self._loop_ms(models[i], plants[i], gains, tf, i))
                continue
            if not loop_stable(loop_closed_loop(list(models), *self._loop_args(gains, tf))[0]):
                return math.inf
            worst = max(worst, self._loops_ms(models, plants, gains, tf))
        return worst

    def model_setpoint_response(self, gains: GainValues, tf: list[float], b: float) -> tuple[float, float]:
        """(ISE, worst overshoot [% of the step]) of a unit setpoint step on the local models (setpoint weights b and
        the config's c), over training.setpoint_hold_steps samples: ISE = Ts sum_k (1 - y_k)^2, the mean over the
        models (and loops: with several decoupled PIDs each loop's step on its own model, the others at rest,
        `loop_setpoint_response`); (inf, inf) where a loop is unstable on one. Coupled PIDs (none a fixed-PID search
        tries: search_map) raise ValueError: their setpoint path is not modelled."""
        if not self._decoupled(gains):
            raise ValueError("setpoint responses on the local models need decoupled PIDs (coupling 0)")
        ise, overshoot = 0.0, 0.0
        for i in range(self.config.n_loops):
            loop_ise, loop_overshoot = self.loop_setpoint_response(i, gains, tf, b)
            if not math.isfinite(loop_ise):
                return math.inf, math.inf
            ise, overshoot = ise + loop_ise, max(overshoot, loop_overshoot)
        return ise / self.config.n_loops, overshoot

    def loop_setpoint_response(self, loop: int, gains: GainValues, tf: list[float], b: float) -> tuple[float, float]:
        """(ISE mean over the models, worst overshoot [%]) of loop `loop`'s unit setpoint step on its own models
        (model_setpoint_response for one decoupled loop); (inf, inf) where it is unstable on one."""
        c = self.config
        Kp, Ti, Td, _ = gains
        Nc, Dc = self._feedback(gains, tf, loop)
        Nr = reference_polynomial(Kp[loop], Ti[loop], Td[loop], c.sample_time_s, b, self.c[loop],
                                  c.derivative_filter_N, tf[loop], c.measurement_filter_order)
        ise, overshoot = 0.0, 0.0
        for models in self.models:
            if not self._stable(models[loop], Nc, Dc):
                return math.inf, math.inf
            y = model_step_response(models[loop], Nc, Dc, Nr, c.setpoint_hold_steps)
            ise += float(np.sum((1.0 - y) ** 2) * c.sample_time_s)
            overshoot = max(overshoot, 100.0 * max(0.0, float(np.max(y)) - 1.0))
        return ise / len(self.models), overshoot

    def validate_models(self, vector, record: ModelPath) -> ModelPath:
        """record with the search's result on the FMU against its prediction on the local models: predicted_load_cost,
        fmu_load_cost, fmu_chatter, validation_error (|FMU - model| / FMU), tolerance, agrees (the error at most
        MODEL_TOLERANCE and the FMU's chatter at most MAX_CHATTER)."""
        gains, tf = self.gains(vector), self.filters(vector)
        predicted, _ = self.model_load_response(gains, tf)
        measured, chatter = self.load_response(gains, tf)
        error = abs(measured - predicted) / measured if measured > 0 else math.inf
        return dataclasses.replace(
            record, predicted_load_cost=float(predicted), fmu_load_cost=float(measured), fmu_chatter=float(chatter),
            validation_error=float(error), tolerance=MODEL_TOLERANCE,
            agrees=bool(error <= MODEL_TOLERANCE and chatter <= MAX_CHATTER and measured < DIVERGED_COST))

    def use_fmu(self) -> None:
        """The search's load cost on the FMU from here on (the local models dropped, their outcomes forgotten; several
        loops' models still bound Ms: `loop_models`)."""
        self.models = None
        self._seen.clear()

    def cost(self, vector) -> float:
        """The load cost of a vector: DIVERGED_COST when a loop has no Kp interval (not simulated); J_load x
        (1 + CHATTER_PENALTY x the chatter above MAX_CHATTER, relative) otherwise: a saturating limit cycle,
        which the linear Ms cannot see, chatters."""
        found = self.outcome(vector)
        return DIVERGED_COST if found is None else penalised(*found)

    def costs(self, population: np.ndarray, pool: SearchPool) -> np.ndarray:
        """`cost` of every column of population (n, S) (scipy's vectorized form), the new ones evaluated on `pool`."""
        return np.array([self.cost(v) for v in self.evaluate_new(population, pool)])

    def budget(self, maxiter: int, popsize: int) -> int:
        """The most cost evaluations `search` makes: DE's (maxiter + 1) * popsize * n, then the polish's."""
        return (maxiter + 1) * popsize * self.n + polish_evaluations(maxiter) * self.n

    def search(self, seed: int, maxiter: int, popsize: int, progress: Steps = QUIET):
        """Differential evolution of `cost`, then a Nelder-Mead polish from its result (polish_evaluations(maxiter)
        per parameter at most); scipy's OptimizeResult of the better. Each generation is evaluated as a whole
        (deferred updating) on `pool_workers()` processes (tuning.search_pool): the same result for any number.
        progress: counts every cost evaluation. Several loops on the local models: `search_loops`."""
        if self.models is not None and self.config.n_loops > 1:
            return self.search_loops(seed, maxiter, popsize, progress)
        # the local models in this process (microseconds a candidate), the FMU on the search pool
        with (contextlib.nullcontext() if self.models is not None else
              SearchPool(self, LoadDesign.replica, (self.args, self.prepared()), self.pool_workers(),
                         fmus=search_fmus(self.config))) as pool:
            costs = batch_counted((lambda x: np.array([self.cost(v) for v in columns(x)])) if pool is None else
                                  (lambda x: self.costs(x, pool)), progress)
            result = differential_evolution(costs, [(-1.0, 1.0)] * self.n, maxiter=maxiter, popsize=popsize,
                                            seed=seed, polish=False, tol=1e-6, vectorized=True, updating="deferred")
        result.nfev = costs.calls  # scipy counts a vectorized call as one
        if result.fun < DIVERGED_COST:
            cost = counted(self.cost, progress, start=costs.calls)
            polished = minimize(cost, result.x, method="Nelder-Mead", bounds=[(-1.0, 1.0)] * self.n,
                                options={"maxfev": polish_evaluations(maxiter) * self.n, "xatol": 1e-4,
                                         "fatol": 1e-7})
            if polished.fun < result.fun:
                result.x, result.fun = polished.x, float(polished.fun)
            result.nfev += int(polished.nfev)
        return result

    def loop_indices(self, loop: int) -> list[int]:
        """The entries of a search vector that loop `loop`'s PID depends on: its Kp, Ti, Td (and Tf when tuned)."""
        return [3 * loop, 3 * loop + 1, 3 * loop + 2] + ([self.gain_map.size + loop] if self.tune_filter else [])

    def loop_cost(self, loop: int, vector) -> float:
        """Loop `loop`'s share of `cost` on the local models with decoupled PIDs (vector: a whole search vector; only
        loop_indices(loop) matter): DIVERGED_COST where the loop has no Kp interval or its Ms on its models exceeds
        the limit, else penalised(loop_load_response)."""
        gains, tf = self.gains(vector), self.filters(vector)
        if self.kp_interval(loop, gains.Ti[loop], gains.Td[loop], tf[loop]) is None:
            return DIVERGED_COST
        if self.limit is not None and self.loop_models_ms(loop, gains, tf) > self.limit:
            return DIVERGED_COST
        return penalised(*self.loop_load_response(loop, gains, tf))

    def search_loops(self, seed: int, maxiter: int, popsize: int, progress: Steps = QUIET):
        """`search` of several decoupled loops on the local models (the fixed-PID searches' coupling is 0: search_map),
        one loop at a time: on diag(the models) J_load is the sum of the loops' shares, the chatter, Ms and stability
        each loop's own (`loop_cost`), so the joint optimum is the loops' optima together wherever no loop chatters
        above MAX_CHATTER (the joint cost multiplies the whole sum by the worst chatter's penalty). Per loop a
        differential evolution over its 3-4 entries (seed + loop), then its Nelder-Mead polish: the same number of
        evaluations as `budget`'s joint search, each a third (two loops: half) of the work, and a search in 3-4
        dimensions instead of 3-4 n. scipy's OptimizeResult with the joint `cost` of the loops' optima together."""
        x = np.zeros(self.n)
        calls = [0]

        def counted_batch(fn):
            def wrapped(population):
                out = fn(population)
                calls[0] += columns(population).shape[0]
                progress.update(calls[0])
                return out
            return wrapped

        for loop in range(self.config.n_loops):
            idx = self.loop_indices(loop)

            def loop_cost(sub, loop=loop, idx=idx):
                vector = x.copy()
                vector[idx] = sub
                return self.loop_cost(loop, vector)
            costs = counted_batch(lambda pop, f=loop_cost: np.array([f(v) for v in columns(pop)]))
            found = differential_evolution(costs, [(-1.0, 1.0)] * len(idx), maxiter=maxiter, popsize=popsize,
                                           seed=seed + loop, polish=False, tol=1e-6, vectorized=True,
                                           updating="deferred")
            best, best_cost = np.asarray(found.x), float(found.fun)
            if best_cost < DIVERGED_COST:
                polished = minimize(counted_batch(loop_cost), best, method="Nelder-Mead",
                                    bounds=[(-1.0, 1.0)] * len(idx),
                                    options={"maxfev": polish_evaluations(maxiter) * len(idx), "xatol": 1e-4,
                                             "fatol": 1e-7})
                if polished.fun < best_cost:
                    best = np.asarray(polished.x)
            x[idx] = best
        return OptimizeResult(x=x, fun=float(self.cost(x)), nfev=calls[0], success=True)

    def search_verified(self, seed: int, maxiter: int, popsize: int, progress: Steps = QUIET) -> tuple:
        """`search` on the local models where `identify_models` found them, its result verified on the FMU
        (`validate_models`; its cost is then the FMU's); where they disagree, or without models, `search` on the FMU.
        Returns (scipy's result, nfev the evaluations of both searches; the path taken, a ModelPath)."""
        record = ModelPath(self.design_model, "fmu", self.model_note, self.model_records())
        spent = 0
        if self.models is not None:
            generations, population = model_budget(maxiter, popsize)
            progress.step("load design on the identified local models (differential evolution, then Nelder-Mead)",
                          self.budget(generations, population))
            result = self.search(seed, generations, population, progress=progress)
            progress.step("load design: the identified models' choice verified on the FMU")
            record = self.validate_models(result.x, record)
            if record.agrees:
                record.path = "identified"
                result.fun = penalised(record.fmu_load_cost, record.fmu_chatter)
                return result, record
            record.note = (f"the FMU's load cost {record.fmu_load_cost:.4g} differs from the models' "
                           f"{record.predicted_load_cost:.4g} by {100 * record.validation_error:.1f} % "
                           f"(tolerance {100 * record.tolerance:.0f} %) or the loop chatters on the FMU "
                           f"({record.fmu_chatter:.3f}): the search ran on the FMU")
            spent = int(result.nfev)
            self.use_fmu()
        progress.step("load design (differential evolution, then Nelder-Mead)", self.budget(maxiter, popsize))
        result = self.search(seed, maxiter, popsize, progress=progress)
        result.nfev = int(result.nfev) + spent
        return result, record

    def close(self) -> None:
        for core in self.cores + self.quiet_cores:
            core.close()
        self.cores, self.quiet_cores = [], []


def setpoint_response(core, gains: GainValues, seeds: list[int]) -> tuple[float, float]:
    """(ISE mean over the episodes, worst overshoot [% of the step]) of constant gains on `core`'s (noise-free)
    episodes; (inf, inf) when one ends early. ISE = Ts sum_k e_k^2 summed over loops; overshoot per setpoint step
    as metrics.compute_metrics defines it (the first step from the initial measurement), computed here directly
    because the search calls it thousands of times."""
    config = core.config
    ise, overshoot = 0.0, 0.0
    for s in seeds:
        traj = gains_rollout(lambda c: gains, config, seed=s, core=core)
        if traj.terminated:
            return math.inf, math.inf
        r, y = traj.setpoint, traj.measurement
        ise += float(np.sum((r - y) ** 2) * config.sample_time_s)
        overshoot = max(overshoot, _worst_overshoot(r, y))
    return ise / len(seeds), overshoot


def _worst_overshoot(r: np.ndarray, y: np.ndarray) -> float:
    """Largest overshoot [%] over the setpoint steps of r (n+1, n_loops), each from the previous setpoint (the
    first from y[0]); steps smaller than 1e-9 of the values are no steps."""
    worst = 0.0
    for i in range(r.shape[1]):
        ri, yi = r[:, i], y[:, i]
        starts = [0] + [int(k) + 1 for k in np.flatnonzero(np.diff(ri) != 0)]
        for s, end in zip(starts, starts[1:] + [len(ri)]):
            base = yi[0] if s == 0 else ri[s - 1]
            delta = ri[s] - base
            if abs(delta) <= 1e-9 * max(1.0, abs(ri[s]), abs(base)) or end - s < 2:
                continue
            sign = 1.0 if delta > 0 else -1.0
            worst = max(worst, max(0.0, float(np.max(sign * (yi[s:end] - ri[s])))) / abs(delta) * 100.0)
    return worst


class SetpointDesign(OutcomeCache):
    """Step 4 (module docstring): (Kp, Ti, Td[, Tf], b) minimising the setpoint ISE subject to Ms and noise as in
    step 2, J_load <= load_tolerance x the step-2 optimum (with rule_bound, and at most what the classical rules
    reach at the candidate's Ms) and overshoot <= max_overshoot. Used when no b in B_GRID
    meets the overshoot limit with the step-2 gains, with the setpoint responses simulated on the FMU's training
    episodes; and, with on_models, where a b meets it, for the least setpoint ISE within the load tolerance
    (tuning.design_rule, requirement 5) with the unit setpoint step simulated on the design's local models
    (`model_setpoint_response`). objective "load": the load cost is minimised instead of the setpoint ISE, within the
    same limits (tuning.design_rule.follow_setpoints). The vector is the load design's plus one entry for b."""

    def __init__(self, design: LoadDesign, best_load: float, load_tolerance: float, max_overshoot: float,
                 seeds: list[int], on_models: bool = False, rule_bound=None, objective: str = "setpoint"):
        self.design = design
        self.objective = objective  # "setpoint": the setpoint ISE is minimised; "load": the load cost
        self.rule_bound = rule_bound  # Ms -> the load cost the classical rules reach at that Ms (with on_models;
        #                               tuning.classical_rules.load_bound), or None
        self.best_load, self.load_tolerance, self.max_overshoot_fraction = best_load, load_tolerance, max_overshoot
        self.load_limit = load_tolerance * best_load if math.isfinite(load_tolerance) else math.inf  # inf: no limit
        self.max_overshoot = 100.0 * max_overshoot
        self.seeds = seeds
        self.on_models = on_models and design.models is not None
        quiet = dataclasses.replace(design.config, measurement_noise_std=0.0, actuator_noise_std=0.0,
                                    load_disturbance=0.0)
        self.core = None if self.on_models else open_core(quiet)
        self.n = design.n + 1
        self._seen: dict = {}
        self._owns_design = False  # a replica's design is its own (closed with it)

    @staticmethod
    def weight(vector) -> float:
        """b of a vector: its last entry mapped from [-1, 1] to [0, 1]."""
        return (min(max(float(vector[-1]), -1.0), 1.0) + 1.0) / 2.0

    @classmethod
    def replica(cls, design_args: tuple, prepared: dict, best_load: float, load_tolerance: float,
                max_overshoot: float, seeds: list[int], on_models: bool = False) -> "SetpointDesign":
        """A search worker's copy (tuning.search_pool) on a replica of the load design (LoadDesign.replica)."""
        trade = cls(LoadDesign.replica(design_args, prepared), best_load, load_tolerance, max_overshoot, seeds,
                    on_models=on_models)
        trade._owns_design = True
        return trade

    def new_outcome(self, vector) -> tuple:
        """(step 2's constraint values, (load cost, ISE, overshoot)) of a vector; the second None where the first
        fail already (not simulated); `outcome` keeps it."""
        cheap = self.design.constraint_values(vector[:-1])
        return cheap, (None if np.any(cheap > 0) else self._simulate(vector))

    def _simulate(self, vector) -> tuple[float, float, float]:
        """(load cost, ISE, overshoot) of a vector, simulated (on the local models with on_models)."""
        d = self.design
        gains, tf = d.gains(vector[:-1]), d.filters(vector[:-1])
        load = d.search_load_cost(gains, tf)
        if self.on_models:
            return (load, *d.model_setpoint_response(gains, tf, self.weight(vector)))
        self.core.set_structure([self.weight(vector)] * d.config.n_loops, d.c, tf)
        return (load, *setpoint_response(self.core, gains, self.seeds))

    def evaluate(self, vector) -> tuple[float, float, float]:
        """(load cost, ISE, overshoot) of a vector (simulated even where step 2's limits fail)."""
        found = self.outcome(vector)[1]
        return found if found is not None else self._simulate(vector)

    def constraint_values(self, vector) -> np.ndarray:
        """[step 2's, load cost / its limit - 1, overshoot / its limit - 1] (<= 0: feasible); where step 2's fail the
        last two are not simulated: 1 + their worst, and 1."""
        cheap, simulated = self.outcome(vector)
        if simulated is None:
            return np.concatenate([cheap, [1.0 + float(np.max(cheap)), 1.0]])
        load, _, overshoot = simulated
        return np.concatenate([cheap, [load / self.vector_load_limit(vector) - 1.0,
                                       overshoot / max(self.max_overshoot, 1e-9) - 1.0
                                       if math.isfinite(overshoot) else DIVERGED_COST]])

    def vector_load_limit(self, vector) -> float:
        """The load limit of a vector: load_limit, and with a rule bound at most what the classical rules reach at the
        vector's Ms."""
        if self.rule_bound is None:
            return self.load_limit
        d = self.design
        return min(self.load_limit, self.rule_bound(d.limit_values(d.gains(vector[:-1]), d.filters(vector[:-1]))[0]))

    def cost(self, vector) -> float:
        load, ise, _ = self.evaluate(vector)
        value = load if self.objective == "load" else ise
        return min(value, DIVERGED_COST) if math.isfinite(value) else DIVERGED_COST

    def _batch(self, population: np.ndarray, pool: SearchPool | None, fn) -> list:
        if pool is None:
            return [fn(v) for v in columns(population)]
        return [fn(v) for v in self.evaluate_new(population, pool)]

    def budget(self, maxiter: int, popsize: int, whole_box: bool = False) -> int:
        """The most cost evaluations `search` makes (DE with maxiter halved around a start, whole: over the whole box)."""
        return (self.generations(maxiter, whole_box) + 1) * popsize * self.n

    @staticmethod
    def generations(maxiter: int, whole_box: bool) -> int:
        """DE generations of `search`: maxiter halved around a start (the feasible set lies near it), all of them over
        the whole box (with no start, the feasible set may lie anywhere in it)."""
        return maxiter if whole_box else max(1, maxiter // 2)

    def search(self, start, seed: int, maxiter: int, popsize: int, progress: Steps = QUIET):
        """DE from a population around `start` (the load optimum with its best b: the feasible set lies near it, within
        load_tolerance of its load cost), spread INIT_SPREAD in the [-1, 1] coordinates; start None: a Latin
        hypercube over the whole box (step 5: the load optimum's neighbourhood failed); `generations` of them.
        progress: counts every constraint evaluation (the simulations: DE computes the constraints of every trial and
        the cost of the feasible ones only, so counting the cost would stop far short of the total)."""
        maxiter = self.generations(maxiter, start is None)
        if start is None:
            init = "latinhypercube"
        else:
            rng = np.random.default_rng(seed)
            start = np.clip(np.asarray(start, float), -1.0, 1.0)
            init = np.clip(start + rng.normal(0.0, INIT_SPREAD, (popsize * self.n, self.n)), -1.0, 1.0)
            init[0] = start
        d = self.design
        # on the search pool: each candidate on the local models (milliseconds: the Kp intervals of every loop and
        # point, the setpoint and load responses) or on the FMU
        with SearchPool(self, SetpointDesign.replica, (d.args, d.prepared(), self.best_load, self.load_tolerance,
                                                       self.max_overshoot_fraction, self.seeds, self.on_models),
                        d.pool_workers(), fmus=search_fmus(d.config)) as pool:
            constraints = batch_counted(lambda x: np.array(self._batch(x, pool, self.constraint_values)).T, progress)
            result = differential_evolution(lambda x: np.array(self._batch(x, pool, self.cost)),
                                            [(-1.0, 1.0)] * self.n, maxiter=maxiter, popsize=popsize, seed=seed,
                                            polish=False, tol=1e-6, init=init, vectorized=True, updating="deferred",
                                            constraints=NonlinearConstraint(constraints, -np.inf, 0.0))
        result.nfev = constraints.calls  # the vectors simulated (scipy counts a vectorized call as one)
        return result

    def close(self) -> None:
        if self.core is not None:
            self.core.close()
        if self._owns_design:
            self.design.close()


def model_budget(maxiter: int, popsize: int, minimum: tuple[int, int] = (MODEL_MIN_GENERATIONS, MODEL_MIN_POPSIZE)
                 ) -> tuple[int, int]:
    """(generations, popsize) of a search on the local models for the FMU path's (maxiter, popsize): a model candidate
    costs about a thousandth of an FMU simulation, so the search affords MODEL_GENERATIONS x as many generations, and
    at least `minimum` (the load search's; SETPOINT_MODEL_MINIMUM for the setpoint search)."""
    return max(MODEL_GENERATIONS * maxiter, minimum[0]), max(popsize, minimum[1])


def setpoint_weight(config: TuningConfig, gains: GainValues, structure: tuple[list, list, list], seeds: list[int],
                    max_overshoot: float, grid: tuple = B_GRID) -> tuple[float, list[dict]]:
    """The b of `grid` (B_GRID: tuning.design_rule, requirement 3) and the table of what each b gave ({"b", "ISE",
    "Overshoot"}, Overshoot in percent of the step, worst over the episodes' setpoint steps)."""
    quiet = dataclasses.replace(config, measurement_noise_std=0.0, actuator_noise_std=0.0, forecast_horizon=0,
                                load_disturbance=0.0)
    core = open_core(quiet)
    rows = []
    try:
        for b in grid:
            core.set_structure([b] * config.n_loops, structure[1], structure[2])
            ise, overshoot = setpoint_response(core, gains, seeds)
            rows.append({"b": b, "ISE": ise, "Overshoot": overshoot})
    finally:
        core.close()
    within = [r for r in rows if r["Overshoot"] <= 100.0 * max_overshoot]
    best = min(within, key=lambda r: r["ISE"]) if within else min(rows, key=lambda r: (r["Overshoot"], r["ISE"]))
    return best["b"], rows
