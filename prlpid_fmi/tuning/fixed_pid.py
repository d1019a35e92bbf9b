"""The setpoint search of constant gains, and the Ms check that detunes a PID until it meets the Ms limit.

tuning.design_rule designs the fixed PID; it measures the plant with the PID this search finds in a few
generations, and baseline.objective "setpoint" is this search alone:

Constant Kp, Ti, Td (a coupled PID's coefficients held at 0: load_design.search_map) are searched inside the
scenario's gain ranges by differential evolution. The search vector lives in [-1, 1]^n and is mapped like the paper's
absolute action map (geometric for log ranges), but the candidate gains drive the loop core directly (no action path).
Cost, mean over a few seeded training episodes (same setpoint ranges, noise, disturbances and
parameter randomisation as training, forecast off), per loop in normalised units::

    J = sum_k Ts * ( e_k**2 + w_cv * min(|u_k - u_{k-1}| / control_scale, 1) )

with w_cv = reward.control_variation_weight, the same weight the agent's reward uses, so the search
does not buy ISE with a chattering actuator. A diverging episode costs DIVERGED_COST.

Robustness: with `max_sensitivity` given, the result must have a peak sensitivity Ms (measured on the
FMU, prlpid_fmi.robustness.margins) at most that limit at every operating point of the setpoint range: the
low end, the middle and the high end (margins.setpoint_range_points; a fixed PID is used at every setpoint,
and a nonlinear plant's Ms changes over the range), and with training.randomize on each Monte-Carlo parameter
draw of tuning.load_experiment.parameter_samples too (the deliverable checks the same draws). The cheapest few members of the final DE population are
tried in order of cost; if none qualifies, the best one is detuned, at its worst failing point until every
point meets the limit, by the smallest lambda there, in two ways: Kp / lambda with Ti and Td * lambda (the
same controller on a time axis lambda times slower: the integral gain Kp/Ti falls by lambda^2, so the last part
of a step can creep in) and Kp / lambda with Ti and Td kept; the one with the lower J is kept. The load design
uses the first, and the second only where the first cannot meet the limit.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import differential_evolution

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.loop.actions import ActionMap
from prlpid_fmi.loop.core import LoopCore, pid_structure
from prlpid_fmi.loop.evaluation import Trajectory, gains_rollout
from prlpid_fmi.loop.gains import Gains, GainValues, gains_from_values
from prlpid_fmi.loop.isolated import make_core
from prlpid_fmi.progress import Steps, batch_counted
from prlpid_fmi.robustness.margins import margins_of, predicted_ms, setpoint_range_points
from prlpid_fmi.robustness.status import meets_limit
from prlpid_fmi.tuning.load_design import columns, search_map
from prlpid_fmi.tuning.load_experiment import parameter_samples
from prlpid_fmi.tuning.search_pool import SearchPool, search_fmus, search_workers

DIVERGED_COST = 1e6


@dataclass(frozen=True)
class FixedPid:
    """Result of the search: its vector in [-1, 1]^n, the gains (exactly those evaluated), the cost, the
    evaluations, the structure (b, c, Tf lists per loop) and what the design found (info: estimates per point,
    the setpoint weights tried; empty for the setpoint objective)."""

    action: np.ndarray
    gains: Gains
    cost: float
    evaluations: int
    structure: tuple = ((), (), ())
    info: dict = dataclasses.field(default_factory=dict)

    def structure_dict(self) -> dict:
        """{"setpoint_weight", "derivative_weight", "measurement_filter_s"}: lists per loop (fixed_pid.json)."""
        b, c, tf = self.structure
        return {"setpoint_weight": list(b), "derivative_weight": list(c), "measurement_filter_s": list(tf)}

    def gains_values(self) -> GainValues:
        """The gains as GainValues, what LoopCore.step takes."""
        return self.gains.values()


def episode_cost(traj: Trajectory, core: LoopCore) -> float:
    """J of one trajectory (see module docstring), DIVERGED_COST scaled by the steps missing when it diverged."""
    config = core.config
    scale = np.asarray(core.scale)
    e = (traj.setpoint - traj.measurement) / scale
    cost = float(np.sum(e ** 2) * config.sample_time_s)
    weight = config.reward.control_variation_weight
    if weight:
        du = np.abs(np.diff(traj.pid_output, axis=0)) / np.asarray(core.u_scale)
        cost += weight * float(np.sum(np.minimum(du, 1.0)) * config.sample_time_s) / config.n_loops
    if traj.terminated:
        cost += DIVERGED_COST * (1.0 + (config.episode_steps - traj.steps) / config.episode_steps)
    return cost


class SetpointSearch:
    """J (module docstring) of search vectors in [-1, 1]^n, on one loop core of `config` (forecast off) over the
    seeded episodes `seeds`; a search worker builds its own (tuning.search_pool)."""

    def __init__(self, config: TuningConfig, seeds: list[int]):
        self.gain_map = search_map(config)
        self.seeds = seeds
        self.core = make_core(config)

    def cost(self, vector) -> float:
        return _cost_of(self.gain_map.values(np.asarray(vector, float).tolist()), self.core, self.seeds)

    def close(self) -> None:
        self.core.close()


ROBUST_CANDIDATES = 4  # cheapest DE population members whose Ms is measured before detuning
DETUNE_STEP = 1.15  # detuning factors lambda = DETUNE_STEP**k (Kp / lambda, Ti and Td * lambda) ...
DETUNE_SCAN = (1, 2, 4, 8, 16, 30)  # ... scanned at these k (lambda 1.15 to 66), then bisected
DETUNE_BISECTIONS = 4


PREDICTION_MARGIN = 0.005  # an Ms predicted this far (relative) from the limit decides without an experiment
PREDICTION_TOLERANCE = 0.05  # a measured Ms this close (relative) to its prediction confirms the predictions


def _meets(config: TuningConfig, gains: GainValues, point: list[float], limit: float) -> bool:
    """The deliverable's rule at the point (robustness.status.meets_limit): verified within the limit, or impossible
    to measure there (a time-varying plant); a failed estimate (diverged, saturated, lightly damped) does not."""
    return meets_limit(margins_of(config, gains, point), limit)


def _likely_meets(config: TuningConfig, gains: GainValues, point: list[float], limit: float) -> bool:
    """`_meets` as predicted from the plant response measured at the point before (robustness.margins.predicted_ms)
    where the prediction lies more than PREDICTION_MARGIN (relative) from the limit, else measured. A search step,
    never a verdict: what a search returns is measured (`detune`, `_robust`)."""
    ms = predicted_ms(config, gains, point)
    if ms is not None and abs(ms - limit) > PREDICTION_MARGIN * limit:
        return ms <= limit
    return _meets(config, gains, point, limit)


def clearly_within(config: TuningConfig, gains: GainValues, point: list[float], limit: float) -> bool:
    """Ms predicted (robustness.margins.predicted_ms) more than PREDICTION_MARGIN (relative) below the limit at the
    point: a search may pass such gains without an experiment; a verdict measures them."""
    ms = predicted_ms(config, gains, point)
    return ms is not None and ms < (1.0 - PREDICTION_MARGIN) * limit


def detune(config: TuningConfig, gains: GainValues, point: list[float], limit: float,
           keep_ti: bool = False, plant: TuningConfig | None = None) -> tuple | None:
    """`gains` detuned (Kp / lambda, Ti * lambda and Td * lambda, or Ti and Td kept with keep_ti, lambda =
    DETUNE_STEP**k, clipped into the gain ranges) by the smallest k that gives Ms <= limit at `point`. Kp / lambda
    with Ti, Td * lambda is C(lambda s) / lambda, the same controller on a time axis lambda times slower, its zeros
    and crossover moved down together. A scan of k in DETUNE_SCAN,
    then bisection on k between the last failing and the first passing value. None when no k in the scan
    passes (an unstable plant fails at both ends, so the scan starts small). plant: the config whose FMU
    parameters Ms is measured with (a Monte-Carlo draw; default `config`), the gain ranges are `config`'s.

    The scan and the bisection decide each step from the Ms predicted from the plant response measured at the
    point (`_likely_meets`; one independent loop) and measure on the FMU only where the prediction lies near the
    limit, or where no response was measured there yet (the first verified measurement of the scan is then the
    point's response, and predicts the steps after it); the result is then measured. Where that measurement fails
    the limit, the whole search runs again on measurements alone (the search before predictions): same result
    whenever the predictions decide as the measurements would. Where no k is predicted to pass, the scan's k of least
    predicted Ms is measured: failing too, and within PREDICTION_TOLERANCE of its prediction, None (a PID too weak for
    an unstable plant, which detuning only weakens, costs one experiment, not a scan); passing, or a measurement
    the prediction missed (a nonlinear plant's response changes with the PID), the search on measurements alone."""
    plant = config if plant is None else plant
    found = _detune(config, gains, point, limit, keep_ti, plant, _likely_meets)
    if found is not None and _meets(plant, found, point, limit):
        return found
    if found is None:  # predicted: no k passes; the most promising k measured, and where it fails too, none
        predicted = [(predicted_ms(plant, detuned(config, gains, k, keep_ti), point), k) for k in DETUNE_SCAN]
        if all(ms is not None for ms, _ in predicted):
            expected, k = min(predicted)
            measured = margins_of(plant, detuned(config, gains, k, keep_ti), point)
            confirmed = (not math.isfinite(expected) and not math.isfinite(measured.Ms)) or \
                abs(measured.Ms - expected) <= PREDICTION_TOLERANCE * expected
            if not meets_limit(measured, limit) and confirmed:
                return None
    return _detune(config, gains, point, limit, keep_ti, plant, _meets)


def detuned(config: TuningConfig, gains: GainValues, k: float, keep_ti: bool) -> GainValues:
    """gains detuned by lambda = DETUNE_STEP**k (`detune`), clipped into config's gain ranges."""
    Kp, Ti, Td, coupling = gains
    lam = DETUNE_STEP ** k
    ti_factor = 0.0 if keep_ti else 1.0
    return GainValues([max(x / lam, l.Kp.low) for x, l in zip(Kp, config.loops)],
                      [min(x * lam ** ti_factor, l.Ti.high) for x, l in zip(Ti, config.loops)],
                      [min(x * lam ** ti_factor, max(l.Td.high, x)) for x, l in zip(Td, config.loops)], coupling)


def _detune(config: TuningConfig, gains: GainValues, point: list[float], limit: float, keep_ti: bool,
            plant: TuningConfig, meets) -> GainValues | None:
    """`detune`'s scan and bisection with meets(plant, gains, point, limit) deciding each step."""
    def at(k):
        return detuned(config, gains, k, keep_ti)

    low = 0.0  # k known to fail (the gains themselves)
    for k in DETUNE_SCAN:
        if meets(plant, at(k), point, limit):
            high = float(k)
            for _ in range(DETUNE_BISECTIONS):
                mid = 0.5 * (low + high)
                if meets(plant, at(mid), point, limit):
                    high = mid
                else:
                    low = mid
            return at(high)
        low = float(k)
    return None


def detune_over(config: TuningConfig, gains: GainValues, points: list[list[float]], limit: float,
                keep_ti: bool | None = None, draws: list[TuningConfig] = ()) -> tuple | None:
    """`gains` detuned (`detune`) until Ms <= limit at every operating point, on the nominal plant and on every
    Monte-Carlo draw in `draws` (tuning.load_experiment.parameter_samples): each pass detunes at the worst failing
    check, which usually settles the others too. None when a check cannot be met. keep_ti None: the together rule
    (Ti and Td * lambda), else, where it cannot meet the limit, Kp / lambda alone (the together rule keeps
    Kp * Td, the sampled loop's gain near Nyquist, which is sometimes what breaks the limit)."""
    if keep_ti is None:
        together = detune_over(config, gains, points, limit, keep_ti=False, draws=draws)
        return together if together is not None else detune_over(config, gains, points, limit, keep_ti=True,
                                                                   draws=draws)
    checks = [(plant, p) for plant in (config, *draws) for p in points]
    for _ in checks:
        failing = [(margins_of(plant, gains, p).Ms, i) for i, (plant, p) in enumerate(checks)
                   if not _meets(plant, gains, p, limit)]
        if not failing:
            return gains
        plant, point = checks[max(failing)[1]]
        gains = detune(config, gains, point, limit, keep_ti=keep_ti, plant=plant)
        if gains is None:
            return None
    return gains if all(_meets(plant, gains, p, limit) for plant, p in checks) else None


def _robust(config: TuningConfig, gain_map: ActionMap, population, energies, limit: float,
            core: LoopCore, seeds: list[int]):
    """(vector, gains tuple) of the cheapest of the ROBUST_CANDIDATES cheapest population members with
    Ms <= limit at every operating point of the setpoint range (setpoint_range_points), on the nominal plant and
    the Monte-Carlo draws (parameter_samples, with training.randomize); else the best member made robust
    (`robust_gains`)."""
    points, draws = setpoint_range_points(config), parameter_samples(config)
    order = np.argsort(energies)
    checks = [(plant, p) for plant in (config, *draws) for p in points]
    for i in order[:ROBUST_CANDIDATES]:
        g = gain_map.values(population[i].tolist())
        # a member predicted to fail clearly (_likely_meets) is not measured; the one taken is, at every check
        if all(_likely_meets(plant, g, p, limit) for plant, p in checks) and \
                all(_meets(plant, g, p, limit) for plant, p in checks):
            return population[i], g
    best = population[order[0]]
    return best, robust_gains(config, gain_map.values(best.tolist()), limit, lambda r: _cost_of(r, core, seeds))


def robust_gains(config: TuningConfig, g: GainValues, limit: float, cost) -> GainValues:
    """g where its Ms <= limit at every operating point of the setpoint range (and Monte-Carlo draw); else g detuned
    both ways (`detune_over`, with and without keep_ti; a loop in a limit cycle has Ms inf and a slower loop cures
    it), the one of lower cost(gains) (J on the search's episodes); else the same PI (Td at its low end, detuned if
    need be); else g as it is (the deliverable then reports its Ms)."""
    points, draws = setpoint_range_points(config), parameter_samples(config)
    checks = [(plant, p) for plant in (config, *draws) for p in points]
    if all(_meets(plant, g, p, limit) for plant, p in checks):
        return g
    repairs = [r for r in (detune_over(config, g, points, limit, keep_ti=False, draws=draws),
                           detune_over(config, g, points, limit, keep_ti=True, draws=draws)) if r]
    if not repairs and any(td > l.Td.low for td, l in zip(g[2], config.loops)):
        # the derivative is the usual culprit of a loop that limit-cycles at Nyquist against a limit (the
        # exothermic reactor: Kp 6.6, Ti 123 s, Td 17 s never settles; the same PI has Ms 1.13-1.15): the same PI
        pi = (g[0], g[1], [l.Td.low for l in config.loops], g[3])
        repairs = [pi] if all(_meets(plant, pi, p, limit) for plant, p in checks) else \
            [r for r in (detune_over(config, pi, points, limit, keep_ti=False, draws=draws),) if r]
    return min(repairs, key=cost) if repairs else g


def robust_setpoint_pid(config: TuningConfig, found: FixedPid, seeds: list[int], limit: float) -> FixedPid:
    """`found` (a setpoint_pid result checked against a looser Ms limit) made robust to `limit` (`robust_gains`), its
    cost J on `seeds` again where its gains changed."""
    search = dataclasses.replace(config, forecast_horizon=0)
    evaluator = SetpointSearch(search, seeds)
    try:
        gains = robust_gains(search, found.gains.values(), limit, lambda r: _cost_of(r, evaluator.core, seeds))
        if gains == found.gains.values():
            return found
        return dataclasses.replace(found, gains=gains_from_values(*gains), cost=_cost_of(gains, evaluator.core, seeds))
    finally:
        evaluator.close()


def setpoint_pid(config: TuningConfig, seed: int, episodes: int, maxiter: int, popsize: int, progress: Steps,
                  max_sensitivity: float | None, name: str = "setpoint search", workers: int | None = None) -> FixedPid:
    """The setpoint objective's search (module docstring); each generation evaluated as a whole (deferred updating)
    on search_workers(workers) processes (tuning.search_pool): the same result for any number."""
    search = dataclasses.replace(config, forecast_horizon=0)
    seeds = [seed + i for i in range(episodes)]
    evaluator = SetpointSearch(search, seeds)
    core, gain_map = evaluator.core, evaluator.gain_map
    n = gain_map.size
    progress.step(name, (maxiter + 1) * popsize * n)
    try:
        with SearchPool(evaluator, SetpointSearch, (search, seeds), search_workers(workers, [core]),
                        fmus=search_fmus(search)) as pool:
            cost = batch_counted(lambda x: np.array(pool.map("cost", list(columns(x)))), progress)
            result = differential_evolution(cost, [(-1.0, 1.0)] * n, maxiter=maxiter, popsize=popsize, seed=seed,
                                            polish=False, tol=1e-6, vectorized=True, updating="deferred")
            result.nfev = cost.calls  # scipy counts a vectorized call as one
        vector, gains = result.x, gain_map.values(result.x.tolist())
        cost = float(result.fun)
        if max_sensitivity is not None:
            progress.step(f"Ms check on the FMU of the {name}'s best ({len(setpoint_range_points(config))} "
                          "operating points" + (", parameter draws" if parameter_samples(config) else "") + ")")
            vector, gains = _robust(search, gain_map, result.population, result.population_energies, max_sensitivity,
                                    core, seeds)
            cost = _cost_of(gains, core, seeds)
    finally:
        core.close()
    return FixedPid(vector, gains_from_values(*gains), cost, int(result.nfev), pid_structure(config))


def _cost_of(gains: GainValues, core: LoopCore, seeds: list[int]) -> float:
    return sum(episode_cost(gains_rollout(lambda c: gains, core.config, seed=s, core=core), core)
               for s in seeds) / len(seeds)
