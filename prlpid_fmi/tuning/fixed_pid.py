"""The well-tuned fixed PID that every adaptive policy is reported against, and the anchor it learns around.

baseline.objective "load" (the default) designs it for load rejection under the Ms and noise limits, then sets
the setpoint weight (tuning.load_design); it measures the plant with the PID the "setpoint" search below finds
in STABILISING_GENERATIONS generations. baseline.objective "setpoint" is the paper-era search below, alone:

Constant Kp, Ti, Td (and coupling) are searched inside the scenario's gain ranges by differential
evolution. The search vector lives in [-1, 1]^n and is mapped like the paper's absolute action map
(geometric for log ranges), but the candidate gains drive the loop core directly (no action path).
Cost, mean over a few seeded training episodes (same setpoint ranges, noise, disturbances and
parameter randomisation as training, forecast off), per loop in normalised units::

    J = sum_k Ts * ( e_k**2 + w_cv * min(|u_k - u_{k-1}| / control_scale, 1) )

with w_cv = reward.control_variation_weight, the same weight the agent's reward uses, so the search
does not buy ISE with a chattering actuator. A diverging episode costs DIVERGED_COST.

Robustness: with `max_sensitivity` given, the result must have a peak sensitivity Ms (measured on the
FMU, prlpid_fmi.robustness.margins) at most that limit at every operating point of the setpoint range: the
low end, the middle and the high end (margins.setpoint_range_points; a fixed PID is used at every setpoint,
and a nonlinear plant's Ms changes over the range), and with training.randomize on each Monte-Carlo parameter
draw of tuning.load_design.parameter_samples too (the deliverable checks the same draws). The cheapest few members of the final DE population are
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

from prlpid_fmi.config import BaselineConfig, DeployConfig, TuningConfig
from prlpid_fmi.loop.actions import ActionMap
from prlpid_fmi.loop.core import LoopCore, pid_structure
from prlpid_fmi.loop.evaluation import Trajectory, gains_rollout
from prlpid_fmi.loop.gains import Gains, gains_from_values
from prlpid_fmi.loop.isolated import make_core
from prlpid_fmi.progress import QUIET, Steps, batch_counted
from prlpid_fmi.robustness.margins import margins_of, predicted_ms, setpoint_range_points
from prlpid_fmi.robustness.status import meets_limit
from prlpid_fmi.tuning.load_design import LoadDesign, SetpointDesign, columns, parameter_samples, setpoint_weight
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

    def gains_values(self) -> tuple:
        """(Kp, Ti, Td, coupling) lists, what LoopCore.step takes."""
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
        self.gain_map = ActionMap(config.loops, config.coupled, config.coupling_range)
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


def _meets(config: TuningConfig, gains: tuple, point: list[float], limit: float) -> bool:
    """The deliverable's rule at the point (robustness.status.meets_limit): verified within the limit, or impossible
    to measure there (a time-varying plant); a failed estimate (diverged, saturated, lightly damped) does not."""
    return meets_limit(margins_of(config, gains, point), limit)


def _likely_meets(config: TuningConfig, gains: tuple, point: list[float], limit: float) -> bool:
    """`_meets` as predicted from the plant response measured at the point before (robustness.margins.predicted_ms)
    where the prediction lies more than PREDICTION_MARGIN (relative) from the limit, else measured. A search step,
    never a verdict: what a search returns is measured (`detune`, `_robust`)."""
    ms = predicted_ms(config, gains, point)
    if ms is not None and abs(ms - limit) > PREDICTION_MARGIN * limit:
        return ms <= limit
    return _meets(config, gains, point, limit)


def detune(config: TuningConfig, gains: tuple, point: list[float], limit: float,
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
    limit; the result is then measured. Where that measurement fails the limit, or no k passes, the whole search
    runs again on measurements alone (the search before predictions): same result whenever the predictions decide
    as the measurements would."""
    plant = config if plant is None else plant
    if predicted_ms(plant, gains, point) is not None:
        found = _detune(config, gains, point, limit, keep_ti, plant, _likely_meets)
        if found is not None and _meets(plant, found, point, limit):
            return found
    return _detune(config, gains, point, limit, keep_ti, plant, _meets)


