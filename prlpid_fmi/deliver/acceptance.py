"""The acceptance check every deployed controller must pass, whatever the design found (deliver.rule refuses a
candidate that fails it).

A candidate is replayed as a plain PID (constant gains, or its gain table) on the scenario's evaluation and on
held-out episodes of the training distribution (deliver.evidence). On every one of them:

1. it follows: the episode runs to its end (no divergence, no rejected FMU step);
2. it settles every setpoint step (metrics: SettlingTime finite) and recovers from every disturbance (RecoveryTime
   finite). A step whose hold a random load step cuts short (training.load_disturbance: the step's segment ends
   where the load begins, half-way through the hold) is not judged there: the clean replays (deliver.evidence: the
   held-out seeds again without loads and noise) judge steps with their whole hold; the load's recovery is judged
   where it happens. Where training has noise, the held-out episodes' settling and recovery are judged on
   their noise-free replays (deliver.evidence: without noise and loads, and without noise with the loads), not on
   the noisy ones: actuator noise makes the measurement wander by an amount only the data can estimate, and a
   band that estimate sets can leave a settled loop "unsettled"; the noisy replays are judged on following and
   their Chatter. An episode with a step left unsettled is replayed once with every hold LONG_HOLD times
   as long (the same setpoints in the same order, the scenario's disturbances and the episode's random load steps
   moved with their holds: `stretched`).
   A step that settles then is *slow*: reported, not failed; so is a noise-free disturbance still being recovered at
   the end of the long hold (its largest error over the last LIMIT_TAIL at most CONVERGING x that over the
   LIMIT_TAIL before: a slow load recovery, not an offset or a swing that stays). One that still does not settle
   fails, unless no input within the limits can hold its setpoint: the controller's command sits at one of its
   limits over the last quarter of the long hold while the measurement stays short of the setpoint on the side it
   came from. Such a setpoint is *excused* and named;
3. its overshoot beyond NOISE_BAND standard deviations of the measurement noise is at most
   max(OVERSHOOT_FLOOR, deploy.max_overshoot) of the step (of MIN_STEP of the setpoint range for smaller steps),
   measured on episodes without random load steps (`random_loads`: deliver.evidence adds load-free replays of
   the held-out episodes where the training distribution has them); between deploy.max_overshoot and that it passes,
   and the verdict says by how much it is above the user's limit;
4. its command does not chatter by itself: on the noise-free replays (`noise_free`), the fraction of samples at which
   the command oscillates at the sample rate (metrics.fast_reversals: three moves in a row of alternating sign, each
   above CHATTER_THRESHOLD of the span, or a pulse one sample wide between small moves: a limit cycle, a ringing
   derivative, a command toggling at a limit) is at most deploy.max_chatter. A swing at the loop's own bandwidth
   (damping an oscillatory plant) is not chatter. On the noisy replays the Chatter metric (metrics.chatter_fraction)
   is a preference, like the noise limits of the design: reported (`noisy_chatter`), not failed.

The Ms limit is the rule's own check (deliver.rule.Candidate.problems). `check` returns an Acceptance: the failures,
each with what failed, by how much and what would change it, and the slow and excused steps.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from prlpid_fmi.config import Disturbance, TuningConfig
from prlpid_fmi.loop.evaluation import command_chatter
from prlpid_fmi.metrics import NOISE_BAND, overall_metric

LONG_HOLD = 4  # an unsettled step is replayed with holds this many times as long
OVERSHOOT_FLOOR = 25.0  # [%] the overshoot limit is max(this, deploy.max_overshoot)
LIMIT_TAIL = 0.25  # fraction of the long hold at its end over which a command at its limit excuses a setpoint
MIN_STEP = 0.05  # overshoot is a fraction of the step, or of this fraction of the setpoint range if larger
LIMIT_TOLERANCE = 0.005  # a command within this fraction of the span of a limit sits at it
CONVERGING = 0.8  # a noise-free segment whose error over the long hold's last quarter is at most this x that over
# the quarter before is still converging: slow, not failed

Replay = Callable[[TuningConfig, int], tuple]  # (config, seed) -> (metrics, loop.evaluation.Trajectory)


@dataclass(frozen=True)
class Episode:
    """One replay the check reads: label ("the evaluation", "held-out episode 3"), the config and seed it ran
    with, and its metrics (loop.evaluation.measure) and Trajectory. settling: whether its steps' settling and its
    disturbances' recovery are judged (False: a noisy replay whose noise-free twins judge them)."""

    label: str
    config: TuningConfig
    seed: int
    metrics: dict
    trajectory: object
    settling: bool = True


