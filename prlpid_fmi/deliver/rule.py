"""Choosing what to deploy: the adaptive gain schedule (replayed as a plain PID) or the tuned fixed PID.

Rule (one place; explained in docs/architecture.md "Deliverable"):
- A controller is eligible when it never diverged (evaluation and every Monte-Carlo sample), no margin
  estimate failed (robustness.status: diverged, at a limit, too lightly damped to settle) and its worst
  peak sensitivity Ms over the verified estimates is at most `max_sensitivity`. An estimate impossible to
  make (a plant that varies faster than the experiment) does not disqualify the fixed PID (the verdict says
  so), but the gain schedule is deployed on verified robustness only: every one of its estimates verified,
  unless `allow_unverified` (deploy.allow_unverified) opts in.
- Its score is the evaluation's ISE plus the mean ISE over the Monte-Carlo samples.
- The schedule is deployed when it is eligible, scores at least MIN_IMPROVEMENT below the fixed PID (a
  table of gains must earn its place over one set of gains: a tie is not a win), its total variation
  of u is at most TOTAL_VARIATION_LIMIT times the fixed PID's (no ISE bought by chattering), and its
  ISE on held-out episodes of the training distribution (`holdout_ise`: seeds used for nothing else)
  is no worse than the fixed PID's (a win on one evaluation schedule must carry over to setpoints and
  disturbances it was not measured on), nor is its total variation of u there above TOTAL_VARIATION_LIMIT times
  the fixed PID's, nor does it leave a setpoint step unsettled in more of those episodes, and its load IAE (load steps at the plant input over the setpoint
  range) is at most LOAD_TOLERANCE times the fixed PID's (setpoint ISE alone does not decide), and its overshoot
  (the acceptance check's) is within deploy.max_overshoot wherever the fixed PID's is; otherwise the fixed PID when it
  is eligible; otherwise nothing is deployable. Where the fixed PID is not eligible itself, an eligible schedule is
  deployed without those comparisons (they rank a table against a controller that may be deployed).
- With a classical gain schedule (tuning.schedule.classical, on nonlinear plants) there are three candidates:
  the classical schedule must first win over the fixed PID by the rule above (`choose_among`); the winner is
  the incumbent the adaptive schedule must then beat by the same rule. So the adaptive policy is deployed only
  where it beats classical gain scheduling, and classical scheduling only where it beats one fixed PID.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

from prlpid_fmi.deliver.acceptance import Acceptance, Episode
from prlpid_fmi.metrics import overall_metric
from prlpid_fmi.robustness.status import Robustness, meets_limit, status, why


class Deployed(str, enum.Enum):
    """What a run deploys. The value is the word metrics.json, schedule.csv's report and the sweep tables write."""

    SCHEDULE = "gain schedule"
    CLASSICAL = "classical gain schedule"
    FIXED_PID = "fixed PID"
    NONE = "none"

    def __str__(self) -> str:
        return self.value

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)

    @classmethod
    def read(cls, word) -> "Deployed | None":
        """The member a metrics.json value names (None for a missing or unknown word)."""
        try:
            return cls(word)
        except ValueError:
            return None


TOTAL_VARIATION_LIMIT = 1.5
LOAD_TOLERANCE = 1.02  # the schedule's load IAE may be at most this x the fixed PID's
MIN_IMPROVEMENT = 0.01  # the schedule's score must be at most (1 - this) x the fixed PID's


