"""The fixed PID's design rule: its requirements in order of priority, in one place.

baseline.objective "load" (the default) keeps, in this order:

1. a stabilising loop that follows and settles the setpoint steps: on the range episode (`range_schedule`: noise
   free, the low, middle and high setpoint of robustness.margins.setpoint_range_points visited by every step between
   them, low -> middle -> high and back, each held RANGE_HOLD x training.setpoint_hold_steps samples), no
   divergence and every step inside the 2 % band to the end of its hold (metrics.compute_metrics' SettlingTime);
   a step that settles only after setpoint_hold_steps is *slow*, not unsettled; and its command does not chatter:
   metrics.fast_reversals (the acceptance check's chatter) at most CHATTER_MARGIN x deploy.max_chatter on the
   full-range episodes (tuning.full_range: every step from one end of the setpoint range to the other) and
   CHATTER_EPISODES quiet training episodes (`quiet_command`; the margin because the acceptance check replays
   other episodes), else the gains are detuned together (Kp / lambda, Ti and Td x lambda) until it is: a loop that
   rings at the sample rate after a large step (a saturating or strongly nonlinear plant, which the linear Ms at
   the operating points does not see) is slowed, not deployed;
2. Ms <= deploy.max_sensitivity at every operating point and parameter draw (the load search's Kp interval, then
   the check on the FMU, tuning.fixed_pid.detune_over);
3. overshoot <= deploy.max_overshoot (the setpoint weight b, then, where no b meets it, gains traded for it within
   the load tolerance, or where none is within it, the gains nearest the tolerance that meet the limit);
4. load IAE <= baseline.load_tolerance x the load optimum (tuning.load_experiment; tuning.load_design's search);
5. among those, the least setpoint ISE (tuning.load_design.SetpointDesign): where the load search used the
   identified local models, over the gains and b within the load tolerance, and, where one loop's plant has a
   SIMC/AMIGO model, with load IAE no worse than those rules reach at the same Ms (tuning.classical_rules), searched
   on the models and verified on the FMU (`_on_models`); else b alone where it meets the overshoot limit (a search of
   the gains there costs a differential evolution of FMU setpoint episodes);
6. std(u) <= deploy.max_noise_gain and std(u_k - u_(k-1)) <= deploy.max_noise_increment from the measurement
   noise, fractions of the control span: preferences.

`design_under` runs requirements 2-6 at given noise limits (`NoiseLimits`). Where its result does not meet 1 and
a noise limit held it (its estimate within 1 % of the limit: LoadDesign.active_limits), the noise limits are relaxed
before they may cost following: first a measurement filter (the filter searched, where controller.measurement_filter
is not "tuned"), then the limits that held it x RELAX_FACTORS in turn, up to none; the first design that meets 1
ends it. Where none does, the stabilising PID the plant was measured with (the setpoint search's, made robust to the
Ms limit, with its best b) is a candidate too. Of the candidates the rule keeps the one first in `priority` (no divergence, fewest unsettled
steps, Ms met, overshoot met, load within tolerance, least setpoint ISE, least relaxed): a candidate that diverges or
leaves a step unsettled is never kept over one that settles. The result is a `DesignResult`; fixed_pid.json is
written from it by run.tune.


baseline.objective "setpoint" is tuning.fixed_pid's setpoint search alone.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from prlpid_fmi.config import BaselineConfig, DeployConfig, TuningConfig
from prlpid_fmi.loop.core import pid_structure
from prlpid_fmi.loop.evaluation import command_chatter, gains_rollout
from prlpid_fmi.loop.gains import GainValues, gains_from_values
from prlpid_fmi.metrics import compute_metrics
from prlpid_fmi.progress import QUIET, Steps
from prlpid_fmi.robustness.margins import margins_of, setpoint_range_points
from prlpid_fmi.robustness.status import meets_limit
from prlpid_fmi.tuning.classical_rules import load_bound
from prlpid_fmi.tuning.design_result import (CandidateRecord, ChatterCheck, DesignDetails, DesignReport, DesignResult,
                                             Followed, Following, ModelPath, ModelSearch, Relaxation, Requirement,
                                             Trade)
from prlpid_fmi.tuning.fixed_pid import (DETUNE_STEP, FixedPid, detune_over, detuned, robust_setpoint_pid,
                                         setpoint_pid)
from prlpid_fmi.tuning.full_range import full_range_episodes, quiet
from prlpid_fmi.tuning.load_design import (MODEL_TOLERANCE, SETPOINT_MODEL_MINIMUM, LoadDesign, SetpointDesign,
                                           model_budget, setpoint_weight)
from prlpid_fmi.tuning.load_experiment import DIVERGED_COST, approach, open_core, parameter_samples, start_measurement
from prlpid_fmi.tuning.search_pool import search_workers

RANGE_HOLD = 4  # the range episode holds each setpoint this many x training.setpoint_hold_steps samples
RANGE_ORDER = (0, 1, 2, 1, 0)  # indices into (low, middle, high): up and down the range between neighbours (a
# low -> high jump saturates the reactor's jacket and ignites it with PIDs that hold its 10 K steps)
SETTLING_BAND = 0.02  # a step is settled when |r - y| stays within this fraction of the step to the end of its hold
RELAX_FACTORS = (2.0, 5.0, math.inf)  # factors on a noise limit the relaxation tries, in turn
STABILISING_GENERATIONS = 6  # generations of the setpoint search that finds the PID the plant is measured with
MEASURING_MS_FACTOR = 1.5  # ... whose Ms may reach this x deploy.max_sensitivity: its measurements need a settled,
# verified loop, not a deployable one (a lightly damped loop fails as unsettled there)
CHATTER_MARGIN = 0.8  # the design holds the command's chatter to this x deploy.max_chatter (the acceptance's limit)
CHATTER_EPISODES = 8  # quiet random training episodes of the chatter check, besides the two full-range ones
CHATTER_DETUNINGS = 16  # the chatter check tries lambda = DETUNE_STEP**k for k = 1 .. this (up to 9.4)


# -- typed results ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class NoiseLimits:
    """std(u) and std(u_k - u_(k-1)) from the measurement noise, fractions of the control span (inf: none), and
    whether the measurement filter Tf is searched."""

    gain: float
    increment: float
    filter_tuned: bool


@dataclass
class Candidate:
    """A design under one set of noise limits (or the stabilising PID): what `priority` orders."""

    vector: np.ndarray
    gains: GainValues
    structure: tuple
    details: DesignDetails
    limits: NoiseLimits
    relaxed: tuple
    ms_met: bool
    overshoot: float  # worst on the training episodes b was chosen on [%]
    ise: float  # setpoint ISE of those episodes
    load_cost: float
    following: Following | None = None


# -- requirement 1: the range episode -----------------------------------------------------------------------------
def range_schedule(config: TuningConfig, start: list[float] | None) -> tuple[tuple, int]:
    """((step, setpoints), ...) of the range episode and its hold [samples]: a ramp from the FMU's start to the low
    setpoint over the first hold (tuning.load_experiment.approach), then the setpoints of RANGE_ORDER, each held."""
    hold = RANGE_HOLD * config.setpoint_hold_steps
    points = setpoint_range_points(config)
    points = [points[0], points[len(points) // 2], points[-1]]
    schedule = list(approach(start, points[0], hold))
    for j, index in enumerate(RANGE_ORDER[1:]):
        schedule.append(((j + 1) * hold, tuple(float(v) for v in points[index])))
    return tuple(schedule), hold


def following(config: TuningConfig, gains: GainValues, structure: tuple) -> Following:
    """Requirement 1 (module docstring) of constant gains with structure (b, c, Tf) on the range episode."""
    start = start_measurement(config)
    schedule, hold = range_schedule(config, start)
    quiet = dataclasses.replace(config, measurement_noise_std=0.0, actuator_noise_std=0.0, forecast_horizon=0,
                                load_disturbance=0.0, disturbances=(), randomize={}, setpoint_schedule=schedule,
                                episode_steps=hold * len(RANGE_ORDER))
    core = open_core(quiet)
    try:
        core.set_structure(*structure)
        traj = gains_rollout(lambda c: gains, quiet, seed=0, core=core)
    finally:
        core.close()
    steps = len(RANGE_ORDER) - 1
    if traj.terminated:
        return Following(steps, steps, 0, True, math.inf, math.inf)
    m = compute_metrics(traj.time_s, traj.setpoint, traj.measurement, traj.control_signal, config.sample_time_s,
                        noise_std=0.0, settling_threshold=SETTLING_BAND)
    segments = [s for s in m["segments"] if s["start_step"] >= hold and math.isfinite(s.get("StepSize", math.nan))
                and s["StepSize"] != 0 and not math.isnan(s["SettlingTime"])]
    unsettled = sum(1 for s in segments if not math.isfinite(s["SettlingTime"]))
    slow = sum(1 for s in segments if math.isfinite(s["SettlingTime"])
               and s["SettlingTime"] > config.setpoint_hold_steps * config.sample_time_s)
    overshoot = max((s["Overshoot"] for s in segments if not math.isnan(s["Overshoot"])), default=0.0)
    r, y = traj.setpoint[hold:], traj.measurement[hold:]
    ise = float(np.sum((r - y) ** 2) * config.sample_time_s)
    return Following(len(segments), unsettled, slow, False, float(overshoot), ise)


def quiet_command(config: TuningConfig, gains: GainValues, structure: tuple, max_chatter: float, seed: int
                  ) -> tuple[ChatterCheck, GainValues]:
    """Requirement 1's chatter (module docstring): the worst metrics.fast_reversals of the PID's command on the
    full-range episodes (tuning.full_range) and CHATTER_EPISODES quiet training episodes (random setpoints, no load
    steps or noise; seeds seed + i; an episode that diverges counts in the range episode's following, not here).
    Above CHATTER_MARGIN x max_chatter the gains are detuned together (Kp / lambda, Ti and Td x lambda, lambda =
    DETUNE_STEP**k, k = 1 .. CHATTER_DETUNINGS: the same controller on a slower time axis, so the setpoint response
    b was chosen for keeps its shape) to the first k that meets it; where none does, the gains stay (the acceptance
    check then says so). Ms is not measured again here: the deliverable rule measures the result's. Returns (the
    check's record, the gains)."""
    target = CHATTER_MARGIN * max_chatter
    config = dataclasses.replace(config, forecast_horizon=0)
    episodes = [(c, s) for _, c, s in full_range_episodes(config, seed)]
    episodes += [(quiet(config), seed + i) for i in range(CHATTER_EPISODES)]
    cores = {}
    try:
        def worst(g: GainValues) -> float:
            found = []
            for c, s in episodes:
                if id(c) not in cores:
                    cores[id(c)] = open_core(c)
                    cores[id(c)].set_structure(*structure)
                traj = gains_rollout(lambda _: g, c, seed=s, core=cores[id(c)])
                found.append(math.nan if traj.terminated else command_chatter(traj, c))  # diverging: requirement 1
            return max((x for x in found if not math.isnan(x)), default=math.nan)

        before = worst(gains)
        if not before > target:
            return ChatterCheck(before, target, episodes=len(episodes)), gains
        for k in range(1, CHATTER_DETUNINGS + 1):
            slower = detuned(config, gains, k, keep_ti=False)
            after = worst(slower)
            if after <= target:
                return ChatterCheck(before, target, DETUNE_STEP ** k, after, len(episodes)), slower
        return ChatterCheck(before, target, episodes=len(episodes)), gains
    finally:
        for core in cores.values():
            core.close()


def priority(candidate: Candidate, deploy: DeployConfig, load_limit: float) -> tuple:
    """The rule's order (module docstring) as a sort key: smaller is kept."""
    f = candidate.following
    over = max(0.0, candidate.overshoot - 100.0 * deploy.max_overshoot) if math.isfinite(candidate.overshoot) else \
        math.inf
    load = max(0.0, candidate.load_cost - load_limit)
    return (f.diverged, f.unsettled, not candidate.ms_met, over, load,
            candidate.ise if math.isfinite(candidate.ise) else math.inf, len(candidate.relaxed))


# -- requirements 2-6 at given noise limits -----------------------------------------------------------------------
class Designer:
    """The load design's measurements, made once (the stabilising PID, the plant responses), and `design_under`
    for any noise limits. Close with `close()`."""

    def __init__(self, config: TuningConfig, seed: int, episodes: int, maxiter: int, popsize: int, progress: Steps,
                 max_sensitivity: float | None, baseline: BaselineConfig, deploy: DeployConfig):
        self.config, self.seed, self.maxiter, self.popsize = config, seed, maxiter, popsize
        self.episodes, self.progress, self.limit = episodes, progress, max_sensitivity
        self.baseline, self.deploy = baseline, deploy
        self.seeds = [seed + i for i in range(episodes)]
        # its Ms checked and detuned as the setpoint search does, to MEASURING_MS_FACTOR x the limit: a lightly damped
        # loop does not settle in the frequency-response experiment, and an unverified response gives the design no
        # constraint; where it becomes a candidate itself, it is made robust to the limit then (`robust_first`)
        self.first = setpoint_pid(config, seed, episodes, STABILISING_GENERATIONS, popsize, progress,
                                  None if max_sensitivity is None else MEASURING_MS_FACTOR * max_sensitivity,
                                  name="stabilising PID (setpoint search)", workers=baseline.workers)
        self._robust_first: FixedPid | None = None
        self.measured: dict | None = None
        self.evaluations = self.first.evaluations
        self.load_optimum: float | None = None
        self.model_record = ModelPath()  # the last load search's path (LoadDesign.search_verified)

    def design_under(self, limits: NoiseLimits, relaxed: tuple = ()) -> Candidate:
        """Requirements 2-6 at these noise limits: the load search (Ms and noise by the Kp interval), b for the
        overshoot, the trade within the load tolerance where no b meets it, the search without the load limit where
        that fails too, and the Ms check on the FMU."""
        config, baseline, progress = self.config, self.baseline, self.progress
        if limits.filter_tuned != (config.measurement_filter == "tuned"):
            config = dataclasses.replace(config, measurement_filter="tuned")
        design = LoadDesign(config, baseline.load_step, self.limit, limits.gain, baseline.widen_ranges,
                            limits.increment, search_workers(baseline.workers), baseline.design_model)
        try:
            progress.step(f"frequency response of the plant at {len(design.points)} operating points"
                          + (f" and {len(parameter_samples(config))} parameter draws" if parameter_samples(config)
                             else ""))
            design.prepare(self.first.gains.values(), measured=self.measured)
            self.measured = design.measured()
            result, self.model_record = design.search_verified(self.seed, self.maxiter, self.popsize, progress)
            self.evaluations += int(result.nfev)
            return self._finish(config, design, result, limits, relaxed)
        finally:
            design.close()

    def _finish(self, config, design: LoadDesign, result, limits: NoiseLimits, relaxed: tuple) -> Candidate:
        """Requirements 3-5 and the Ms check after the load search (design_under)."""
        deploy, baseline, progress, seeds = self.deploy, self.baseline, self.progress, self.seeds
        maxiter, popsize, seed = self.maxiter, self.popsize, self.seed
        vector = np.asarray(result.x)
        gains, tf = design.gains(vector), design.filters(vector)
        best_load = float(result.fun)
        if self.load_optimum is None:
            self.load_optimum = best_load  # the load optimum at the requested limits: what the tolerance is of
        b, c, _ = pid_structure(config)
        choices, traded, followed, refined = [], None, None, None
        if config.setpoint_weight == "tuned":
            progress.step("setpoint weight b")
            weight, choices = setpoint_weight(config, gains, (b, c, tf), seeds, deploy.max_overshoot)
            b = [weight] * config.n_loops
            if not any(r["Overshoot"] <= 100.0 * deploy.max_overshoot for r in choices):
                traded, second = self._trade(config, design, vector, weight, best_load, (b, c, tf))
                # the load tolerance (requirement 4) missed, every limit above it met: the gains nearest the
                # tolerance that meet the overshoot limit are kept (the search ranks by violation)
                if traded.feasible or traded.nearest_load_tolerance:  # else the load optimum stays, with the
                    # b of least overshoot
                    vector = second
                    gains, tf = design.gains(vector[:-1]), design.filters(vector[:-1])
                    b = [SetpointDesign.weight(vector)] * config.n_loops
            elif design.models is not None and 1.0 < baseline.load_tolerance < math.inf:
                before = next(r for r in choices if r["b"] == weight)["ISE"]
                refined, found = self._on_models(config, design, vector, weight, best_load, (b, c, tf), before)
                if found is not None:
                    vector, choices = found
                    gains, tf = design.gains(vector[:-1]), design.filters(vector[:-1])
                    b = [SetpointDesign.weight(vector)] * config.n_loops
            if traded is not None and not traded.feasible and not traded.nearest_load_tolerance:
                followed, found = follow_setpoints(config, design, self.robust_first, best_load, deploy, seeds, seed,
                                                   maxiter, popsize, progress,
                                                   diverged=not follows_setpoints(choices, traded))
                if found is not None:
                    vector, gains, (b, c, tf) = found
        structure = (b, c, tf)
        ms_met, fallback = True, None
        if self.limit is not None:
            tuned = dataclasses.replace(design.search_config, tuned_structure=tuple(zip(b, c, tf)))
            points = setpoint_range_points(config)
            progress.step(f"Ms check on the FMU ({len(points)} operating points"
                          + (", parameter draws" if parameter_samples(config) else "") + "; detuned where one fails)")
            repaired = detune_over(tuned, gains, points, self.limit, draws=parameter_samples(tuned))
            if repaired is None:  # the design's estimate misled it (coupled loops, a nonlinear plant): the setpoint
                # search's robust PID rather than an undeployable one
                fallback = setpoint_pid(config, seed, self.episodes, maxiter, popsize, progress, self.limit,
                                        name="setpoint search (the load design could not meet the Ms limit)",
                                        workers=baseline.workers)
                gains, structure = fallback.gains.values(), fallback.structure
                tf = list(structure[2])
            else:
                detuned, gains = repaired != gains, repaired
                cost = design.load_cost(gains, tf)
                if detuned and cost > baseline.load_tolerance * best_load:
                    # the check on the FMU cost more load rejection than the design may give up: the setpoint
                    # search's robust PID when it rejects loads better
                    alternative = setpoint_pid(config, seed, self.episodes, maxiter, popsize, progress, self.limit,
                                               name="setpoint search (the Ms check detuned the load design)",
                                               workers=baseline.workers)
                    if design.load_cost(alternative.gains.values(), list(alternative.structure[2])) < cost:
                        fallback = alternative
                        gains, structure = fallback.gains.values(), fallback.structure
                        tf = list(structure[2])
            if fallback is not None:  # the setpoint search keeps its best member even where nothing meets the limit
                checked = dataclasses.replace(config, tuned_structure=tuple(zip(*structure)))
                ms_met = all(meets_limit(margins_of(plant, gains, p), self.limit)
                             for plant in (checked, *parameter_samples(checked)) for p in points)
        progress.step("the command's chatter on the full-range and quiet training episodes (requirement 1)")
        chatter, gains = quiet_command(design.search_config, gains, structure, deploy.max_chatter, seed)
        cost = design.load_cost(gains, tf)
        ise, overshoot = self._setpoint_response(config, gains, structure)
        details = DesignDetails(
            load_cost=cost, load_optimum=self.load_optimum, load_step=baseline.load_step, traded_for_overshoot=traded,
            followed_setpoints=followed, setpoint_refined=refined, estimates=design.estimates(gains, tf),
            active_limits=design.active_limits(gains, tf), setpoint_weights=choices,
            stabilising_gains=self.first.gains.as_dict(),
            feasible=bool(getattr(result, "constr_violation", 0) <= 0),
            fell_back_to_setpoint_search=fallback is not None,
            noise_increment_limit_relaxed=design.increment_relaxed, noise=noise_shares(design, gains, tf),
            design_model=self.model_record, chatter=chatter)
        if design.increment_relaxed:  # no Kp met it with Ms for the stabilising PID's Ti, Td (LoadDesign.prepare)
            relaxed = tuple(r for r in relaxed if r.limit != "max_noise_increment") + (
                Relaxation("max_noise_increment", self.deploy.max_noise_increment, math.inf),)
        return Candidate(vector, gains, structure, details, limits, relaxed, ms_met, overshoot, ise, cost)

    def _trade(self, config: TuningConfig, design: LoadDesign, vector, weight: float, best_load: float,
               structure: tuple) -> tuple[Trade, np.ndarray]:
        """The setpoint search within the load tolerance (SetpointDesign) from the load optimum with b = weight:
        (what it found, a Trade: feasible, or nearest_load_tolerance where every limit but the load tolerance is
        met; its vector). Where the load search used the local models, the search runs on them first (`_on_models`:
        setpoint steps and load cost on the models, verified on the FMU); where the FMU does
        not confirm it, it runs with the setpoint responses on the FMU, its load cost still on the models (its load
        limit the models' optimum's) and its result's load IAE verified on the FMU (Trade.load_cost the FMU's,
        load_cost_model, validation_error); where the two differ by more than MODEL_TOLERANCE, the search runs
        again on the FMU (ModelPath.setpoint_search)."""
        baseline, deploy, seed = self.baseline, self.deploy, self.seed
        record = None
        if design.models is not None:
            record, found = self._on_models(config, design, vector, weight, best_load, structure, math.inf)
            if found is not None:
                self.model_record.setpoint_search = "identified"
                feasible = record.load_cost <= baseline.load_tolerance * best_load
                return Trade(record.load_cost, record.ISE, record.Overshoot, feasible, not feasible,
                             record.evaluations, on_models=record), found[0]
        while True:
            on_models = design.models is not None
            reference = self.model_record.predicted_load_cost if on_models else best_load
            trade = SetpointDesign(design, reference, baseline.load_tolerance, deploy.max_overshoot, self.seeds)
            self.progress.step("setpoint ISE within the overshoot limit (no b met it)"
                               + (" on the local models' load cost" if on_models else ""),
                               trade.budget(self.maxiter, self.popsize))
            try:
                second = trade.search(np.append(vector, 2.0 * weight - 1.0), seed, self.maxiter, self.popsize,
                                      progress=self.progress)
                values = trade.constraint_values(second.x)
                feasible = bool(np.max(values) <= 0)
                nearest = not feasible and bool(np.max(np.delete(values, -2)) <= 0)  # only the load limit missed
                load, ise, overshoot = trade.evaluate(second.x)
            finally:
                trade.close()
            self.evaluations += int(second.nfev)
            found = Trade(load, ise, overshoot, feasible, nearest, int(second.nfev), on_models=record)
            if not on_models:
                if self.model_record.setpoint_search is None:
                    self.model_record.setpoint_search = "fmu"
                return found, np.asarray(second.x)
            x = np.asarray(second.x)
            measured = design.load_cost(design.gains(x[:-1]), design.filters(x[:-1]))
            error = abs(measured - load) / measured if measured > 0 else math.inf
            found = dataclasses.replace(found, load_cost=measured, load_cost_model=load, validation_error=error)
            if error <= MODEL_TOLERANCE or min(measured, load) >= DIVERGED_COST:  # both diverge: the models agree
                self.model_record.setpoint_search = "identified"
                return found, x
            self.model_record.setpoint_search = "fmu"
            self.model_record.setpoint_search_note = (
                f"the setpoint search's result has load cost {measured:.4g} on the FMU, {load:.4g} on the models "
                f"({100 * error:.1f} % apart, tolerance {100 * MODEL_TOLERANCE:.0f} %): that search ran again on the FMU")
            design.use_fmu()

    def _on_models(self, config: TuningConfig, design: LoadDesign, vector, weight: float, best_load: float,
                   structure: tuple, ise_to_beat: float) -> tuple[ModelSearch, tuple | None]:
        """Requirements 3-5 on the local models (the load search used them): the least setpoint ISE within the load
        tolerance and the overshoot limit, searched on the models (SetpointDesign with on_models: a unit step, from the
        load optimum with b = weight; tuning.load_design.model_budget's generations and population, at least
        SETPOINT_MODEL_MINIMUM), then verified on the FMU: b
        chosen again on the training episodes (`setpoint_weight`), kept only where its overshoot is within the limit,
        its ISE below `ise_to_beat` (the optimum's with its b) and the FMU's load cost within the tolerance of the
        optimum's, and, replacing an optimum that met the limits, where it settles the range episode (requirement 1).
        ise_to_beat inf: no b met the overshoot limit with the optimum; then where no gains on the models meet the
        load tolerance with the overshoot limit, those nearest it that meet every other limit (the search ranks by
        violation) are verified and kept the same way, the load tolerance given up (requirement 3 ranks above 4).
        Returns (the ModelSearch of DesignDetails.setpoint_refined or Trade.on_models, (vector with b, the b table)
        or None)."""
        baseline, deploy, seeds, progress = self.baseline, self.deploy, self.seeds, self.progress
        trading = not math.isfinite(ise_to_beat)  # no b met the overshoot limit: the load tolerance may yield to it
        bound = None if trading or config.n_loops > 1 else self._rule_bound(design, design.filters(vector))
        trade = SetpointDesign(design, self.model_record.predicted_load_cost, baseline.load_tolerance,
                               deploy.max_overshoot, seeds, on_models=True, rule_bound=bound)
        maxiter, popsize = model_budget(self.maxiter, self.popsize, SETPOINT_MODEL_MINIMUM)
        progress.step("least setpoint ISE within the load tolerance on the local models", trade.budget(maxiter, popsize))
        try:
            second = trade.search(np.append(vector, 2.0 * weight - 1.0), self.seed, maxiter, popsize, progress=progress)
            values = trade.constraint_values(second.x)
            feasible = bool(np.max(values) <= 0)
            nearest = not feasible and bool(np.max(np.delete(values, -2)) <= 0)  # only the load limit missed
            model_load, model_ise, model_overshoot = trade.evaluate(second.x)
            start_ise = trade.evaluate(np.append(vector, 2.0 * weight - 1.0))[1]
        finally:
            trade.close()
        self.evaluations += int(second.nfev)
        record = ModelSearch(int(second.nfev), model_load, model_overshoot, feasible,
                             model_ise_ratio=model_ise / start_ise if start_ise > 0 else None,
                             nearest_on_models=nearest,
                             ISE_before=ise_to_beat if math.isfinite(ise_to_beat) else None,
                             classical_bound=bound is not None)
        if not (feasible or (trading and nearest)) or not (trading or model_ise <= start_ise):
            return record, None
        x = np.asarray(second.x)
        gains, tf = design.gains(x[:-1]), design.filters(x[:-1])
        progress.step("the refined gains' b and load cost verified on the FMU")
        load = design.load_cost(gains, tf)
        b, rows = setpoint_weight(config, gains, (structure[0], structure[1], tf), seeds, deploy.max_overshoot)
        row = next(r for r in rows if r["b"] == b)
        record.load_cost, record.ISE, record.Overshoot, record.b = load, row["ISE"], row["Overshoot"], b
        if not ((trading or load <= baseline.load_tolerance * best_load) and row["ISE"] < ise_to_beat
                and row["Overshoot"] <= 100.0 * deploy.max_overshoot):
            return record, None
        if not trading:  # replacing gains that met every limit: only by gains that settle the range
            record.settles_range = following(config, gains, ([b] * config.n_loops, structure[1], tf)).settles
            if not record.settles_range:
                return record, None
        record.kept = True
        return record, (np.append(x[:-1], 2.0 * b - 1.0), rows)

    @staticmethod
    def _rule_bound(design: LoadDesign, tf: list[float]):
        """Ms -> the load cost that SIMC or AMIGO reach at that Ms on the design's local models (tuning.
        classical_rules, the rules from the middle operating point's model, with measurement filter tf and within the
        noise limits), or None where no rule applies (unstable, oscillatory)."""
        def assess(pid: tuple[float, float, float]):
            gains = GainValues([pid[0]], [pid[1]], [pid[2]])
            if not design.meets_noise_limits(gains, tf):
                return None
            load = design.model_load_response(gains, tf)[0]
            return None if load >= DIVERGED_COST else (design.limit_values(gains, tf)[0], load)
        return load_bound(design.models[len(design.models) // 2][0], assess)

    def _setpoint_response(self, config: TuningConfig, gains: GainValues, structure: tuple) -> tuple[float, float]:
        """(ISE, worst overshoot [%]) of the training episodes the design chose b on (noise free)."""
        b, c, tf = structure
        weight, rows = setpoint_weight(config, gains, ([b[0]] * config.n_loops, c, tf), self.seeds,
                                       self.deploy.max_overshoot, grid=(float(b[0]),))
        return rows[0]["ISE"], rows[0]["Overshoot"]

    def robust_first(self) -> FixedPid:
        """The stabilising PID made robust to the Ms limit (tuning.fixed_pid.robust_setpoint_pid), once: what a
        candidate or fallback built from it deploys."""
        if self._robust_first is None:
            self._robust_first = self.first if self.limit is None else \
                robust_setpoint_pid(self.config, self.first, self.seeds, self.limit)
        return self._robust_first

    def stabilising(self, limits: NoiseLimits) -> Candidate:
        """The stabilising PID (robust to the Ms limit: `robust_first`) with its best b (setpoint_weight) as a
        candidate."""
        config, first = self.config, self.robust_first()
        gains = first.gains.values()
        _, c, tf = first.structure
        loader = LoadDesign(config, self.baseline.load_step, self.limit, math.inf, self.baseline.widen_ranges)
        try:
            loader.prepare(gains, measured=self.measured)
            load = loader.load_cost(gains, list(tf))
        finally:
            loader.close()
        weight, rows = setpoint_weight(config, gains, first.structure, self.seeds, self.deploy.max_overshoot)
        best = next(r for r in rows if r["b"] == weight)
        structure = ([weight] * config.n_loops, list(c), list(tf))
        details = DesignDetails(
            load_cost=load, load_optimum=self.load_optimum, load_step=self.baseline.load_step,
            followed_setpoints=Followed("stabilising PID", load_optimal_diverged=True, load_cost=load, ISE=best["ISE"],
                                        Overshoot=best["Overshoot"],
                                        feasible=best["Overshoot"] <= 100.0 * self.deploy.max_overshoot),
            setpoint_weights=rows, stabilising_gains=first.gains.as_dict(), design_model=self.model_record)
        return Candidate(np.asarray(first.action), gains, structure, details, limits, (), True, best["Overshoot"],
                         best["ISE"], details.load_cost)


def noise_shares(design: LoadDesign, gains: GainValues, tf: list[float]) -> dict:
    """{"std_u", "std_du"}: the largest std(u) and std(u_k - u_(k-1)) from the measurement noise over the nominal
    points and loops, fractions of the control span, estimated from the measured plant responses (0 without noise,
    None where nothing was measured)."""
    sigma = design.config.measurement_noise_std
    if not sigma > 0:
        return {"std_u": 0.0, "std_du": 0.0}
    std_u, std_du, seen = 0.0, 0.0, False
    for plants in design.plants[:len(design.points)]:
        for i, plant in enumerate(plants or ()):
            u, du = plant.noise_gains(design.controller(gains, tf, i))
            std_u, std_du = max(std_u, sigma * u / design.spans[i]), max(std_du, sigma * du / design.spans[i])
            seen = True
    return {"std_u": std_u, "std_du": std_du} if seen else {"std_u": None, "std_du": None}


def relaxations(config: TuningConfig, deploy: DeployConfig, held: set[str]) -> list[tuple[NoiseLimits, tuple]]:
    """The relaxation ladder (module docstring): (limits, what they relax) in turn, the filter first."""
    filter_tuned = config.measurement_filter == "tuned"
    ladder, given = [], []
    if not filter_tuned:
        filter_tuned = True
        given = [Relaxation("measurement_filter", 0.0, 1.0)]
        ladder.append((NoiseLimits(deploy.max_noise_gain, deploy.max_noise_increment, True), tuple(given)))
    names = [n for n in ("max_noise_gain", "max_noise_increment") if n in held] or \
        ["max_noise_gain", "max_noise_increment"]
    requested = {"max_noise_gain": deploy.max_noise_gain, "max_noise_increment": deploy.max_noise_increment}
    names = [n for n in names if math.isfinite(requested[n])]
    for factor in RELAX_FACTORS if names else ():
        used = {n: requested[n] * factor if n in names else requested[n] for n in requested}
        ladder.append((NoiseLimits(used["max_noise_gain"], used["max_noise_increment"], filter_tuned),
                       tuple(given) + tuple(Relaxation(n, requested[n], used[n]) for n in names)))
    return ladder


def requirements(candidate: Candidate, deploy: DeployConfig, max_sensitivity: float | None,
                 load_tolerance: float) -> tuple[Requirement, ...]:
    """Each requirement's measured value (module docstring's numbering; noise against the limits requested)."""
    f, d = candidate.following, candidate.details
    ms = [e["Ms"] for e in d.estimates if e.get("Ms") is not None]
    ratio = d.load_cost / d.load_optimum if d.load_optimum else math.nan
    noise = d.noise or {}
    out = [Requirement(1, "follows and settles the setpoint steps", float(f.unsettled), 0.0, bool(f.settles)),
           Requirement(2, "Ms", float(max(ms)) if ms else math.nan, max_sensitivity, bool(candidate.ms_met)),
           Requirement(3, "overshoot [%]", float(candidate.overshoot), 100.0 * deploy.max_overshoot,
                       bool(candidate.overshoot <= 100.0 * deploy.max_overshoot)),
           Requirement(4, "load IAE / load optimum", float(ratio), load_tolerance,
                       bool(not ratio > load_tolerance * (1.0 + 1e-9))),
           Requirement(5, "setpoint ISE", float(candidate.ise), None, bool(math.isfinite(candidate.ise)))]
    for name, key, limit in (("std(u) / span", "std_u", deploy.max_noise_gain),
                             ("std(u_k - u_(k-1)) / span", "std_du", deploy.max_noise_increment)):
        value = noise.get(key)
        value = math.nan if value is None else float(value)
        out.append(Requirement(6, name, value, limit, bool(not value > limit * (1.0 + 1e-9))))
    chatter = d.chatter
    if chatter is not None:  # requirement 1's chatter, last so that the positions above stay (bound_by)
        worst = chatter.after if math.isfinite(chatter.after) else chatter.before
        out.append(Requirement(1, "command chatter on quiet episodes", float(worst), chatter.target, chatter.met))
    return tuple(out)


def bound_by(candidate: Candidate, reqs: tuple[Requirement, ...]) -> str:
    """The requirement that bound the design: the first one not met; else requirement 1 where a noise limit was
    relaxed for it; else the first requirement whose limit is active (2: Ms at its limit, 3: gains traded for the
    overshoot, 6: a noise limit held the design); else 4 (the load optimum)."""
    failed = sorted((r for r in reqs if not r.met and r.rank != 5), key=lambda r: r.rank)
    if failed:
        return failed[0].name
    if candidate.relaxed:
        return reqs[0].name
    d = candidate.details
    active = d.held_by
    if "max_sensitivity" in active:
        return reqs[1].name
    traded = d.traded_for_overshoot
    if (traded and traded.feasible) or (d.followed_setpoints and d.followed_setpoints.source):
        return reqs[2].name
    if active & {"max_noise_gain", "max_noise_increment"}:
        return reqs[5].name if "max_noise_gain" in active else reqs[6].name
    return reqs[3].name


def design_load_pid(config: TuningConfig, seed: int, episodes: int, maxiter: int, popsize: int, progress: Steps,
                    max_sensitivity: float | None, baseline: BaselineConfig, deploy: DeployConfig) -> DesignResult:
    """The rule of the module docstring."""
    designer = Designer(config, seed, episodes, maxiter, popsize, progress, max_sensitivity, baseline, deploy)
    requested = NoiseLimits(deploy.max_noise_gain, deploy.max_noise_increment, config.measurement_filter == "tuned")
    candidates = [designer.design_under(requested)]
    progress.step("setpoint steps across the setpoint range (requirement 1)")
    candidates[0].following = following(config, candidates[0].gains, candidates[0].structure)
    held = candidates[0].details.held_by & {"max_noise_gain", "max_noise_increment"}
    if not candidates[0].following.settles and config.measurement_noise_std > 0 and held:
        for limits, relaxed in relaxations(config, deploy, held):
            candidate = designer.design_under(limits, relaxed)
            candidate.following = following(config, candidate.gains, candidate.structure)
            candidates.append(candidate)
            if candidate.following.settles:
                break
    load_limit = baseline.load_tolerance * designer.load_optimum
    if not any(c.following.settles for c in candidates):
        candidate = designer.stabilising(requested)
        candidate.following = following(config, candidate.gains, candidate.structure)
        candidates.append(candidate)
    kept = min(candidates, key=lambda c: priority(c, deploy, load_limit))
    reqs = requirements(kept, deploy, max_sensitivity, baseline.load_tolerance)
    details = dataclasses.replace(kept.details, candidates=tuple(
        CandidateRecord(tuple(c.relaxed), c.following, float(c.load_cost), float(c.ise), float(c.overshoot),
                        bool(c.ms_met), gains_from_values(*c.gains), c is kept) for c in candidates))
    report = DesignReport(bound_by(kept, reqs), tuple(kept.relaxed), reqs, kept.following, details)
    return DesignResult(kept.vector, gains_from_values(*kept.gains), kept.load_cost, designer.evaluations,
                        kept.structure, report)


def tune_fixed_pid(config: TuningConfig, seed: int = 0, episodes: int | None = None, maxiter: int | None = None,
                   popsize: int | None = None, progress: Steps = QUIET, max_sensitivity: float | None = None,
                   baseline: BaselineConfig = BaselineConfig(), deploy: DeployConfig = DeployConfig()) -> DesignResult:
    """The fixed PID of baseline.objective: "load" (the rule of the module docstring) or "setpoint" (tuning.fixed_pid's
    setpoint search over `episodes` seeded training episodes).

    progress: a prlpid_fmi.progress.Steps the searches show their steps on. max_sensitivity: the Ms limit (None: no
    robustness requirement). baseline: objective, load_step, load_tolerance, widen_ranges, and the budget (episodes,
    maxiter, popsize) where those arguments are None; deploy: max_overshoot, max_noise_gain, max_noise_increment.
    """
    episodes = baseline.episodes if episodes is None else episodes
    maxiter = baseline.maxiter if maxiter is None else maxiter
    popsize = baseline.popsize if popsize is None else popsize
    if baseline.objective == "load":
        return design_load_pid(config, seed, episodes, maxiter, popsize, progress, max_sensitivity, baseline, deploy)
    found = setpoint_pid(config, seed, episodes, maxiter, popsize, progress, max_sensitivity, workers=baseline.workers)
    return DesignResult(found.action, found.gains, found.cost, found.evaluations, found.structure)


def follows_setpoints(choices: list[dict], traded: Trade | None) -> bool:
    """Whether the gains of the load search follow the training episodes b is chosen on: with some b of
    setpoint_weight's table they did not diverge, or the trade found gains within every limit."""
    return any(math.isfinite(r["ISE"]) for r in choices) or bool(traded and traded.feasible)


def follow_setpoints(config: TuningConfig, design: LoadDesign, first: Callable[[], FixedPid], best_load: float,
                     deploy: DeployConfig, seeds: list[int], seed: int, maxiter: int, popsize: int, progress: Steps,
                     diverged: bool = True) -> tuple[Followed, tuple | None]:
    """Where no gains within the load tolerance met the overshoot limit: the least load cost within the Ms, noise and
    overshoot limits (the rule's order: the overshoot limit before the load tolerance, nearest that), without a load
    limit, searched over the whole box. Its best is kept where it meets every limit, or where the gains of the load
    search diverged on the episodes (`diverged`) and it follows them; where they diverged and it does not follow them
    either, the stabilising PID first() (made robust) with its best setpoint weight. Where the load search used the
    local models the search runs on them first (`_follow_on_models`); its result stands where the FMU confirms it and
    it settles the range episode, else the search runs with the setpoint episodes on the FMU.
    Where the least load IAE leaves a step of the range episode unsettled (requirement 1 ranks first), the least
    setpoint ISE within the same limits is kept if it settles them (objective "setpoint"). Returns (what was
    found, a Followed, (vector, gains, (b, c, Tf)) to keep, or None: the gains stay)."""
    record = None
    if design.models is not None:
        record, kept = _follow_on_models(config, design, best_load, deploy, seeds, seed, maxiter, popsize, progress)
        if kept is not None and following(config, kept[1], kept[2]).settles:
            return Followed("search", "load", diverged, record.load_cost, record.ISE, record.Overshoot, True,
                            record.evaluations, record), kept
        if kept is not None:
            record.kept, record.settles_range = False, False
    args = (config, design, best_load, deploy, seeds, seed, maxiter, popsize, progress, diverged, record)
    found, kept = _follow_on_fmu(*args, objective="load")
    if kept is not None and not following(config, kept[1], kept[2]).settles:
        by_ise, kept_by_ise = _follow_on_fmu(*args, objective="setpoint")
        if kept_by_ise is not None and following(config, kept_by_ise[1], kept_by_ise[2]).settles:
            return by_ise, kept_by_ise
    if kept is not None:
        return found, kept
    if not diverged:
        return dataclasses.replace(found, source=None), None
    first = first()
    gains = first.gains.values()
    _, c, tf = first.structure
    weight, rows = setpoint_weight(config, gains, first.structure, seeds, deploy.max_overshoot)
    best = next(r for r in rows if r["b"] == weight)
    if not math.isfinite(best["ISE"]):
        return dataclasses.replace(found, source=None), None
    found = dataclasses.replace(found, source="stabilising PID", load_cost=design.load_cost(gains, list(tf)),
                                ISE=best["ISE"], Overshoot=best["Overshoot"],
                                feasible=best["Overshoot"] <= 100.0 * deploy.max_overshoot)
    return found, (np.asarray(first.action), gains, ([weight] * config.n_loops, list(c), list(tf)))


def _follow_on_fmu(config: TuningConfig, design: LoadDesign, best_load: float, deploy: DeployConfig, seeds: list[int],
                   seed: int, maxiter: int, popsize: int, progress: Steps, diverged: bool,
                   record: ModelSearch | None, objective: str) -> tuple[Followed, tuple | None]:
    """follow_setpoints' search with the setpoint episodes on the FMU, minimising the load cost (objective "load") or
    the setpoint ISE ("setpoint") within the Ms, noise and overshoot limits: (what it found, (vector, gains, (b, c,
    Tf)) where it meets every limit or, where the load-optimal gains diverged, it follows the episodes; else None)."""
    follow = SetpointDesign(design, best_load, math.inf, deploy.max_overshoot, seeds, objective=objective)
    progress.step(("least load IAE" if objective == "load" else "least setpoint ISE")
                  + " within the overshoot limit, without the load tolerance"
                  + (" (the load-optimal gains diverge on the setpoint episodes)" if diverged else ""),
                  follow.budget(maxiter, popsize, whole_box=True))
    result, (load, ise, overshoot), feasible = _whole_box(follow, seed, maxiter, popsize, progress)
    found = Followed("search", objective, diverged, load, ise, overshoot, feasible, int(result.nfev), record)
    if not (feasible or (diverged and math.isfinite(ise))):
        return found, None
    vector = np.asarray(result.x)
    b = [follow.weight(vector)] * config.n_loops
    return found, (vector, design.gains(vector[:-1]), (b, list(design.c), design.filters(vector[:-1])))


def _whole_box(follow: SetpointDesign, seed: int, generations: int, popsize: int, progress: Steps) -> tuple:
    """(DE result, (load cost, ISE, overshoot) of its best, whether that meets every limit) of `follow`'s search over
    the whole box; `follow` closed after it."""
    try:
        result = follow.search(None, seed, generations, popsize, progress=progress)
        return result, follow.evaluate(result.x), bool(np.max(follow.constraint_values(result.x)) <= 0)
    finally:
        follow.close()


def _follow_on_models(config: TuningConfig, design: LoadDesign, best_load: float, deploy: DeployConfig,
                      seeds: list[int], seed: int, maxiter: int, popsize: int, progress: Steps
                      ) -> tuple[ModelSearch, tuple | None]:
    """follow_setpoints' search on the local models (SetpointDesign on_models: unit setpoint steps and the load cost
    on the models, tuning.load_design.model_budget's generations, at least SETPOINT_MODEL_MINIMUM), then verified on
    the FMU: b chosen again on the training episodes (`setpoint_weight`), kept where its overshoot there is within the
    limit. Returns (Followed.on_models, (vector with b, gains, (b, c, Tf)) or None)."""
    follow = SetpointDesign(design, best_load, math.inf, deploy.max_overshoot, seeds, on_models=True,
                            objective="load")
    generations, size = model_budget(maxiter, popsize, SETPOINT_MODEL_MINIMUM)
    progress.step("least load IAE within the overshoot limit on the local models",
                  follow.budget(generations, size, whole_box=True))
    result, (model_load, _, model_overshoot), feasible = _whole_box(follow, seed, generations, size, progress)
    record = ModelSearch(int(result.nfev), model_load, model_overshoot, feasible)
    if not feasible:
        return record, None
    x = np.asarray(result.x)
    gains, tf = design.gains(x[:-1]), design.filters(x[:-1])
    progress.step("the models' choice: b and load cost verified on the FMU")
    b, rows = setpoint_weight(config, gains, (list(design.b), list(design.c), tf), seeds, deploy.max_overshoot)
    row = next(r for r in rows if r["b"] == b)
    record.load_cost, record.ISE, record.Overshoot, record.b = (design.load_cost(gains, tf), row["ISE"],
                                                                row["Overshoot"], b)
    if not (math.isfinite(row["ISE"]) and row["Overshoot"] <= 100.0 * deploy.max_overshoot):
        return record, None
    record.kept = True
    return record, (np.append(x[:-1], 2.0 * b - 1.0), gains, ([b] * config.n_loops, list(design.c), tf))