@dataclass(frozen=True)
class Failure:
    """A failed check: check ("follows" | "settles" | "overshoot" | "chatter"), what failed and by how much
    (a sentence without its subject), and what would change it."""

    check: str
    text: str
    remedy: str = ""
    episode: str = ""  # the replay it failed on (Episode.label), "" for the worst over all


@dataclass(frozen=True)
class Acceptance:
    """The acceptance check of one candidate. steps: setpoint steps checked; settled: of them, settled within their
    hold; slow: steps that settled only on the long hold; excused: setpoints no input within the limits can hold
    (each a sentence); overshoot_pct: the worst overshoot [%] beyond the noise band (NaN: no step);
    overshoot_limit_pct / user_overshoot_pct: the check's limit and deploy.max_overshoot [%]; chatter: the worst
    Chatter fraction of the noise-free replays, noisy_chatter of the others (NaN: not defined or none such)."""

    failures: tuple[Failure, ...] = ()
    steps: int = 0
    settled: int = 0
    slow: tuple[str, ...] = ()
    excused: tuple[str, ...] = ()
    overshoot_pct: float = math.nan
    overshoot_limit_pct: float = OVERSHOOT_FLOOR
    user_overshoot_pct: float = 5.0
    chatter: float = math.nan
    max_chatter: float = 0.05
    episodes: int = 0
    noisy_chatter: float = math.nan
    noisy_chatter_where: str = ""
    details: tuple[str, ...] = ()  # every failure found, one sentence each (failures groups them per check)

    @property
    def passed(self) -> bool:
        return not self.failures

    @property
    def above_user_overshoot(self) -> float:
        """Percentage points of overshoot above deploy.max_overshoot (0 when within it)."""
        if not math.isfinite(self.overshoot_pct):
            return 0.0
        return max(0.0, self.overshoot_pct - self.user_overshoot_pct)

    def as_dict(self) -> dict:
        """What metrics.json records of the check."""
        def num(x):
            return None if isinstance(x, float) and math.isnan(x) else x if math.isfinite(x) else str(x)
        return {"passed": self.passed, "failures": [dataclasses.asdict(f) for f in self.failures],
                "episodes": self.episodes, "steps": self.steps, "settled_in_hold": self.settled,
                "slow": list(self.slow), "excused": list(self.excused), "overshoot_pct": num(self.overshoot_pct),
                "overshoot_limit_pct": self.overshoot_limit_pct, "user_overshoot_pct": self.user_overshoot_pct,
                "chatter": num(self.chatter), "max_chatter": self.max_chatter,
                "chatter_with_noise": num(self.noisy_chatter), "details": list(self.details)}


@dataclass
class _Tally:
    failures: list = field(default_factory=list)
    slow: list = field(default_factory=list)
    excused: list = field(default_factory=list)
    steps: int = 0
    settled: int = 0
    overshoot: float = math.nan
    overshoot_where: str = ""
    chatter: float = math.nan
    chatter_where: str = ""
    noisy: float = math.nan
    noisy_where: str = ""


def check(episodes: list[Episode], replay: Replay, max_overshoot: float, max_chatter: float) -> Acceptance:
    """The acceptance check (module docstring) over `episodes`; `replay` runs the candidate on another config (the
    long holds). max_overshoot: deploy.max_overshoot [fraction of the step]; max_chatter: deploy.max_chatter."""
    user = 100.0 * max_overshoot
    limit = max(OVERSHOOT_FLOOR, user)
    t = _Tally()
    for ep in episodes:
        _check_episode(ep, replay, t)
    if math.isfinite(t.overshoot) and t.overshoot > limit:
        t.failures.append(Failure("overshoot", f"overshoots {t.overshoot:.0f} % ({t.overshoot_where}), above the "
                                               f"limit max({OVERSHOOT_FLOOR:g} %, deploy.max_overshoot) = {limit:g} %",
                                  "a smaller setpoint weight b (controller.setpoint_weight: tuned), a lower Ms limit "
                                  "(deploy.max_sensitivity), or smaller setpoint steps"))
    if math.isfinite(t.chatter) and t.chatter > max_chatter:
        t.failures.append(Failure("chatter", f"oscillates its command at the sample rate on {t.chatter:.0%} of the "
                                             f"samples ({t.chatter_where}, without noise), above deploy.max_chatter "
                                             f"{max_chatter:g}",
                                  "a smaller Td or Kp (a loop that rings or limit-cycles at its sample time), a "
                                  "shorter sample time, or a larger deploy.max_chatter if the actuator tolerates it"))
    return Acceptance(_grouped(t.failures), t.steps, t.settled, tuple(t.slow), tuple(t.excused), t.overshoot,
                      limit, user, t.chatter, max_chatter, len(episodes), t.noisy, t.noisy_where,
                      tuple(f.text for f in t.failures))