@dataclass
class Candidate:
    """One deployable controller's evidence.

    name: "gain schedule" | "fixed PID". metrics: evaluation metrics (compute_metrics + "terminated").
    monte_carlo: metrics of each Monte-Carlo sample. margins: prlpid_fmi.robustness.margins.Margins per operating
    point (one for the fixed PID), with `breakpoints` the matching operating points.
    """

    name: str
    metrics: dict
    monte_carlo: list = field(default_factory=list)
    margins: list = field(default_factory=list)
    breakpoints: list = field(default_factory=list)
    holdout_ise: float = math.nan  # ISE over held-out training-distribution episodes (NaN: not measured)
    holdout_tv: float = math.nan  # total variation of u over the same episodes (NaN: not measured)
    holdout_unsettled: int | None = None  # how many of them leave a setpoint step unsettled (None: not measured)
    load_iae: float = math.nan  # load IAE per unit load of tuning.load_experiment's experiment (NaN: not measured)
    draws: int = 0  # Monte-Carlo parameter draws the margins were also measured on (labelled in words; deliver.evidence)
    evaluation: Episode | None = None  # the evaluation replay (metrics and trajectory) the acceptance check reads
    acceptance: Acceptance | None = None  # deliver.acceptance.check (None: not checked)

    @property
    def diverged(self) -> bool:
        return bool(self.metrics.get("terminated")) or any(m.get("terminated") for m in self.monte_carlo)

    @property
    def worst_Ms(self) -> float:
        """Largest Ms over the operating points whose estimate counts (robustness.status: verified or failed;
        inf where the loop diverged or sat at a limit); NaN when every one was impossible (see `unverified`)."""
        return max((m.Ms for m in self.margins if counts(m)), default=math.nan)

    @property
    def unverified(self) -> bool:
        """The margins were measured but every estimate was impossible (robustness.status: the plant varies
        faster than the experiment): robustness could not be checked, so it neither qualifies nor disqualifies."""
        return bool(self.margins) and not any(counts(m) for m in self.margins)

    def states(self) -> list[tuple]:
        """(operating point, robustness.status.Robustness) per margin estimate."""
        return [(b, status(m)) for b, m in zip(self.breakpoints, self.margins)]

    @property
    def score(self) -> float:
        """Evaluation ISE + mean Monte-Carlo ISE (lower is better)."""
        ise = self.overall("ISE")
        if self.monte_carlo:
            ise += sum(self.overall("ISE", m) for m in self.monte_carlo) / len(self.monte_carlo)
        return ise

    def overall(self, key: str, metrics: dict | None = None) -> float:
        """An overall metric summed over loops (ISE, IAE, effort, total variation) or their worst (others)."""
        return overall_metric((metrics or self.metrics)["overall"], key)

    def problems(self, max_sensitivity: float) -> list[str]:
        """Why the candidate may not be deployed (empty: eligible)."""
        out = []
        if self.diverged:
            ended = self.metrics.get("termination")
            if ended:
                out.append(f"its evaluation ended early at t = {ended['time_s']:g} s ({ended['message']})")
            else:
                out.append("it diverged in the evaluation" + (" or a Monte-Carlo sample" if self.monte_carlo else ""))
        if not self.margins:
            out.append("its robustness margins could not be measured")
        elif self.unverified:
            pass  # said in the verdict, not a reason to refuse
        else:
            failed = [(b, m) for b, m in zip(self.breakpoints, self.margins) if status(m) == Robustness.FAILED]
            if failed:
                b, m = failed[0]
                out.append(f"its loop fails the robustness check at {len(failed)} of {len(self.margins)} operating "
                           f"points (at {_point(b)}, {why(m, max_sensitivity)})")
            elif not self.worst_Ms <= max_sensitivity:
                out.append(f"its peak sensitivity Ms = {self.worst_Ms:.2f} exceeds the limit {max_sensitivity:g}")
        return out + self.check_failures()

    def failed_checks(self) -> list:
        """The acceptance check's failures (deliver.acceptance.Failure); a divergence of the evaluation that
        `diverged` reports already is left out."""
        if self.acceptance is None:
            return []
        return [f for f in self.acceptance.failures
                if not (self.diverged and f.check == "follows" and f.episode == "the evaluation")]

    def check_failures(self) -> list[str]:
        """failed_checks, one sentence each."""
        return [f"it fails the acceptance check ({f.check}): it {f.text}" for f in self.failed_checks()]


def _point(b) -> str:
    return f"{b:g}" if isinstance(b, (int, float)) else str(b)


def counts(m) -> bool:
    """Whether a Margins estimate decides (robustness.status: verified or failed, not impossible)."""
    return status(m) != Robustness.IMPOSSIBLE


def meets(m, limit: float) -> bool:
    """robustness.status.meets_limit: verified within the limit, or impossible to measure."""
    return meets_limit(m, limit)


@dataclass(frozen=True)
class Decision:
    """deploy: what is deployed; reasons: why, one sentence each."""

    deploy: Deployed
    reasons: tuple[str, ...]


