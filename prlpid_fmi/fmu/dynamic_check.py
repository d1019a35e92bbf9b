"""`prlpid-fmi inspect --probe`: dynamic checks of an FMU that a modelDescription validator cannot make.

Each check runs in its own worker process (prlpid_fmi.loop.isolated), so an FMU that crashes gets a
verdict instead of ending the tool. The FMU is driven through its real inputs with a fixed, gently
varying input sequence u_k = start + amplitude * sin(0.7 k) (amplitude 0.1 * max(1, |start|)) at
its default step size (else 0.1 s); outputs are compared bit for bit (NaN equals NaN):

- state: save the state (get FMU state) after HOLD_STEP steps, run on, set the state back and run
  again: the two runs must be identical; with canSerializeFMUstate also through serialize, a second
  instance, deserialize.
- instances: a second instance driven with other inputs must leave the first one's trajectory as it
  is when the first runs alone.
- outputs: finite over the run.
- reset: after a run, reset must give the initial outputs and the same trajectory again.
- memory: resident memory after MEMORY_RESETS resets (each followed by a few steps).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prlpid_fmi.fmu.description import describe_fmu

STEPS = 40
HOLD_STEP = 20
MEMORY_RESETS = 100
MEMORY_WARN_KB_PER_RESET = 64.0
DEFAULT_STEP_S = 0.1


@dataclass(frozen=True)
class Finding:
    """One check's result: verdict PASS | FAIL | WARN | SKIP, and one line saying what was seen."""

    check: str
    verdict: str
    message: str

    def line(self) -> str:
        return f"{self.verdict:<5} {self.check:<10} {self.message}"


def _inputs(path: Path, steps: int) -> tuple[list[str], np.ndarray]:
    d = describe_fmu(path)
    names = list(d.input_names)
    start = np.array([float(d.variable(n).start) if isinstance(d.variable(n).start, (int, float)) else 0.0
                      for n in names])
    k = np.arange(steps)[:, None]
    return names, start + 0.1 * np.maximum(1.0, np.abs(start)) * np.sin(0.7 * k)


def _plant(path: Path, name: str = "probe"):
    from prlpid_fmi.fmu.plant import FmuPlant

    d = describe_fmu(path)
    return FmuPlant(path, list(d.input_names), list(d.output_names), d.default_step_size_s or DEFAULT_STEP_S,
                    instance_name=name)


def _run(plant, u: np.ndarray) -> np.ndarray:
    return np.array([plant.step(row) if len(row) else plant.step([]) for row in u])


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


def _difference(a: np.ndarray, b: np.ndarray) -> str:
    with np.errstate(invalid="ignore"):
        return f"max |difference| {np.nanmax(np.abs(a - b)):.3g}"


def check_state(path: Path) -> list[Finding]:
    d = describe_fmu(path)
    if not d.can_get_and_set_state:
        return [Finding("state", "SKIP", "canGetAndSetFMUstate is false: no state to save")]
    _, u = _inputs(path, STEPS)
    out = []
    with _plant(path) as plant:
        _run(plant, u[:HOLD_STEP])
        plant.hold_state()
        first = _run(plant, u[HOLD_STEP:])
        plant.restore_state()
        again = _run(plant, u[HOLD_STEP:])
        ok = _same(first, again)
        out.append(Finding("state", "PASS" if ok else "FAIL",
                           f"a state saved at t = {HOLD_STEP * plant.sample_time_s:g} s and set back "
                           + ("reproduces the next " f"{STEPS - HOLD_STEP} steps exactly" if ok else
                              f"gives another trajectory ({_difference(first, again)})")))
        if d.can_serialize_state and not d.once_per_process:
            plant.restore_state()
            blob = plant.get_state()
            with _plant(path, "probe-copy") as other:
                other.set_state(blob)
                copied = _run(other, u[HOLD_STEP:])
            ok = _same(first, copied)
            out.append(Finding("state", "PASS" if ok else "FAIL",
                               "the serialized state restored into a second instance " +
                               ("reproduces the trajectory exactly" if ok else
                                f"gives another trajectory ({_difference(first, copied)})")))
        elif d.can_serialize_state:
            out.append(Finding("state", "SKIP", "one instance per process: the serialized state cannot be tried "
                                                "in a second instance"))
        else:
            out.append(Finding("state", "SKIP", "canSerializeFMUstate is false: the state cannot move to another "
                                                "instance (a prior rolls back the plant's own instance)"))
    return out