def _grouped(failures: list[Failure]) -> tuple[Failure, ...]:
    """One failure per check: the first of each, with how many more there are (Acceptance.details lists all)."""
    out = []
    for check_name in dict.fromkeys(f.check for f in failures):
        same = [f for f in failures if f.check == check_name]
        first = same[0]
        if len(same) > 1:
            first = Failure(first.check, f"{first.text}; and in {len(same) - 1} more place"
                                         f"{'s' if len(same) > 2 else ''} (metrics.json: acceptance.details)",
                            first.remedy, "")
        out.append(first)
    return tuple(out)


def _check_episode(ep: Episode, replay: Replay, t: _Tally) -> None:
    m, traj, config = ep.metrics, ep.trajectory, ep.config
    if m.get("terminated"):
        ended = m.get("termination") or {}
        when = f" at t = {ended['time_s']:g} s" if "time_s" in ended else ""
        t.failures.append(Failure("follows", f"diverges on {ep.label}{when}"
                                             + (f" ({ended['message']})" if ended.get("message") else ""),
                                  "a gain range that contains stabilising gains, a shorter sample time for a fast "
                                  "or unstable plant, or a setpoint range the actuator can hold", ep.label))
        return
    if noise_free(config):
        c = command_chatter(traj, config)
        if math.isfinite(c) and not c <= t.chatter:
            t.chatter, t.chatter_where = c, ep.label
    else:
        c = overall_metric(m["overall"], "Chatter")
        if math.isfinite(c) and not c <= t.noisy:
            t.noisy, t.noisy_where = c, ep.label
    if not ep.settling:
        return
    index = {l.output: i for i, l in enumerate(config.loops)}
    for seg in judged(m, traj):
        if not _is_step(seg):
            continue
        i = index.get(seg["loop"], 0)
        t.steps += 1
        t.settled += seg["SettlingTime"] != math.inf
        os = _overshoot(traj, seg, i, config) if not random_loads(config) else math.nan
        if math.isfinite(os) and not os <= t.overshoot:
            t.overshoot, t.overshoot_where = os, f"{ep.label}, the step to {traj.setpoint[seg['start_step'], i]:.4g} " \
                                                  f"at t = {seg['start_time_s']:g} s"
    unsettled = late(m, traj)
    if unsettled:
        _long_hold(ep, unsettled, replay, t, index)


def judged(metrics: dict, traj) -> list[dict]:
    """The segments of a replay's metrics the check judges: all but the setpoint steps a random load step cuts short
    (their segment ends where the load begins: loop.evaluation.measure splits segments there), which the clean
    replays judge with their whole hold."""
    cut = {start for start, _, _, _ in traj.loads}
    return [seg for seg in metrics["segments"] if not (_is_step(seg) and seg["end_step"] in cut)]


def late(metrics: dict, traj, steps_only: bool = False) -> list[dict]:
    """The judged segments (`judged`) of a replay left unsettled (a step) or unrecovered (a disturbance; not with
    steps_only) at the end of their hold."""
    out = []
    for seg in judged(metrics, traj):
        if _is_step(seg):
            if seg["SettlingTime"] == math.inf:
                out.append(seg)
        elif not steps_only and seg["RecoveryTime"] == math.inf:
            out.append(seg)
    return out


def _is_step(seg: dict) -> bool:
    return not math.isnan(seg["SettlingTime"])


def noise_free(config: TuningConfig) -> bool:
    """Whether the config's episodes have neither measurement nor actuator noise."""
    return config.measurement_noise_std == 0 and config.actuator_noise_std == 0