def choose(schedule: Candidate | None, fixed: Candidate, max_sensitivity: float,
           allow_unverified: bool = False) -> Decision:
    """Apply the rule of the module docstring to a schedule and an incumbent (`fixed`: the fixed PID, or the
    classical schedule that beat it; its name is what the reasons compare with)."""
    reasons = []
    against = fixed.name
    if schedule is not None:
        problems = schedule.problems(max_sensitivity)
        impossible = sum(status(m) == Robustness.IMPOSSIBLE for m in schedule.margins)
        if not problems and impossible and not allow_unverified:
            problems.append(f"its robustness is not verified ({impossible} of {len(schedule.margins)} Ms estimates "
                            "impossible to make: the plant varies faster than the margin experiment); "
                            "deploy.allow_unverified: true deploys it anyway")
        refused = fixed.problems(max_sensitivity)
        if not problems and refused:  # comparisons with a controller that may not be deployed mean nothing
            return Decision(Deployed(schedule.name), tuple(
                [f"The {against} is not deployable: {p}." for p in refused]
                + [f"The {schedule.name} passes every check, so it is deployed in its place (the comparisons with "
                   f"the {against} do not apply)."]))
        if not problems:
            if not schedule.score <= (1 - MIN_IMPROVEMENT) * fixed.score:
                problems.append(f"it does not beat the {against} on ISE by {MIN_IMPROVEMENT:.0%} or more "
                                f"({schedule.score:.4g} vs {fixed.score:.4g})")
            tv_s, tv_f = _total_variation(schedule), _total_variation(fixed)
            if tv_s > TOTAL_VARIATION_LIMIT * tv_f:
                problems.append(f"its control signal varies {tv_s / tv_f:.1f}x as much as the {against}'s "
                                f"(limit {TOTAL_VARIATION_LIMIT}x)")
            l_s, l_f = schedule.load_iae, fixed.load_iae
            if not (math.isnan(l_s) or math.isnan(l_f)) and not l_s <= LOAD_TOLERANCE * l_f:
                problems.append(f"it rejects load steps worse than the {against} (load IAE {l_s:.4g} against "
                                f"{l_f:.4g}, limit {LOAD_TOLERANCE}x): better setpoint tracking does not make up "
                                "for that")
            v_s, v_f = schedule.holdout_tv, fixed.holdout_tv
            if not (math.isnan(v_s) or math.isnan(v_f) or math.isinf(v_s)) and v_s > TOTAL_VARIATION_LIMIT * v_f:
                problems.append(f"on held-out episodes of the training distribution its control signal varies "
                                f"{v_s / v_f:.1f}x as much as the {against}'s (limit {TOTAL_VARIATION_LIMIT}x)")
            a_s, a_f = schedule.acceptance, fixed.acceptance
            if a_s is not None and a_f is not None and a_s.above_user_overshoot > 0 \
                    and a_f.above_user_overshoot == 0 and math.isfinite(a_f.overshoot_pct):
                problems.append(f"its overshoot {a_s.overshoot_pct:.3g} % is above deploy.max_overshoot "
                                f"({a_s.user_overshoot_pct:g} %) where the {against}'s {a_f.overshoot_pct:.3g} % is "
                                "within it: the user's limit is not traded for ISE")
            n_s, n_f = schedule.holdout_unsettled, fixed.holdout_unsettled
            if n_s is not None and n_f is not None and n_s > n_f:
                problems.append(f"on held-out episodes of the training distribution it leaves a setpoint step "
                                f"unsettled in {n_s} episodes (the {against}: {n_f})")
            h_s, h_f = schedule.holdout_ise, fixed.holdout_ise
            if not (math.isnan(h_s) or math.isnan(h_f)) and not h_s <= h_f:
                problems.append("its win does not carry over: on held-out episodes of the training distribution "
                                + ("it diverged" if math.isinf(h_s) else
                                   f"its ISE is {h_s:.4g} against the {against}'s {h_f:.4g}"))
        if not problems:
            said = (f"The {schedule.name} beats the {against} on ISE ({schedule.score:.4g} vs {fixed.score:.4g}) "
                    "within the robustness and effort limits.",)
            if math.isinf(schedule.holdout_ise) and math.isinf(fixed.holdout_ise):
                said += (f"On held-out episodes of the training distribution both it and the {against} diverged: "
                         "that check could not tell them apart, and neither holds every setpoint step of the "
                         "training distribution.",)
            return Decision(Deployed(schedule.name), said)
        reasons += [f"The {schedule.name} is not deployed: {p}." for p in problems]
    problems = fixed.problems(max_sensitivity)
    if not problems:
        return Decision(Deployed(fixed.name), tuple(reasons))
    reasons += [f"The {fixed.name} is not deployable either: {p}." for p in problems]
    return Decision(Deployed.NONE, tuple(reasons))


def choose_among(schedule: Candidate | None, classical: Candidate | None, fixed: Candidate, max_sensitivity: float,
                 allow_unverified: bool = False) -> Decision:
    """The three-candidate rule of the module docstring (classical None: `choose` of the schedule and the fixed
    PID). The reasons of both comparisons are kept, in order."""
    if classical is None:
        return choose(schedule, fixed, max_sensitivity, allow_unverified)
    first = choose(classical, fixed, max_sensitivity, allow_unverified)
    if schedule is None:
        return first
    incumbent = classical if first.deploy == Deployed.CLASSICAL else fixed  # NONE: the fixed PID's measures
    second = choose(schedule, incumbent, max_sensitivity, allow_unverified)
    if second.deploy == Deployed.SCHEDULE:
        return Decision(Deployed.SCHEDULE, second.reasons + first.reasons)
    return Decision(first.deploy, first.reasons + tuple(r for r in second.reasons if r not in first.reasons))


def _total_variation(c: Candidate) -> float:
    return c.overall("TotalVariation")
