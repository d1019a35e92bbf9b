"""Choosing what to deploy: the adaptive gain schedule (replayed as a plain PID) or the tuned fixed PID.

Rule (one place; explained in docs/architecture.md "Deliverable"):
- A controller is eligible when it never diverged (evaluation and every Monte-Carlo sample) and its
  worst peak sensitivity Ms over its operating points is at most `max_sensitivity`.
- Its score is the evaluation's ISE plus the mean ISE over the Monte-Carlo samples.
- The schedule is deployed when it is eligible, scores at least MIN_IMPROVEMENT below the fixed PID (a
  table of gains must earn its place over one set of gains: a tie is not a win), its total variation
  of u is at most TOTAL_VARIATION_LIMIT times the fixed PID's (no ISE bought by chattering), and its
  ISE on held-out episodes of the training distribution (`holdout_ise`: seeds used for nothing else)
  is no worse than the fixed PID's (a win on one evaluation schedule must carry over to setpoints and
  disturbances it was not measured on); otherwise the fixed PID when it is eligible; otherwise nothing
  is deployable.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

TOTAL_VARIATION_LIMIT = 1.5
MIN_IMPROVEMENT = 0.01  # the schedule's score must be at most (1 - this) x the fixed PID's


@dataclass
class Candidate:
    """One deployable controller's evidence.

    name: "gain schedule" | "fixed PID". metrics: evaluation metrics (compute_metrics + "terminated").
    monte_carlo: metrics of each Monte-Carlo sample. margins: prlpid_fmi.margins.Margins per operating
    point (one for the fixed PID), with `breakpoints` the matching operating points.
    """

    name: str
    metrics: dict
    monte_carlo: list = field(default_factory=list)
    margins: list = field(default_factory=list)
    breakpoints: list = field(default_factory=list)
    holdout_ise: float = math.nan  # ISE over held-out training-distribution episodes (NaN: not measured)

    @property
    def diverged(self) -> bool:
        return bool(self.metrics.get("terminated")) or any(m.get("terminated") for m in self.monte_carlo)

    @property
    def worst_Ms(self) -> float:
        """Largest Ms over the operating points whose estimate counts: reliable ones, and inf (the loop
        diverged or sat at a limit there); NaN when every estimate is unreliable (see `unverified`)."""
        return max((m.Ms for m in self.margins if counts(m)), default=math.nan)

    @property
    def unverified(self) -> bool:
        """The margins were measured but no estimate is reliable (a time-varying or strongly nonlinear
        plant): robustness could not be checked, so it neither qualifies nor disqualifies."""
        return bool(self.margins) and not any(counts(m) for m in self.margins)

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
        elif math.isinf(self.worst_Ms):
            out.append(f"its loop is not robustly stable at every operating point: in the margin measurement it "
                       f"diverged or was held at an actuator limit (Ms = infinity; limit {max_sensitivity:g})")
        elif not self.worst_Ms <= max_sensitivity:
            out.append(f"its peak sensitivity Ms = {self.worst_Ms:.2f} exceeds the limit {max_sensitivity:g}")
        return out


def counts(m) -> bool:
    """Whether a Margins estimate decides: reliable, or infinite (diverged / saturated: always a failure)."""
    return bool(m.reliable) or not math.isfinite(m.Ms)


def meets(m, limit: float) -> bool:
    """A Margins estimate meets the Ms limit, or cannot judge it (finite but unreliable)."""
    return not counts(m) or m.Ms <= limit


@dataclass(frozen=True)
class Decision:
    """deploy: "gain schedule" | "fixed PID" | "none"; reasons: why, one sentence each."""

    deploy: str
    reasons: tuple[str, ...]


def choose(schedule: Candidate | None, fixed: Candidate, max_sensitivity: float) -> Decision:
    """Apply the rule of the module docstring."""
    reasons = []
    if schedule is not None:
        problems = schedule.problems(max_sensitivity)
        if not problems:
            if not schedule.score <= (1 - MIN_IMPROVEMENT) * fixed.score:
                problems.append(f"it does not beat the fixed PID on ISE by {MIN_IMPROVEMENT:.0%} or more "
                                f"({schedule.score:.4g} vs {fixed.score:.4g})")
            tv_s, tv_f = _total_variation(schedule), _total_variation(fixed)
            if tv_s > TOTAL_VARIATION_LIMIT * tv_f:
                problems.append(f"its control signal varies {tv_s / tv_f:.1f}x as much as the fixed PID's "
                                f"(limit {TOTAL_VARIATION_LIMIT}x)")
            h_s, h_f = schedule.holdout_ise, fixed.holdout_ise
            if not (math.isnan(h_s) or math.isnan(h_f)) and not h_s <= h_f:
                problems.append("its win does not carry over: on held-out episodes of the training distribution "
                                + ("it diverged" if math.isinf(h_s) else
                                   f"its ISE is {h_s:.4g} against the fixed PID's {h_f:.4g}"))
        if not problems:
            return Decision("gain schedule", (f"it beats the fixed PID on ISE ({schedule.score:.4g} vs "
                                              f"{fixed.score:.4g}) within the robustness and effort limits",))
        reasons += [f"The gain schedule is not deployed: {p}." for p in problems]
    problems = fixed.problems(max_sensitivity)
    if not problems:
        return Decision("fixed PID", tuple(reasons))
    reasons += [f"The fixed PID is not deployable either: {p}." for p in problems]
    return Decision("none", tuple(reasons))


def overall_metric(overall: dict, key: str) -> float:
    """`key` from compute_metrics' overall dict: plain for one loop; "key[loop]" summed (integral
    metrics) or maximised (step metrics) over loops for several."""
    if key in overall:
        return float(overall[key])
    values = [float(v) for k, v in overall.items() if k.startswith(key + "[")]
    if not values:
        return math.nan
    return sum(values) if key in ("ISE", "IAE", "ITAE", "ControlEffort", "TotalVariation") else max(values)


def _total_variation(c: Candidate) -> float:
    return c.overall("TotalVariation")


def _ms(c: Candidate) -> str:
    return "not verified" if math.isnan(c.worst_Ms) else f"{c.worst_Ms:.2f}"


def _ratio(a: float, b: float) -> str:
    return f"{a / b:.2f}x" if b and math.isfinite(a) and math.isfinite(b) else "n/a"


def verdict(decision: Decision, schedule: Candidate | None, fixed: Candidate, max_sensitivity: float,
            gain_mapping: str = "anchored") -> str:
    """The report's opening paragraph, in words (markdown); gain_mapping: the run's controller.gain_mapping."""
    lines = ["## Verdict", ""]
    if decision.deploy == "gain schedule":
        s, f = schedule, fixed
        if math.isfinite(s.overall("Overshoot")) and f.overall("Overshoot") > 0:
            shape = f"its overshoot {_ratio(s.overall('Overshoot'), f.overall('Overshoot'))}"
        elif math.isfinite(s.overall("Overshoot")):  # the fixed PID does not overshoot: no ratio
            shape = f"its overshoot {s.overall('Overshoot'):.2g} % (fixed PID {f.overall('Overshoot'):.2g} %)"
        else:  # no setpoint step: disturbance rejection
            shape = f"its peak deviation {_ratio(s.overall('PeakDeviation'), f.overall('PeakDeviation'))}"
        lines.append(f"**Deploy the adaptive gain schedule** (schedule.csv, a plain gain-scheduled PID; no neural "
                     f"network). On the evaluation its ISE is {_ratio(s.overall('ISE'), f.overall('ISE'))} the fixed "
                     f"PID's, {shape}, and its worst Ms {_ms(s)} (fixed PID {_ms(f)}; limit "
                     f"{max_sensitivity:g}). Ratios are gain schedule ÷ fixed PID; lower is better.")
    elif decision.deploy == "fixed PID":
        lines.append(f"**Deploy the fixed PID** (schedule.csv holds it as a one-row table; also fixed_pid.csv). "
                     f"Its worst Ms is {_ms(fixed)} (limit {max_sensitivity:g}).")
        if schedule is not None:
            the_map = ("wider controller.anchor_bands" if gain_mapping == "anchored" else
                       "the anchored gain map (controller.gain_mapping: anchored, which starts training at the fixed "
                       "PID)")
            lines.append(f"The adaptive schedule was not deployed (why: below). To try: a longer training budget "
                         f"(--timesteps), {the_map}, or training.randomize over the parameters that vary in your "
                         "plant.")
    else:
        lines.append(f"**Nothing here is safe to deploy**: no controller meets the robustness limit Ms <= "
                     f"{max_sensitivity:g} without diverging. Narrow the gain ranges, lower the sample time, or "
                     "check the plant's limits and operating range.")
    unverified = [c.name for c in (schedule, fixed) if c is not None and c.unverified]
    if unverified:
        lines.append(f"Robustness could not be verified for: {', '.join(unverified)} (the frequency-response "
                     "estimate on the FMU was unreliable, e.g. a time-varying or strongly nonlinear plant); "
                     "the choice rests on the evaluation alone.")
    lines += [""] + [f"- {r}" for r in decision.reasons]
    return "\n".join(lines) + "\n"