def random_loads(config: TuningConfig) -> bool:
    """Whether the config's episodes carry random load steps (training.load_disturbance with random setpoints:
    loop.core puts one in the second half of every hold and removes it as the setpoint changes, so the response
    to a setpoint step there is also a load response and its overshoot is not the loop's)."""
    return config.load_disturbance > 0 and config.setpoint_schedule is None


def _overshoot(traj, seg: dict, i: int, config: TuningConfig) -> float:
    """Overshoot [%] of a step segment: its peak beyond the new setpoint less NOISE_BAND noise standard deviations,
    over max(|step|, MIN_STEP of the loop's setpoint range) (a percentage of a step much smaller than the range
    measures the noise, not the loop)."""
    s, e, delta = seg["start_step"], seg["end_step"], seg["StepSize"]
    if not (math.isfinite(delta) and delta != 0):
        return math.nan
    y = traj.measurement[s:e, i]
    r = traj.setpoint[s, i]
    peak = float(np.max(np.sign(delta) * (y - r)))
    lo, hi = config.loops[i].setpoint_range
    return 100.0 * max(0.0, peak - NOISE_BAND * config.measurement_noise_std) / max(abs(delta), MIN_STEP * (hi - lo))


def stretched(config: TuningConfig, traj, factor: int = LONG_HOLD) -> TuningConfig:
    """The config of `traj`'s episode with every setpoint hold and disturbance `factor` times as long: the
    setpoints the episode ran (traj.setpoint, (n+1, n_loops)) as an explicit schedule, and its random load steps
    (traj.loads, each in the second half of its hold) as actuator disturbances in the second half of the longer
    hold."""
    r = np.asarray(traj.setpoint)
    changes = [0] + [k for k in range(1, len(r)) if np.any(r[k] != r[k - 1])]
    schedule = tuple((k * factor, tuple(float(v) for v in r[k])) for k in changes)
    disturbances = tuple(dataclasses.replace(d, start_step=d.start_step * factor,
                                             end_step=None if d.end_step is None else d.end_step * factor)
                         for d in config.disturbances)
    hold = config.setpoint_hold_steps
    loads = tuple(Disturbance("actuator", config.loops[i].output, (end - hold) * factor + hold * factor // 2,
                              float(value), end * factor) for start, end, i, value in traj.loads)
    return dataclasses.replace(config, setpoint_schedule=schedule, episode_steps=config.episode_steps * factor,
                               disturbances=disturbances + loads, load_disturbance=0.0)


def _long_hold(ep: Episode, unsettled: list[dict], replay: Replay, t: _Tally, index: dict) -> None:
    """Replay the episode with LONG_HOLD times the holds; each unsettled segment is then slow, excused or failed."""
    config = stretched(ep.config, ep.trajectory)
    metrics, traj = replay(config, ep.seed)
    if metrics.get("terminated"):
        ended = metrics.get("termination") or {}
        t.failures.append(Failure("follows", f"diverges on {ep.label} replayed with {LONG_HOLD}x longer holds"
                                             + (f" at t = {ended['time_s']:g} s" if "time_s" in ended else ""),
                                  "a gain range that contains stabilising gains, or a shorter sample time"))
        return
    for seg in unsettled:
        i = index.get(seg["loop"], 0)
        step = _is_step(seg)
        target = float(ep.trajectory.setpoint[seg["start_step"], i])
        what = (f"the step to {target:.4g} at t = {seg['start_step'] * config.sample_time_s:g} s" if step else
                f"the disturbance at t = {seg['start_step'] * config.sample_time_s:g} s")
        where = f"{what} of {ep.label}" + (f" (loop {seg['loop']})" if len(index) > 1 else "")
        # the segment's replay: the step's segment, then those its load steps start (events split segments)
        parts = [s for s in metrics["segments"] if s["loop"] == seg["loop"]
                 and seg["start_step"] * LONG_HOLD <= s["start_step"] < seg["end_step"] * LONG_HOLD]
        if not parts:
            t.failures.append(Failure("settles", f"leaves {where} unsettled", "", ep.label))
            continue
        times = [p["SettlingTime"] if _is_step(p) else p["RecoveryTime"] for p in parts]
        if all(math.isfinite(x) for x in times):
            hold = (seg["end_step"] - seg["start_step"]) * ep.config.sample_time_s
            detail = f"{times[0]:.4g} s after {'the step' if step else 'it starts'}"
            if len(parts) > 1:  # the hold's random load step too: what did not settle may be its recovery
                detail += f", the load step in its hold recovered {max(times[1:]):.4g} s after the load"
            t.slow.append(f"{where}: settles within a {LONG_HOLD}x longer hold ({detail}; its hold is {hold:.4g} s)")
            continue
        twin = next(p for p, x in zip(parts, times) if not math.isfinite(x))
        limit = _at_limit(traj, twin, i, config)
        if step and limit is not None:
            t.excused.append(f"setpoint {target:.4g} ({where}): no input within the limits holds it, the command "
                             f"stays at its {limit} for the last {LIMIT_TAIL:.0%} of a {LONG_HOLD}x longer hold "
                             "with the measurement short of the setpoint")
            continue
        ratio = math.nan if step or not noise_free(config) else _decay(traj, twin, i, target)
        if ratio <= CONVERGING:  # a disturbance still being recovered; a step must settle within the long hold
            t.slow.append(f"{where}: still converging at the end of a {LONG_HOLD}x longer hold (its largest error over "
                          f"the last {LIMIT_TAIL:.0%} is {ratio:.0%} of that over the {LIMIT_TAIL:.0%} before)")
            continue
        t.failures.append(Failure("settles", f"leaves {where} unsettled, also with a {LONG_HOLD}x longer hold "
                                             f"({_how(traj, twin, i, target)})",
                                  "more gain where the loop is sluggish (a gain range that contains it), integral "
                                  "action (a finite Ti), or a setpoint range the plant can follow"))