def _detune(config: TuningConfig, gains: tuple, point: list[float], limit: float, keep_ti: bool, plant: TuningConfig,
            meets) -> tuple | None:
    """`detune`'s scan and bisection with meets(plant, gains, point, limit) deciding each step."""
    Kp, Ti, Td, coupling = gains
    ti_factor = 0.0 if keep_ti else 1.0

    def detuned(k):
        lam = DETUNE_STEP ** k
        return ([max(x / lam, l.Kp.low) for x, l in zip(Kp, config.loops)],
                [min(x * lam ** ti_factor, l.Ti.high) for x, l in zip(Ti, config.loops)],
                [min(x * lam ** ti_factor, max(l.Td.high, x)) for x, l in zip(Td, config.loops)], coupling)

    low = 0.0  # k known to fail (the gains themselves)
    for k in DETUNE_SCAN:
        if meets(plant, detuned(k), point, limit):
            high = float(k)
            for _ in range(DETUNE_BISECTIONS):
                mid = 0.5 * (low + high)
                if meets(plant, detuned(mid), point, limit):
                    high = mid
                else:
                    low = mid
            return detuned(high)
        low = float(k)
    return None


def detune_over(config: TuningConfig, gains: tuple, points: list[list[float]], limit: float,
                keep_ti: bool | None = None, draws: list[TuningConfig] = ()) -> tuple | None:
    """`gains` detuned (`detune`) until Ms <= limit at every operating point, on the nominal plant and on every
    Monte-Carlo draw in `draws` (tuning.load_design.parameter_samples): each pass detunes at the worst failing
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
    the Monte-Carlo draws (parameter_samples, with training.randomize); else the best member detuned both ways (`detune_over`, with and without keep_ti; a loop in a limit cycle has Ms inf and a slower loop
    cures it), the one with the lower J on `seeds`; else the same PI (Td at its low end, detuned if need be); else
    the best member as it is (the deliverable then
    reports its Ms)."""
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
    g = gain_map.values(best.tolist())
    repairs = [r for r in (detune_over(config, g, points, limit, keep_ti=False, draws=draws),
                           detune_over(config, g, points, limit, keep_ti=True, draws=draws)) if r]
    if not repairs and any(td > l.Td.low for td, l in zip(g[2], config.loops)):
        # the derivative is the usual culprit of a loop that limit-cycles at Nyquist against a limit (the
        # exothermic reactor: Kp 6.6, Ti 123 s, Td 17 s never settles; the same PI has Ms 1.13-1.15): the same PI
        pi = (g[0], g[1], [l.Td.low for l in config.loops], g[3])
        repairs = [pi] if all(_meets(plant, pi, p, limit) for plant, p in checks) else \
            [r for r in (detune_over(config, pi, points, limit, keep_ti=False, draws=draws),) if r]
    return best, min(repairs, key=lambda r: _cost_of(r, core, seeds)) if repairs else g


def tune_fixed_pid(config: TuningConfig, seed: int = 0, episodes: int | None = None, maxiter: int | None = None,
                   popsize: int | None = None, progress: Steps = QUIET, max_sensitivity: float | None = None,
                   baseline: BaselineConfig = BaselineConfig(), deploy: DeployConfig = DeployConfig()) -> FixedPid:
    """The fixed PID of baseline.objective: "load" (tuning.load_design: load IAE under the Ms and noise limits,
    then the setpoint weight) or "setpoint" (J of the module docstring over `episodes` seeded training episodes).

    progress: a prlpid_fmi.progress.Steps the search shows its steps on (each search counted per cost evaluation,
    its polish included; the Ms checks and experiments as steps of their own).
    max_sensitivity: the Ms limit the result must meet (None: no robustness requirement).
    baseline: objective, load_step, load_tolerance, widen_ranges, and the budget (episodes, maxiter, popsize) where
    those arguments are None; deploy: max_overshoot and max_noise_gain.
    """
    episodes = baseline.episodes if episodes is None else episodes
    maxiter = baseline.maxiter if maxiter is None else maxiter
    popsize = baseline.popsize if popsize is None else popsize
    if baseline.objective == "load":
        return _load_pid(config, seed, episodes, maxiter, popsize, progress, max_sensitivity, baseline, deploy)
    return _setpoint_pid(config, seed, episodes, maxiter, popsize, progress, max_sensitivity,
                         workers=baseline.workers)


