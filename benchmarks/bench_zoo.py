"""The plant zoo: tune every zoo plant with the tool's CLI and judge what it deployed, independently.

    python benchmarks/bench_zoo.py --set dev                      # the development set
    python benchmarks/bench_zoo.py --set check --timesteps 4096   # the check set (measure when a change is done)
    python benchmarks/bench_zoo.py --plants fopdt_lag_T10 vandevusse --out runs/zoo

The zoo (benchmarks/zoo/zoo.yaml; scenarios in benchmarks/zoo/scenarios/, plant sources in benchmarks/zoo/plants/):
Astrom & Hagglund's PID test batch on one parameterised linear FMU (LinearBatch: lag- and delay-dominated first
order + delay, second order + delay, high order, right-half-plane zero, integrating, oscillatory, unstable and
conditionally stable, several parameter values each) and five nonlinear plants. The split into a development set
and a check set is fixed in zoo.yaml.

Per plant this runs `prlpid-fmi tune SCENARIO --timesteps N --out OUT/<plant>` (skipped when OUT/<plant> already
holds a finished run, so an interrupted benchmark resumes), reads what was deployed (metrics.json "deployed") and
the verdict (report.md's first line under "## Verdict"), and judges it with code of its own:

- Replay: the deployed table (schedule.csv; fixed_pid.csv where nothing is deployed) is replayed on the FMU by a
  PID written here from the law's documented equations (prlpid_fmi/control/pid.py's docstring, the CSV header):
  2-DOF positional PID, e = r - y, ep = b r - yf, ed = c r - yf, I(k) = I(k-1) + e Ts, D = (ed(k) - ed(k-1))/Ts
  (ed(-1) := ed(0)), u = Kp (ep + Td D) + Kp/Ti I, clipped to the actuator limits with clamping (conditional
  integration), the measurement filter of order 1 or 2 (backward-Euler sections of Tf/order, started at y(0)),
  bumpless start I(-1) = (u0 - Kp (b - 1) y0)/Ki from the actuator's start value, and bumpless gain changes of a
  schedule (the error sum rescaled so that u does not jump), the gains interpolated linearly in the scheduling
  variable (the setpoint r, the measurement y or the error r - y of the loop; at a steady state, where a
  linearisation is taken, the error's row is that of error 0).
  No import of the tool's PID, replay or metrics.
- Checks, each on the scenario's evaluation and on HELD_OUT seeded episodes of the training distribution (random
  setpoints from setpoint_range every setpoint_hold_steps; setpoint steps only, no load steps):
  diverges (|r - y| beyond divergence_bound x measurement_scale, or not finite); a step that does not settle
  (|y - r| <= 2 % of the step over the last 10 % of its hold, at least 3 samples) is replayed with a hold 4x as
  long: settled then = slow, else unsettled (a setpoint no input within the limits holds at steady state is
  excused); overshoot > max(25 %, deploy.max_overshoot); chatter (the fraction of samples where u reverses with
  both moves > 1 % of the actuator span) > 5 %; Ms above deploy.max_sensitivity, on the plant's model sampled with
  a zero-order hold (the linear batch exactly; a nonlinear plant linearised at the low, middle and high setpoint).
- Verdict's correctness: a deploy whose replay fails a check is a FALSE DEPLOY; "nothing safe" (deployed none)
  where the benchmark's own reference PID passes every check is a MISS. The reference PID: on a linear plant the
  load-IAE optimum at Ms <= deploy.max_sensitivity (bench_pid_design.optimum) with b by the tool's grid rule
  (bench_pid_design.b_rule); on a nonlinear plant the least mean load IAE over the three linearisations with the
  worst Ms <= the limit (differential evolution), b by the rule at the middle one; replayed through the same
  checks.
- Linear plants: the deployed controller's load IAE (unit load step at the plant input) and setpoint ISE (unit
  step, its own b) against the benchmark's independent optima of the same law (bench_pid_design: the load optimum
  at Ms <= 2; the setpoint optimum over (Kp, Ti, Td, b) with load IAE <= baseline.load_tolerance x that optimum,
  overshoot <= deploy.max_overshoot, Ms <= 2); and its load IAE against SIMC (Skogestad 2003, tau_c set) and AMIGO
  (Astrom & Hagglund 2004, Kp scaled) tuned to the same Ms as the deployed controller (ratio > 1: the rule is
  better at equal Ms). SIMC / AMIGO from the step response's FOPDT (stable, non-oscillatory plants) or the
  integrating form (integrating plants); none for the unstable, oscillatory and conditionally stable ones.
  The optima are cached in OUT/<plant>/zoo_optima.json.

Output: a markdown table per set on stdout, also OUT/zoo_table.md, and OUT/zoo_results.json.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import importlib.util
import json
import math
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import yaml
from scipy import optimize

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
ZOO = HERE / "zoo"
FMU_DIR = ZOO / "fmus"
HELD_OUT = 5              # held-out episodes per plant
HELD_OUT_SEED = 20261204
SETTLE_BAND = 0.02        # of the step
CHATTER_LIMIT = 0.05
CHATTER_MOVE = 0.01       # of the actuator span
OVERSHOOT_FLOOR = 25.0    # %: the acceptance limit is max(25 %, deploy.max_overshoot)
SLOW_FACTOR = 4


def _load(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


bpd = _load(HERE / "bench_pid_design.py", "bench_pid_design")
models = _load(ZOO / "models.py", "zoo_models")


# ----------------------------------------------------------------------------------------- the zoo

@dataclass
class ZooPlant:
    name: str
    set: str
    family: str
    scenario: Path
    raw: dict
    fmu: Path
    fmu_name: str
    params: dict            # the model's defaults overlaid with the scenario's parameters
    Ts: float
    input: str
    output: str
    u_limits: tuple
    setpoint_range: tuple
    scale: float
    bound: float
    gains: dict
    u0: float               # the actuator's start value (the FMU input's start)
    linear: bool

    @property
    def span(self) -> float:
        return self.u_limits[1] - self.u_limits[0]


def zoo_plants() -> list[ZooPlant]:
    index = yaml.safe_load((ZOO / "zoo.yaml").read_text())["plants"]
    out = []
    for entry in index:
        path = ZOO / "scenarios" / f"{entry['name']}.yaml"
        raw = yaml.safe_load(path.read_text())
        pl = raw["plant"]
        fmu = (path.parent / pl["fmu"]).resolve()
        model = yaml.safe_load((ZOO / "plants" / fmu.stem / "model.yaml").read_text())
        params = {v["name"]: float(v["start"]) for v in model["variables"] if v.get("causality") == "parameter"}
        params.update({k: float(v) for k, v in (pl.get("parameters") or {}).items()})
        loop = pl["loops"][0]
        u0 = next(float(v["start"]) for v in model["variables"] if v["name"] == loop["input"])
        out.append(ZooPlant(entry["name"], entry["set"], entry["family"], path, raw, fmu, fmu.stem, params,
                            float(pl["sample_time"]), loop["input"], loop["output"],
                            tuple(float(x) for x in loop["u_limits"]), tuple(float(x) for x in loop["setpoint_range"]),
                            float(loop.get("measurement_scale", 1.0)), float(loop.get("divergence_bound", 100.0)),
                            loop["gains"], u0, fmu.stem == "LinearBatch"))
    return out


def build_fmus(plants: list[ZooPlant]) -> None:
    from prlpid_fmi.fmu import build_fmu
    for name in sorted({p.fmu_name for p in plants}):
        build_fmu(name, out_dir=FMU_DIR, source_dir=ZOO / "plants" / name)


# ----------------------------------------------------------------------------------------- the tune

def tune(plant: ZooPlant, out: Path, timesteps: int, log) -> float:
    """Run `prlpid-fmi tune` unless out/<plant>/metrics.json exists; seconds taken (0 when reused)."""
    run = out / plant.name
    if (run / "metrics.json").is_file() or (out / f"{plant.name}.failed").is_file():
        return 0.0
    if run.exists():   # an unfinished run: the tool never overwrites a run directory
        run.rename(run.with_name(f"{run.name}.unfinished.{int(time.time())}"))
    t0 = time.time()
    cmd = [sys.executable, "-m", "prlpid_fmi", "tune", str(plant.scenario), "--timesteps", str(timesteps),
           "--out", str(run)]
    with open(out / f"{plant.name}.log", "w") as f:
        rc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, cwd=REPO).returncode
    log(f"{plant.name}: tune exit {rc} after {time.time() - t0:.0f} s")
    if rc != 0:   # remembered: a rerun does not repeat a refused tune (delete OUT/<plant>.failed to retry)
        (out / f"{plant.name}.failed").write_text(f"exit {rc}\n")
    return time.time() - t0


def verdict_line(run: Path) -> str:
    lines = (run / "report.md").read_text().splitlines() if (run / "report.md").is_file() else []
    for i, line in enumerate(lines):
        if line.strip().lower() == "## verdict":
            for nxt in lines[i + 1:]:
                if nxt.strip():
                    return nxt.strip()
    return next((l.strip() for l in lines if l.strip() and not l.startswith("#")), "(no report.md)")


# ------------------------------------------------------------------------------- the gain table

@dataclass
class Table:
    """A gain table as written by the tool (its CSV header names the law's options)."""
    variable: str           # setpoint | measurement | error (r - y)
    points: np.ndarray      # breakpoints (K,)
    Kp: np.ndarray
    Ti: np.ndarray
    Td: np.ndarray
    b: np.ndarray
    c: np.ndarray
    Tf: np.ndarray
    order: int
    anti_windup: str
    derivative_N: float | None
    header: str

    def at(self, s: float) -> tuple[float, ...]:
        """(Kp, Ti, Td, b, c, Tf) at scheduling value s: linear between breakpoints, held outside."""
        if len(self.points) == 1:
            i = 0
            return tuple(float(a[i]) for a in (self.Kp, self.Ti, self.Td, self.b, self.c, self.Tf))
        return tuple(float(np.interp(s, self.points, a)) for a in (self.Kp, self.Ti, self.Td, self.b, self.c, self.Tf))

    def at_rest(self, r: float) -> tuple[float, ...]:
        """The gains in force at a steady state at setpoint r (y = r, error 0)."""
        return self.at(0.0 if self.variable == "error" else r)

    def gain_sets(self) -> list[tuple[float, ...]]:
        return [self.at(float(p)) for p in self.points]


class NotReplayed(Exception):
    """A table whose law this benchmark's replay does not implement (that plant's row says so)."""


def read_table(path: Path) -> Table:
    meta, rows, head = {}, [], None
    text = path.read_text()
    for line in text.splitlines():
        if line.startswith("#"):
            k, _, v = line[1:].partition(":")
            meta[k.strip()] = v.strip()
        elif head is None:
            head = [h.strip() for h in line.split(",")]
        elif line.strip():
            rows.append([float(x) for x in line.split(",")])
    a = np.array(rows)
    col = {h.split("[")[0]: i for i, h in enumerate(head)}
    var = head[0].split("[")[0]
    if var not in ("setpoint", "measurement", "error"):
        raise NotReplayed(f"{path}: scheduling variable {head[0]} is not replayed by this benchmark")
    if meta.get("u_rate_limit[" + head[0].split("[")[1], "inf").strip() not in ("inf", ""):
        raise NotReplayed(f"{path}: an output rate limit is not replayed by this benchmark")
    n = meta.get("derivative_filter_N", "none")
    order = int(meta.get("measurement_filter_order", "1"))
    Ti = a[:, col["Ti"]]
    return Table(var, a[:, 0], a[:, col["Kp"]], Ti, a[:, col["Td"]], a[:, col["b"]], a[:, col["c"]], a[:, col["Tf"]],
                 order, meta.get("anti_windup", "clamping"), None if n in ("none", "") else float(n), text[:2000])


# ------------------------------------------------------------------------------- the replay PID

class ReplayPID:
    """The tool's documented law, written here (module docstring). One loop."""

    def __init__(self, table: Table, Ts: float, u_limits: tuple):
        if table.anti_windup not in ("clamping", "none"):
            raise NotReplayed(f"anti-windup {table.anti_windup} is not replayed by this benchmark")
        self.t, self.Ts, (self.lo, self.hi) = table, Ts, u_limits

    def start(self, y0: float, r0: float, u0: float):
        self.first = True
        self.y0, self.u0 = y0, u0
        self.prev_gains = None

    def step(self, r: float, y: float) -> float:
        t, Ts = self.t, self.Ts
        s = r if t.variable == "setpoint" else y if t.variable == "measurement" else r - y
        Kp, Ti, Td, b, c, Tf = t.at(s)
        Ki = Kp / Ti if math.isfinite(Ti) and Ti > 0 else 0.0
        if self.first:
            T = Tf / t.order
            self.x = [y] * t.order
            self.T = T
            self.I = (self.u0 - Kp * ((b - 1.0) * y)) / Ki if Ki != 0 else 0.0
            self.Df = 0.0
        # measurement filter (its Tf from the table's current row; the zoo's tables have one Tf)
        if self.T > 0 and not self.first:
            inp = y
            for j in range(t.order):
                self.x[j] = (self.T * self.x[j] + Ts * inp) / (self.T + Ts)
                inp = self.x[j]
        yf = self.x[-1] if self.T > 0 else y
        if not self.first and self.prev_gains != (Kp, Ti, Td) and Ki != 0:   # bumpless gain change
            Kp0, Ti0, Td0 = self.prev_gains
            Ki0 = Kp0 / Ti0 if math.isfinite(Ti0) and Ti0 > 0 else 0.0
            v = Kp0 * (self.ep + Td0 * self.D) + Ki0 * self.I
            self.I = (v - Kp * (self.ep + Td * self.D)) / Ki
        e = r - y
        ep, ed = b * r - yf, c * r - yf
        if self.first:
            self.ed = ed
        D = (ed - self.ed) / Ts
        if t.derivative_N:
            Tdf = Td / t.derivative_N
            D = (Tdf * self.Df + Ts * D) / (Tdf + Ts) if Tdf > 0 else D
            self.Df = D
        I_try = self.I + e * Ts
        u_try = Kp * (ep + Td * D) + Ki * I_try
        if t.anti_windup == "clamping" and ((u_try > self.hi and Kp * e > 0) or (u_try < self.lo and Kp * e < 0)):
            pass
        else:
            self.I = I_try
        self.ed, self.ep, self.D = ed, ep, D
        self.prev_gains = (Kp, Ti, Td)
        self.first = False
        return min(max(u_try, self.lo), self.hi)


def run_loop(plant: ZooPlant, table: Table, setpoints: list[tuple[int, float]], n: int):
    """(y (n+1,), u (n,), r (n,)) of the closed loop on the FMU from its start: r from the (at_step, value)
    schedule; stops early (returns shorter arrays) when the loop diverges."""
    from prlpid_fmi.fmu import FmuPlant
    r = np.empty(n)
    for (k0, v), nxt in zip(setpoints, setpoints[1:] + [(n, None)]):
        r[k0:nxt[0]] = v
    pid = ReplayPID(table, plant.Ts, plant.u_limits)
    ys, us = [], []
    params = plant.raw["plant"].get("parameters") or None
    with FmuPlant(plant.fmu, inputs=[plant.input], outputs=[plant.output], sample_time_s=plant.Ts,
                  parameters=params) as fmu:
        y = fmu.read_outputs()[0]
        pid.start(y, r[0], plant.u0)
        ys.append(y)
        for k in range(n):
            if not math.isfinite(y) or abs(r[k] - y) > plant.bound * plant.scale:
                break
            u = pid.step(r[k], y)
            y = fmu.step([u])[0]
            ys.append(y)
            us.append(u)
    return np.array(ys), np.array(us), r[:len(us)]


def holdable(plant: ZooPlant, r: float) -> bool:
    """Whether an input within the limits holds output r at steady state (the zoo's own models)."""
    lo, hi = plant.u_limits
    if plant.linear:
        num, den, _ = models.linear_model(plant.params)
        if abs(den[-1]) < 1e-15:
            return True          # integrating: u = 0 holds any output
        u = r * den[-1] / num[-1]
    else:
        nl = models.NONLINEAR[plant.fmu_name]
        try:
            u = nl.u_of_y(r, {**nl.defaults, **plant.params})
        except ValueError:
            return False
    return lo - 1e-9 <= u <= hi + 1e-9


@dataclass
class Replay:
    steps: int = 0
    settled: int = 0
    slow: int = 0
    unsettled: int = 0
    excused: list = field(default_factory=list)
    diverged: bool = False
    overshoot: float = 0.0   # worst, % of the step
    chatter: float = 0.0     # worst episode

    def add(self, other: Replay) -> None:
        self.steps += other.steps
        self.settled += other.settled
        self.slow += other.slow
        self.unsettled += other.unsettled
        self.excused += other.excused
        self.diverged |= other.diverged
        self.overshoot = max(self.overshoot, other.overshoot)
        self.chatter = max(self.chatter, other.chatter)


def chatter(u: np.ndarray, span: float) -> float:
    """Fraction of samples k = 2..n-1 where u reverses direction with both moves above CHATTER_MOVE of span."""
    if len(u) < 3:
        return 0.0
    du = np.diff(u)
    big = np.abs(du) > CHATTER_MOVE * span
    rev = (du[1:] * du[:-1] < 0) & big[1:] & big[:-1]
    return float(np.sum(rev)) / (len(u) - 2)


def _settled(y: np.ndarray, r: float, step: float) -> bool:
    tail = max(3, len(y) // 10)
    return len(y) >= tail and bool(np.all(np.abs(y[-tail:] - r) <= SETTLE_BAND * abs(step)))


def replay_episode(plant: ZooPlant, table: Table, setpoints: list[tuple[int, float]], n: int) -> Replay:
    """Run the episode and judge every setpoint step (module docstring)."""
    y, u, r = run_loop(plant, table, setpoints, n)
    out = Replay()
    if len(u) < n:
        out.diverged = True
    out.chatter = chatter(u, plant.span)
    base = y[0]
    ends = [k for k, _ in setpoints[1:]] + [n]
    for i, ((k0, v), k1) in enumerate(zip(setpoints, ends)):
        step = v - base
        base = v
        if abs(step) < 1e-12 * max(1.0, abs(v)) or k0 >= len(u):
            continue
        out.steps += 1
        if not holdable(plant, v):
            out.excused.append(v)
            continue
        seg = y[k0 + 1:k1 + 1]
        if len(seg):
            out.overshoot = max(out.overshoot, 100.0 * max(0.0, float(np.max((seg - v) * np.sign(step)))) / abs(step))
        if len(seg) == k1 - k0 and _settled(seg, v, step):
            out.settled += 1
            continue
        if out.diverged and k1 > len(u):
            out.unsettled += 1
            continue
        # the same episode up to this step, its hold four times as long
        longer = setpoints[:i + 1]
        m = k0 + SLOW_FACTOR * (k1 - k0)
        y4, u4, _ = run_loop(plant, table, longer, m)
        if len(u4) == m and _settled(y4[k0 + 1 + (SLOW_FACTOR - 1) * (k1 - k0):], v, step):
            out.slow += 1
        else:
            out.unsettled += 1
    return out


def evaluation_schedule(plant: ZooPlant) -> tuple[list[tuple[int, float]], int]:
    ev = plant.raw["evaluation"]
    return [(int(s["at_step"]), float(s["value"])) for s in ev["setpoints"]], int(ev["episode_steps"])


def held_out_schedules(plant: ZooPlant) -> list[tuple[list[tuple[int, float]], int]]:
    tr = plant.raw.get("training") or {}
    n, hold = int(tr.get("episode_steps", 200)), int(tr.get("setpoint_hold_steps", 100))
    rng = np.random.default_rng(HELD_OUT_SEED)
    lo, hi = plant.setpoint_range
    return [([(k, float(rng.uniform(lo, hi))) for k in range(0, n, hold)], n) for _ in range(HELD_OUT)]


# ------------------------------------------------------------------------------- linear models, Ms

def bpd_plant(plant: ZooPlant, num, den, delay) -> "bpd.Plant":
    """A bench_pid_design.Plant for a model (num, den, delay) of this zoo plant; the search box is the scenario's
    gain box widened 10x (Kp, Ti) and 2x (Td), log10 Kp of |Kp| with the box's sign."""
    g = plant.gains
    kp = [abs(float(x)) for x in g["Kp"][:2]]
    sign = -1.0 if float(g["Kp"][0]) < 0 else 1.0
    L = math.log10
    bounds = [(L(min(kp) / 10), L(max(kp) * 10)), (L(float(g["Ti"][0]) / 10), L(float(g["Ti"][1]) * 10)),
              (0.0, 2.0 * float(g["Td"][1]))]
    p = bpd.Plant(plant.name, plant.scenario, ZOO / "plants" / plant.fmu_name, False, bounds, kp_sign=sign)
    p.Ts, p.params, p.fmu_name = plant.Ts, plant.params, plant.fmu_name
    p.input_name, p.output_name = plant.input, plant.output
    p.u_limits, p.setpoint_range, p.gain_box = plant.u_limits, plant.setpoint_range, plant.gains
    p.num, p.den, p.delay = np.asarray(num, float), np.asarray(den, float), float(delay)
    return p


def linear_models(plant: ZooPlant) -> list[tuple[float, "bpd.Plant"]]:
    """[(setpoint, bpd.Plant)]: the linear plant once; a nonlinear one linearised at low, middle, high setpoint."""
    if plant.linear:
        num, den, L = models.linear_model(plant.params)
        return [(float("nan"), bpd_plant(plant, num, den, L))]
    from scipy import signal
    nl = models.NONLINEAR[plant.fmu_name]
    p = {**nl.defaults, **plant.params}
    lo, hi = plant.setpoint_range
    out = []
    for r in (lo, 0.5 * (lo + hi), hi):
        A, B, C = models.linearise(nl, r, p)
        num, den = signal.ss2tf(A, B.reshape(-1, 1), C.reshape(1, -1), np.zeros((1, 1)))
        num = np.trim_zeros(np.where(np.abs(num[0]) < 1e-14 * np.max(np.abs(num[0])), 0.0, num[0]), "f")
        out.append((r, bpd_plant(plant, num, den, nl.delay(p))))
    return out


def worst_ms(plant: ZooPlant, table: Table, lin) -> float:
    """Worst Ms of the table's gains on the plant's sampled models (each linearisation with the gains at its
    setpoint; a linear plant with every row of the table)."""
    worst = 0.0
    for r, bp in lin:
        P = bpd.discretise(bp)
        sets = table.gain_sets() if math.isnan(r) else [table.at_rest(r)]
        for Kp, Ti, Td, b, c, Tf in sets:
            loop = bpd.close(P, Kp, Ti, Td, Tf, table.order)
            worst = max(worst, bpd.peak_sensitivity(loop)[0] if loop.stable else math.inf)
    return worst


# ------------------------------------------------------------------------------- judging

@dataclass
class Judged:
    replay_eval: Replay
    replay_held: Replay
    ms: float
    failures: list

    @property
    def passes(self) -> bool:
        return not self.failures


def judge(plant: ZooPlant, table: Table, lin, max_overshoot: float, ms_limit: float) -> Judged:
    sched, n = evaluation_schedule(plant)
    ev = replay_episode(plant, table, sched, n)
    held = Replay()
    for s, m in held_out_schedules(plant):
        held.add(replay_episode(plant, table, s, m))
    ms = worst_ms(plant, table, lin)
    fail = []
    limit = max(OVERSHOOT_FLOOR, 100.0 * max_overshoot)
    for label, rp in (("evaluation", ev), ("held-out", held)):
        if rp.diverged:
            fail.append(f"diverges ({label})")
        if rp.unsettled:
            fail.append(f"{rp.unsettled} step(s) unsettled with a 4x hold ({label})")
        if rp.overshoot > limit:
            fail.append(f"overshoot {rp.overshoot:.0f} % > {limit:.0f} % ({label})")
        if rp.chatter > CHATTER_LIMIT:
            fail.append(f"chatter {100 * rp.chatter:.1f} % ({label})")
    if not ms <= ms_limit * (1 + 1e-6):
        fail.append(f"Ms {ms:.3g} > {ms_limit:g}")
    return Judged(ev, held, ms, fail)


def reference_table(plant: ZooPlant, lin, ms_limit: float, quick: bool, cache: dict) -> tuple[Table, dict]:
    """The benchmark's own PID (module docstring) as a one-row table, and the optima it comes from."""
    if plant.linear:
        bp = lin[0][1]
        P = bpd.discretise(bp)
        if "opt" not in cache:
            opt = bpd.optimum(bp, P, ms_limit, quick)
            cache["opt"] = dict(Kp=opt.Kp, Ti=opt.Ti, Td=opt.Td, iae_unit=opt.iae_unit, Ms=opt.Ms,
                                at_bound=opt.at_bound, seconds=opt.seconds)
        o = cache["opt"]
        gains = (o["Kp"], o["Ti"], o["Td"])
        b, _ = bpd.b_rule(bpd.close(P, *gains))
    else:
        if "ref" not in cache:
            cache["ref"] = nonlinear_reference(lin, ms_limit, quick)
        o = cache["ref"]
        gains = (o["Kp"], o["Ti"], o["Td"])
        b, _ = bpd.b_rule(bpd.close(bpd.discretise(lin[1][1]), *gains)) if o["Ms"] < math.inf else (1.0, None)
    one = np.array([0.0])
    return Table("setpoint", one, one + gains[0], one + gains[1], one + gains[2], one + b, one * 0.0, one * 0.0, 1,
                 "clamping", None, "reference"), cache


def nonlinear_reference(lin, ms_limit: float, quick: bool) -> dict:
    """Least mean load IAE over the linearisations with the worst Ms <= ms_limit (exact penalty), DE + Nelder-Mead."""
    Ps = [(bp, bpd.discretise(bp)) for _, bp in lin]
    bp0 = Ps[0][0]

    def f(x):
        Kp, Ti, Td = bp0.kp_sign * 10 ** x[0], 10 ** x[1], max(x[2], 0.0)
        total, worst = 0.0, 0.0
        for bp, P in Ps:
            loop = bpd.close(P, Kp, Ti, Td)
            if not loop.stable:
                return 1e3 + loop.rho
            worst = max(worst, bpd.peak_sensitivity(loop)[0])
            total += bpd.load_iae(loop)
        return math.log(total / len(Ps)) + bpd.PENALTY * max(0.0, worst - ms_limit)

    t0 = time.time()
    de = optimize.differential_evolution(f, bp0.bounds, seed=0, polish=False, tol=1e-8, init="sobol",
                                         maxiter=20 if quick else 100, popsize=8 if quick else 15)
    res = optimize.minimize(f, de.x, method="Nelder-Mead", bounds=bp0.bounds, options={"maxiter": 1000})
    x = res.x if res.fun <= de.fun else de.x
    Kp, Ti, Td = bp0.kp_sign * 10 ** x[0], 10 ** x[1], max(x[2], 0.0)
    ms = max((bpd.peak_sensitivity(l)[0] if l.stable else math.inf)
             for l in (bpd.close(P, Kp, Ti, Td) for _, P in Ps))
    return dict(Kp=Kp, Ti=Ti, Td=Td, Ms=ms, seconds=time.time() - t0)


# ------------------------------------------------------------------------------- linear ratios

def rule_gains(bp) -> dict:
    """{label: function(knob) -> (Kp, Ti, Td)} of SIMC (knob tau_c / theta) and AMIGO (knob: Kp factor), or {}."""
    den = bp.den
    poles = np.roots(den)
    h = bp.Ts / 2
    if np.any(poles.real > 1e-9) or np.any(np.abs(poles.imag) > 0.1 * np.abs(poles)):
        return {}   # unstable or oscillatory: no FOPDT / integrating model (a repeated pole of (s + 1)^n splits
        #             into roots |imag| ~ eps^(1/n) off the axis: not an oscillation)
    n_int = int(np.sum(np.abs(poles) < 1e-12))
    if n_int > 1:
        return {}
    if n_int == 1:
        if len(bp.num) > 1 and np.any(np.abs(np.roots(bp.num)) < 100):   # zeros: the conditionally stable plant
            return {}
        kv = bp.num[-1] / den[-2]
        lags = [-1.0 / p.real for p in poles if abs(p) >= 1e-12]
        theta = bp.delay + sum(lags) + h   # integrating + lags: the lags as dead time (half rule's crude limit)
        return {"SIMC": lambda k: (1.0 / (kv * (k * theta + theta)), 4.0 * (k * theta + theta), 0.0),
                "AMIGO": lambda k: (k * 0.45 / (kv * theta), 8.0 * theta, 0.5 * theta)}
    K, T, L = bpd.step_fopdt(bp)
    return {"SIMC": lambda k: (1.0 / K * T / (k * L + L), min(T, 4.0 * (k * L + L)), 0.0),   # tau_c = k theta
            "AMIGO": lambda k: (k * bpd.amigo_fopdt(K, T, L)[0],) + tuple(bpd.amigo_fopdt(K, T, L)[1:])}


def at_ms(P, fn, target: float) -> tuple | None:
    """The rule's gains at Ms = target: bisection on log of the knob (Ms falls with SIMC's tau_c and rises with
    AMIGO's Kp factor; the direction is read off the ends)."""
    def ms(k):
        loop = bpd.close(P, *fn(k))
        return bpd.peak_sensitivity(loop)[0] if loop.stable else math.inf
    lo, hi = math.log(0.02), math.log(50.0)
    f_lo, f_hi = ms(math.exp(lo)) - target, ms(math.exp(hi)) - target
    if not (math.isfinite(f_lo) or math.isfinite(f_hi)) or (f_lo > 0) == (f_hi > 0):
        return None
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        fm = ms(math.exp(mid)) - target
        if (fm > 0) == (f_lo > 0):
            lo, f_lo = mid, fm
        else:
            hi = mid
    return fn(math.exp(0.5 * (lo + hi)))


def linear_ratios(plant: ZooPlant, table: Table, lin, cache: dict, load_tol: float, ms_limit: float,
                  max_overshoot: float, quick: bool) -> dict:
    bp = lin[0][1]
    P = bpd.discretise(bp)
    Kp, Ti, Td, b, c, Tf = table.at_rest(0.5 * sum(plant.setpoint_range))   # a schedule: its middle row
    loop = bpd.close(P, Kp, Ti, Td, Tf, table.order)
    out = {}
    if not loop.stable:
        return {"note": "deployed gains unstable on the model"}
    ms = bpd.peak_sensitivity(loop)[0]
    iae = bpd.load_iae(loop)
    N = loop.horizon()
    y, _ = bpd.setpoint_response_tf(loop, 1.0, N, b, with_u=False)
    ise = float(np.sum((1.0 - y) ** 2) * plant.Ts)
    out.update(load_iae=iae, sp_ise=ise, Ms=ms, overshoot=100 * max(0.0, float(np.max(y)) - 1.0))
    o = cache["opt"]
    out["load_ratio"] = iae / o["iae_unit"]
    if "spopt" not in cache:
        bpd.MS_LIMIT, bpd.MAX_OVERSHOOT = ms_limit, max_overshoot
        sp = bpd.setpoint_optimum(bp, P, load_tol * o["iae_unit"], quick, starts=[(o["Kp"], o["Ti"], o["Td"], 0.0)])
        cache["spopt"] = dict(Kp=sp.Kp, Ti=sp.Ti, Td=sp.Td, b=sp.b, ise_unit=sp.ise_unit, violation=sp.violation,
                              seconds=sp.seconds)
    out["sp_ratio"] = ise / cache["spopt"]["ise_unit"]
    for label, fn in rule_gains(bp).items():
        g = at_ms(P, fn, min(ms, ms_limit))
        if g is not None:
            rl = bpd.close(P, *g)
            out[f"vs_{label}"] = iae / bpd.load_iae(rl)
    return out


# ------------------------------------------------------------------------------- one plant

def assess(plant: ZooPlant, out: Path, quick: bool) -> dict:
    from prlpid_fmi.scenario.load import load_scenario
    run = out / plant.name
    s = load_scenario(plant.scenario)
    ms_limit, max_os = float(s.deploy.max_sensitivity), float(s.deploy.max_overshoot)
    load_tol = float(s.baseline.load_tolerance)
    lin = linear_models(plant)
    if not (run / "metrics.json").is_file():   # tune refused the scenario or failed: judged by the reference alone
        log = (out / f"{plant.name}.log").read_text().strip().splitlines() if (out / f"{plant.name}.log").is_file() else []
        cache = {}
        ref_table, cache = reference_table(plant, lin, ms_limit, quick, cache)
        ref = judge(plant, ref_table, lin, max_os, ms_limit)
        return dict(plant=plant.name, set=plant.set, family=plant.family, deployed="tune failed",
                    verdict=(log[-1] if log else "(no log)"), eval=asdict(Replay()), held=asdict(Replay()),
                    Ms=math.nan, failures=[], judged="MISS" if ref.passes else "refused (reference fails too)",
                    reference=dict(gains=[float(ref_table.Kp[0]), float(ref_table.Ti[0]), float(ref_table.Td[0]),
                                          float(ref_table.b[0])], failures=ref.failures, Ms=ref.ms))
    m = json.loads((run / "metrics.json").read_text())
    deployed = str(m.get("deployed"))
    table_path = run / ("schedule.csv" if deployed != "none" and (run / "schedule.csv").is_file() else "fixed_pid.csv")
    table = read_table(table_path)
    cache_path = run / "zoo_optima.json"
    cache = json.loads(cache_path.read_text()) if cache_path.is_file() else {}
    j = judge(plant, table, lin, max_os, ms_limit)
    ref_table, cache = reference_table(plant, lin, ms_limit, quick, cache)
    ref = judge(plant, ref_table, lin, max_os, ms_limit)
    row = dict(plant=plant.name, set=plant.set, family=plant.family, deployed=deployed, verdict=verdict_line(run),
               table=table_path.name, gains=[list(g[:4]) for g in table.gain_sets()],
               eval=asdict(j.replay_eval), held=asdict(j.replay_held), Ms=j.ms, failures=j.failures,
               reference=dict(gains=[float(ref_table.Kp[0]), float(ref_table.Ti[0]), float(ref_table.Td[0]),
                                     float(ref_table.b[0])], failures=ref.failures, Ms=ref.ms))
    if deployed != "none":
        row["judged"] = "FALSE DEPLOY" if j.failures else "ok"
    else:
        row["judged"] = "MISS" if ref.passes else "refused (reference fails too)"
    if plant.linear:
        row["linear"] = linear_ratios(plant, table, lin, cache, load_tol, ms_limit, max_os, quick)
        row["optima"] = {k: cache[k] for k in ("opt", "spopt") if k in cache}
    cache_path.write_text(json.dumps(cache, indent=1))
    return row


# ------------------------------------------------------------------------------- table

def _f(x, fmt="{:.2f}"):
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt.format(x)


def table_md(rows: list[dict], title: str) -> str:
    head = ("| plant | deployed | verdict (report.md) | eval settled | held-out settled | overshoot % | chatter % | Ms "
            "| load IAE / opt | sp ISE / opt | / SIMC | / AMIGO | judged |")
    lines = [f"### {title}", "", head, "|" + "---|" * 13]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['plant']} | error | {r['error'][:80]} |" + " |" * 10)
            continue
        ev, he = r["eval"], r["held"]

        def settled(x):
            s = f"{x['settled']}/{x['steps']}"
            if x["slow"]:
                s += f" ({x['slow']} slow)"
            if x["excused"]:
                s += f" ({len(x['excused'])} excused)"
            return s + (" diverged" if x["diverged"] else "")
        lin = r.get("linear", {})
        verdict = r["verdict"].replace("|", "/")
        verdict = verdict[:70] + ("…" if len(verdict) > 70 else "")
        why = ""
        if r["judged"] != "ok":
            why = ": " + "; ".join(r["failures"] if r["judged"] == "FALSE DEPLOY" else
                                   (r["reference"]["failures"] or ["reference passes"]))
        lines.append(
            f"| {r['plant']} | {r['deployed']} | {verdict} | {settled(ev)} | {settled(he)} | "
            f"{_f(max(ev['overshoot'], he['overshoot']), '{:.1f}')} | "
            f"{_f(100 * max(ev['chatter'], he['chatter']), '{:.1f}')} | {_f(r['Ms'])} | "
            f"{_f(lin.get('load_ratio'))} | {_f(lin.get('sp_ratio'))} | {_f(lin.get('vs_SIMC'))} | "
            f"{_f(lin.get('vs_AMIGO'))} | {r['judged']}{why} |")
    ok = [r for r in rows if "error" not in r]
    fd = sum(r["judged"] == "FALSE DEPLOY" for r in ok)
    miss = sum(r["judged"] == "MISS" for r in ok)
    lines += ["", f"{len(rows)} plants: {fd} false deploys, {miss} misses, {len(rows) - len(ok)} errors."]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plants", nargs="*", help="zoo plant names (default: the whole set)")
    ap.add_argument("--set", choices=("dev", "check", "all"), default="all")
    ap.add_argument("--timesteps", type=int, default=4096, help="training budget of each tune (default 4096)")
    ap.add_argument("--jobs", type=int, default=1, help="tunes run at once (default 1)")
    ap.add_argument("--out", type=Path, default=REPO / "runs" / "zoo")
    ap.add_argument("--quick", action="store_true", help="shorter optimum searches (30 DE generations)")
    args = ap.parse_args(argv)
    plants = zoo_plants()
    known = {p.name for p in plants}
    if args.plants:
        bad = [n for n in args.plants if n not in known]
        if bad:
            print(f"bench_zoo: unknown plant(s) {', '.join(bad)}; expected names from {ZOO / 'zoo.yaml'}",
                  file=sys.stderr)
            return 2
        plants = [p for p in plants if p.name in args.plants]
    if args.set != "all":
        plants = [p for p in plants if p.set == args.set]
    args.out.mkdir(parents=True, exist_ok=True)
    build_fmus(plants)
    t0 = time.time()

    def log(msg):
        print(f"[{time.time() - t0:7.0f} s] {msg}", file=sys.stderr, flush=True)

    def one(p):
        took = tune(p, args.out, args.timesteps, log)
        try:
            t1 = time.time()
            row = assess(p, args.out, args.quick)
            row["tune_seconds"], row["judge_seconds"] = took, time.time() - t1
        except Exception as exc:   # one plant's failure must not lose the others' rows
            row = dict(plant=p.name, set=p.set, error=f"{type(exc).__name__}: {exc}")
        log(f"{p.name}: {row.get('judged', row.get('error'))}")
        return row

    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        rows = list(pool.map(one, plants))
    text = [f"Zoo benchmark, --timesteps {args.timesteps}{' --quick' if args.quick else ''}, "
            f"{time.strftime('%Y-%m-%d')}, {time.time() - t0:.0f} s", ""]
    for s in ("dev", "check"):
        sel = [r for r in rows if r["set"] == s]
        if sel:
            text += [table_md(sel, f"{'Development' if s == 'dev' else 'Check'} set"), ""]
    out = "\n".join(text)
    print(out)
    (args.out / "zoo_table.md").write_text(out + "\n")
    (args.out / "zoo_results.json").write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