def _tail(seg: dict) -> slice:
    n = seg["end_step"] - seg["start_step"]
    return slice(seg["end_step"] - max(3, int(LIMIT_TAIL * n)), seg["end_step"])


def _at_limit(traj, seg: dict, i: int, config: TuningConfig) -> str | None:
    """"upper limit u_max = ..." / "lower limit ..." when the command sits at it over the segment's tail while the
    measurement stays short of the setpoint on the side it came from; None otherwise."""
    loop = config.loops[i]
    if not (math.isfinite(loop.u_min) and math.isfinite(loop.u_max)):
        return None
    tail = _tail(seg)
    u = np.asarray(traj.pid_output)[tail.start:min(tail.stop, len(traj.pid_output)), i]
    y = np.asarray(traj.measurement)[tail, i]
    delta, r = seg["StepSize"], float(traj.setpoint[seg["start_step"], i])
    if u.size == 0 or not math.isfinite(delta) or delta == 0:
        return None
    short = bool(np.all(np.sign(delta) * (y - r) < 0))
    tol = LIMIT_TOLERANCE * (loop.u_max - loop.u_min)
    if short and np.all(u >= loop.u_max - tol):
        return f"upper limit u_max = {loop.u_max:g}"
    if short and np.all(u <= loop.u_min + tol):
        return f"lower limit u_min = {loop.u_min:g}"
    return None


def _decay(traj, seg: dict, i: int, target: float) -> float:
    """The largest |target - y| over the segment's last LIMIT_TAIL over the largest over the LIMIT_TAIL before it
    (below 1: the error is shrinking; NaN where the segment is too short or the earlier error is 0)."""
    tail = _tail(seg)
    n = tail.stop - tail.start
    if tail.start - n < seg["start_step"]:
        return math.nan
    y = np.asarray(traj.measurement)[:, i]
    last = float(np.max(np.abs(target - y[tail])))
    before = float(np.max(np.abs(target - y[tail.start - n:tail.start])))
    return last / before if before > 0 else math.nan


def _how(traj, seg: dict, i: int, target: float) -> str:
    """In words: an offset (the mean error over the segment's last LIMIT_TAIL) or an oscillation (its peak to
    peak there)."""
    y = np.asarray(traj.measurement)[_tail(seg), i]
    offset = float(np.mean(target - y))
    swing = float(np.ptp(y))
    if abs(offset) > swing:
        return f"a sustained offset of {offset:.3g} over the last {LIMIT_TAIL:.0%} of the long hold"
    return f"still swinging {swing:.3g} peak to peak over the last {LIMIT_TAIL:.0%} of the long hold"