def _setpoint_pid(config: TuningConfig, seed: int, episodes: int, maxiter: int, popsize: int, progress: Steps,
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


STABILISING_GENERATIONS = 6  # generations of the setpoint search that finds the PID the plant is measured with


def _load_pid(config: TuningConfig, seed: int, episodes: int, maxiter: int, popsize: int, progress: Steps,
              max_sensitivity: float | None, baseline: BaselineConfig, deploy: DeployConfig) -> FixedPid:
    """tuning.load_design's three steps, then the Ms check on the FMU with the final controller (detuned by
    `detune_over` where a point fails: the plant-response estimate is an estimate)."""
    design = LoadDesign(config, baseline.load_step, max_sensitivity, deploy.max_noise_gain, baseline.widen_ranges,
                        deploy.max_noise_increment, search_workers(baseline.workers))
    # robust too (its Ms checked and detuned as the setpoint search does): a lightly damped loop does not settle in
    # the frequency-response experiment, and an unverified response gives the design no constraint
    first = _setpoint_pid(config, seed, episodes, STABILISING_GENERATIONS, popsize, progress, max_sensitivity,
                          name="stabilising PID (setpoint search)", workers=baseline.workers)
    try:
        progress.step(f"frequency response of the plant at {len(design.points)} operating points"
                      + (f" and {len(parameter_samples(config))} parameter draws" if parameter_samples(config) else ""))
        design.prepare(first.gains.values())
        progress.step("load design (differential evolution, then Nelder-Mead)", design.budget(maxiter, popsize))
        result = design.search(seed, maxiter, popsize, progress=progress)
        vector = np.asarray(result.x)
        gains, tf = design.gains(vector), design.filters(vector)
        best_load = float(result.fun)
        b, c, _ = pid_structure(config)
        choices, traded, followed = [], None, None
        seeds = [seed + i for i in range(episodes)]
        if config.setpoint_weight == "tuned":
            progress.step("setpoint weight b")
            weight, choices = setpoint_weight(config, gains, (b, c, tf), seeds, deploy.max_overshoot)
            b = [weight] * config.n_loops
            if not any(r["Overshoot"] <= 100.0 * deploy.max_overshoot for r in choices):
                trade = SetpointDesign(design, best_load, baseline.load_tolerance, deploy.max_overshoot, seeds)
                progress.step("setpoint ISE within the overshoot limit (no b met it)", trade.budget(maxiter, popsize))
                try:
                    second = trade.search(np.append(vector, 2.0 * weight - 1.0), seed, maxiter, popsize,
                                          progress=progress)
                    feasible = bool(np.max(trade.constraint_values(second.x)) <= 0)
                    load, ise, overshoot = trade.evaluate(second.x)
                    traded = {"load_cost": load, "ISE": ise, "Overshoot": overshoot, "feasible": feasible,
                              "evaluations": int(second.nfev)}
                    if feasible:  # else the load optimum stays, with the b of least overshoot
                        vector = np.asarray(second.x)
                        gains, tf = design.gains(vector[:-1]), design.filters(vector[:-1])
                        b = [trade.weight(vector)] * config.n_loops
                finally:
                    trade.close()
            if traded is not None and not traded["feasible"]:  # step 5 (tuning.load_design)
                followed, found = follow_setpoints(config, design, first, best_load, deploy, seeds, seed, maxiter,
                                                    popsize, progress, diverged=not follows_setpoints(choices, traded))
                if found is not None:
                    vector, gains, (b, c, tf) = found
        structure = (b, c, tf)
        tuned = dataclasses.replace(design.search_config, tuned_structure=tuple(zip(b, c, tf)))
        fallback = None
        if max_sensitivity is not None:
            points = setpoint_range_points(config)
            progress.step(f"Ms check on the FMU ({len(points)} operating points"
                          + (", parameter draws" if parameter_samples(config) else "") + "; detuned where one fails)")
            repaired = detune_over(tuned, gains, points, max_sensitivity, draws=parameter_samples(tuned))
            if repaired is None:  # the design's estimate misled it (several coupled loops, a nonlinear plant):
                # the setpoint search's robust PID, as before the load design, rather than an undeployable one
                fallback = _setpoint_pid(config, seed, episodes, maxiter, popsize, progress, max_sensitivity,
                                         name="setpoint search (the load design could not meet the Ms limit)",
                                         workers=baseline.workers)
                gains, structure = fallback.gains.values(), fallback.structure
                tf = list(structure[2])
            else:
                detuned, gains = repaired != gains, repaired
                cost = design.load_cost(gains, tf)
                if detuned and cost > baseline.load_tolerance * best_load:
                    # the check on the FMU cost more load rejection than the design may give up (its estimate
                    # misled it: interacting loops, measured loop at a time): the setpoint search's robust PID
                    # when it rejects loads better
                    alternative = _setpoint_pid(config, seed, episodes, maxiter, popsize, progress, max_sensitivity,
                                                name="setpoint search (the Ms check detuned the load design)",
                                                workers=baseline.workers)
                    if design.load_cost(alternative.gains.values(), list(alternative.structure[2])) < cost:
                        fallback = alternative
                        gains, structure = fallback.gains.values(), fallback.structure
                        tf = list(structure[2])
        cost = design.load_cost(gains, tf)
        info = {"objective": "load", "load_cost": cost, "load_optimum": best_load, "load_step": baseline.load_step,
                "traded_for_overshoot": traded, "followed_setpoints": followed,
                "estimates": design.estimates(gains, tf), "active_limits": design.active_limits(gains, tf),
                "setpoint_weights": choices,
                "stabilising_gains": first.gains.as_dict(), "feasible": bool(getattr(result, "constr_violation", 0) <= 0),
                "fell_back_to_setpoint_search": fallback is not None,
                "noise_increment_limit_relaxed": design.increment_relaxed}
    finally:
        design.close()
    return FixedPid(vector, gains_from_values(*gains), cost, first.evaluations + int(result.nfev), structure, info)


def follows_setpoints(choices: list[dict], traded: dict | None) -> bool:
    """Whether the gains kept by steps 2-4 of the load design follow the setpoint episodes they were chosen on: with
    some b of setpoint_weight's table they did not diverge, or the trade found gains within every limit."""
    return any(math.isfinite(r["ISE"]) for r in choices) or bool(traded and traded["feasible"])


def follow_setpoints(config: TuningConfig, design: LoadDesign, first: FixedPid, best_load: float, deploy: DeployConfig,
                     seeds: list[int], seed: int, maxiter: int, popsize: int, progress: Steps,
                     diverged: bool = True) -> tuple[dict, tuple | None]:
    """Step 5 of tuning.load_design, where no gains within the load tolerance met the overshoot limit: the setpoint ISE
    within step 2's limits and the overshoot limit, without a load limit, searched over the whole box. Its best is
    kept where it meets every limit, or where the gains of steps 2-4 diverged on the episodes (`diverged`) and it
    follows them; where they diverged and it does not follow them either, the stabilising PID `first` with its best
    setpoint weight. Returns (what was found, for fixed_pid.json: {"source": "search" | "stabilising PID" | None,
    "load_optimal_diverged", "load_cost", "ISE", "Overshoot", "feasible", "evaluations"}, (vector, gains, (b, c, Tf))
    to keep, or None: the gains of steps 2-4 stay)."""
    follow = SetpointDesign(design, best_load, math.inf, deploy.max_overshoot, seeds)
    progress.step("setpoint ISE within the overshoot limit without the load tolerance"
                  + (" (the load-optimal gains diverge on the setpoint episodes)" if diverged else ""),
                  follow.budget(maxiter, popsize, whole_box=True))
    try:
        result = follow.search(None, seed, maxiter, popsize, progress=progress)
        load, ise, overshoot = follow.evaluate(result.x)
        feasible = bool(np.max(follow.constraint_values(result.x)) <= 0)
        found = {"source": "search", "load_optimal_diverged": diverged, "load_cost": load, "ISE": ise,
                 "Overshoot": overshoot, "feasible": feasible, "evaluations": int(result.nfev)}
    finally:
        follow.close()
    if feasible or (diverged and math.isfinite(ise)):
        vector = np.asarray(result.x)
        b = [follow.weight(vector)] * config.n_loops
        tf = design.filters(vector[:-1])
        return found, (vector, design.gains(vector[:-1]), (b, list(design.c), tf))
    if not diverged:
        return {**found, "source": None}, None
    gains = first.gains.values()
    _, c, tf = first.structure
    weight, rows = setpoint_weight(config, gains, first.structure, seeds, deploy.max_overshoot)
    best = next(r for r in rows if r["b"] == weight)
    if not math.isfinite(best["ISE"]):
        return {**found, "source": None}, None
    found = {**found, "source": "stabilising PID", "load_cost": design.load_cost(gains, list(tf)), "ISE": best["ISE"],
             "Overshoot": best["Overshoot"], "feasible": best["Overshoot"] <= 100.0 * deploy.max_overshoot}
    return found, (np.asarray(first.action), gains, ([weight] * config.n_loops, list(c), list(tf)))


def _cost_of(gains: tuple, core: LoopCore, seeds: list[int]) -> float:
    return sum(episode_cost(gains_rollout(lambda c: gains, core.config, seed=s, core=core), core)
               for s in seeds) / len(seeds)