def check_instances(path: Path) -> list[Finding]:
    d = describe_fmu(path)
    if d.once_per_process:
        return [Finding("instances", "SKIP", "canBeInstantiatedOnlyOncePerProcess: one instance per process")]
    names, u = _inputs(path, STEPS)
    if not names:
        return [Finding("instances", "SKIP", "the FMU has no real inputs to set")]
    with _plant(path) as alone:
        reference = _run(alone, u)
    with _plant(path, "probe-a") as a, _plant(path, "probe-b") as b:
        other = u + 1.0 + np.abs(u)
        traj = []
        for k in range(STEPS):
            b.step(other[k])
            traj.append(a.step(u[k]))
        traj = np.array(traj)
    ok = _same(reference, traj)
    return [Finding("instances", "PASS" if ok else "FAIL",
                    "two instances are independent: other inputs on one leave the other's outputs unchanged" if ok
                    else f"setting {', '.join(names)} on one instance changed the other's outputs "
                         f"({_difference(reference, traj)})")]


def check_reset(path: Path) -> list[Finding]:
    _, u = _inputs(path, STEPS)
    with _plant(path) as plant:
        initial = plant.read_outputs()
        first = _run(plant, u)
        again_initial = plant.raw_reset()
        again = _run(plant, u)
        names, ts = plant.outputs, plant.sample_time_s
    ok_initial, ok_run = _same(initial, again_initial), _same(first, again)
    bad = np.argwhere(~np.isfinite(first) | ((first != 0) & (np.abs(first) < np.finfo(float).tiny)))
    if bad.size:
        k, i = bad[0]
        value = "NaN" if np.isnan(first[k, i]) else repr(float(first[k, i]))
        value += " (a denormal: garbage)" if np.isfinite(first[k, i]) else ""
        outputs = Finding("outputs", "FAIL", f"{names[i]} is {value} at t = {(k + 1) * ts:g} s "
                                             f"(inputs held within 10 % of their start values)")
    else:
        outputs = Finding("outputs", "PASS", f"finite for {STEPS} steps of {ts:g} s")
    if ok_initial and ok_run:
        return [outputs, Finding("reset", "PASS", "reset restores the initial outputs and the same trajectory")]
    what = [] if ok_initial else [f"the initial outputs differ ({_difference(initial, again_initial)})"]
    what += [] if ok_run else [f"the trajectory after reset differs ({_difference(first, again)})"]
    return [outputs, Finding("reset", "FAIL", "; ".join(what))]


def check_memory(path: Path) -> list[Finding]:
    from prlpid_fmi.fmu.plant import rss_bytes

    _, u = _inputs(path, 5)
    with _plant(path) as plant:
        plant.reset()
        _run(plant, u)
        before = rss_bytes()
        if before is None:
            return [Finding("memory", "SKIP", "resident memory is not readable on this platform")]
        for _ in range(MEMORY_RESETS):
            plant.raw_reset()
            _run(plant, u)
        grown = rss_bytes() - before
    per_reset_kb = grown / MEMORY_RESETS / 1024
    verdict = "WARN" if per_reset_kb > MEMORY_WARN_KB_PER_RESET else "PASS"
    return [Finding("memory", verdict, f"after {MEMORY_RESETS} resets: {grown / 2**20:+.1f} MB "
                                       f"({per_reset_kb:.0f} kB per reset"
                                       + ("; the leak guard plant.leak_check_every re-instantiates it)"
                                          if verdict == "WARN" else ")"))]


CHECKS = (check_state, check_instances, check_reset, check_memory)


def dynamic_check(path: str | Path, step_timeout_s: float | None = None) -> list[Finding]:
    """Every check, each in a worker process; a check whose worker dies (a crash, or a call that does not return
    within step_timeout_s [s]: the watchdog's, default measured) is a FAIL naming the call and the time."""
    from prlpid_fmi.fmu.worker import WorkerCrashed, call_in_worker

    path = Path(path)
    describe_fmu(path)  # a PlantError for a file that is no FMU, before any worker starts
    findings = []
    for check in CHECKS:
        name = check.__name__.removeprefix("check_")
        try:
            findings += call_in_worker(check, path, fmus=[path], what=f"the {name} check",
                                       step_timeout_s=step_timeout_s)
        except WorkerCrashed as exc:
            findings.append(Finding(name, "FAIL", str(exc)))
        except Exception as exc:  # noqa: BLE001 - an FMU error is this check's finding
            findings.append(Finding(name, "FAIL", " ".join(str(exc).split())))
    return findings


def format_findings(findings: list[Finding]) -> str:
    return "\n".join(f.line() for f in findings)


def failed(findings: list[Finding]) -> bool:
    return any(f.verdict == "FAIL" for f in findings)


__all__ = ["Finding", "dynamic_check", "format_findings", "failed"]
