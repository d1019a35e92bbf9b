"""The tool's fixed PID against classical PID design, by load-disturbance rejection under a robustness limit.

    python benchmarks/bench_pid_design.py                                  # every plant, full optimum search
    python benchmarks/bench_pid_design.py --quick --plants first_order rc_ladder4

Astrom & Hagglund's criterion for a PID: reject a load disturbance (a step added to the plant input) with
the least IAE, subject to a robustness limit, here Ms = max |S| <= 2. For each plant this measures, on the
sampled linear closed loop (no saturation) and with code of its own (numpy / scipy / python-control; only
the tool's fixed-PID *search* is imported, for its result):

- the tool's fixed PID, found by prlpid_fmi.tuning.fixed_pid.tune_fixed_pid exactly as `tune` calls it;
- SIMC (Skogestad 2003) PI from a first-order-plus-dead-time model (half rule), and SIMC PID from a
  second-order-plus-dead-time model where the plant has one, tau_c = theta;
- AMIGO PID (Astrom & Hagglund 2004) from the FOPDT model of the step response (tangent and 63 % point);
- the Ms <= 2 optimum of load IAE over (Kp, Ti, Td) of the same PID law (differential evolution with an
  exact penalty, then Nelder-Mead polish), and, for the tool, SIMC and AMIGO, the optimum at their own Ms.

Both rule models add half a sample (Ts/2, the zero-order hold) to the dead time; the unstable first-order
plants b/(s - a) are approximated as integrating, b e^(-s Ts/2)/s (both rules' integrating-process forms);
the second-order unstable plant has no such model: no SIMC / AMIGO row. Where no gains in the search box
meet Ms <= 2 (second_order: two unstable poles faster than its right-half-plane zero), the least-Ms PID of
the law is shown instead and the ratios are n/a. A loop whose slowest mode does not decay within N_MAX
samples gets IAE / ISE over that horizon, marked as lower bounds (">="). The tool row's note gives the
tool's own Ms estimate (prlpid_fmi.robustness.margins, on the FMU) next to the one measured here.

PID law (the tool's, prlpid_fmi/control/pid.py, re-implemented here): positional, sample time Ts,
I(k) = I(k-1) + e(k) Ts; D(k) = (e(k) - e(k-1))/Ts with e(-1) := e(0); u(k) = Kp (e(k) + I(k)/Ti + Td D(k)),
unfiltered, no saturation. Its transfer function C(z) = Kp (1 + Ts/Ti z/(z-1) + Td/Ts (z-1)/z); the law
differs from the LTI C(z) only by having no derivative kick at k = 0 (for a setpoint step from rest it acts
as derivative on -y), which the setpoint response includes.
The plant is the FMU's continuous model sampled with a zero-order hold (control.c2d, "zoh"), dead times
as z^-d; a check against the FMU itself (fmpy) runs first.

Columns: load IAE = Ts sum |e(k)| after a load step (unit step for the bundled, normalised plants; 10 % of
the actuator range for the benchmark plants in engineering units); setpoint ISE = Ts sum e(k)^2 and
overshoot for a setpoint step from rest (unit / 10 % of the setpoint range); TV(u) = sum |u(k) - u(k-1)|
on that step, u(-1) = 0; noise gain = std(u) per std of white measurement noise = H2 norm of C S;
Ms = max |S(e^(j w Ts))| on a dense grid to Nyquist, refined around the peak; ratios of load IAE to the
Ms <= 2 optimum and to the optimum at the row's own Ms. Every closed-loop number is checked twice (time
recursion of the law vs transfer functions, Ms vs a simulated sinusoid, H2 by Parseval vs the recursion's
impulse response); the checks of this benchmark's own code run first, as assertions. Nothing about the tool is
asserted: it is a measurement.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import control
import numpy as np
import yaml
from scipy import optimize, signal

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
BENCH_PLANTS = HERE / "plants"
BENCH_SCENARIOS = HERE / "third_party"
FMU_DIR = BENCH_SCENARIOS / "fmus"

MS_LIMIT = 2.0
N_MAX = 400_000          # longest simulation [samples]
DECAY = 1e-12            # simulate until the slowest closed-loop mode has decayed to this
GRID_POINTS = 1500       # frequency grid, geometric in w*Ts from THETA_MIN to pi, then refined at the peak
THETA_MIN = 1e-6
PENALTY = 50.0           # exact penalty on (Ms - limit) in log(IAE)
SEARCH_TIMEOUT_S = 180.0
OWN_MS_MAX = 5.0         # no own-Ms optimum for a row less robust than this


# --------------------------------------------------------------------------------------------- plants

def _yaml(path: Path) -> dict:
    return yaml.safe_load(path.read_text())


@dataclass
class Plant:
    name: str                  # scenario name
    scenario: Path             # scenario file
    model_dir: Path            # plant_sources/<Name> or benchmarks/plants/<Name>
    bundled: bool              # paper plant in normalised units (unit steps) or benchmark plant (10 % steps)
    bounds: list               # optimum search box: (log10|Kp|), (log10 Ti), Td (or log10 Td when td_log)
    kp_sign: float = 1.0
    td_log: bool = False
    # filled by load()
    Ts: float = 0.0
    params: dict = field(default_factory=dict)
    fmu_name: str = ""
    input_name: str = ""
    output_name: str = ""
    u_limits: tuple = ()
    setpoint_range: tuple = ()
    gain_box: dict = field(default_factory=dict)
    num: np.ndarray = None     # continuous model, delay-free part, s-polynomials
    den: np.ndarray = None
    delay: float = 0.0         # dead time [s]

    def load(self) -> "Plant":
        sc = _yaml(self.scenario)
        pl = sc["plant"]
        self.Ts = float(pl["sample_time"])
        self.fmu_name = Path(pl["fmu"]).stem
        model = _yaml(self.model_dir / "model.yaml")
        self.params = {v["name"]: float(v["start"]) for v in model["variables"] if v.get("causality") == "parameter"}
        self.params.update({k: float(v) for k, v in (pl.get("parameters") or {}).items()})
        loop = pl["loops"][0]
        self.input_name, self.output_name = loop["input"], loop["output"]
        self.u_limits = tuple(float(x) for x in loop["u_limits"])
        self.setpoint_range = tuple(float(x) for x in loop["setpoint_range"])
        self.gain_box = loop["gains"]
        self.num, self.den, self.delay = MODELS[self.fmu_name](self.params)
        return self

    @property
    def d(self) -> int:
        """Dead time in samples (the FMUs' dead times are multiples of the sample time here)."""
        d = self.delay / self.Ts
        assert abs(d - round(d)) < 1e-9, f"{self.name}: dead time {self.delay} s is not a multiple of Ts"
        return int(round(d))

    @property
    def load_step(self) -> float:
        return 1.0 if self.bundled else 0.1 * (self.u_limits[1] - self.u_limits[0])

    @property
    def setpoint_step(self) -> float:
        return 1.0 if self.bundled else 0.1 * (self.setpoint_range[1] - self.setpoint_range[0])

    @property
    def gain(self) -> float:
        return self.num[-1] / self.den[-1]


def _lag_power(tau: float, n: int) -> np.ndarray:
    p = np.array([1.0])
    for _ in range(n):
        p = np.polymul(p, [tau, 1.0])
    return p


MODELS = {  # FMU name -> params -> (num(s), den(s), dead time), from each plant's model.c
    # dx/dt = a x + b u, y = x
    "FirstOrderUnstable": lambda p: (np.array([p["b"]]), np.array([1.0, -p["a"]]), 0.0),
    # dx1 = x2, a2 dx2 = u - a1 x2 - a0 x1, y = K (x1 - Tn x2): K (1 - Tn s)/(a2 s^2 + a1 s + a0)
    "SecondOrderUnstable": lambda p: (p["K"] * np.array([-p["Tn"], 1.0]), np.array([p["a2"], p["a1"], p["a0"]]), 0.0),
    # T dT_out/dt = T_in + K valve(t - L) - T_out
    "HeatExchanger": lambda p: (np.array([p["K"]]), np.array([p["T"], 1.0]), p["L"]),
    # tau dv_k/dt = v_{k-1} - v_k, tau = R C, four sections
    "RCLadder4": lambda p: (np.array([1.0]), _lag_power(p["R"] * p["C"], 4), 0.0),
    # T = T_base + K (1 - alpha s) x3, x3 = Q/(1 + tau s)^3
    "InverseResponse": lambda p: (p["K"] * np.array([-p["alpha"], 1.0]), _lag_power(p["tau"], 3), 0.0),
}


def plant_list() -> dict[str, Plant]:
    sc, ps = REPO / "scenarios", REPO / "plant_sources"
    L = math.log10
    plants = [
        Plant("first_order", sc / "first_order.yaml", ps / "FirstOrderUnstable", True,
              [(L(0.5), L(300.0)), (L(0.01), L(100.0)), (0.0, 1.0)]),
        Plant("first_order_1p5", sc / "first_order_1p5.yaml", ps / "FirstOrderUnstable", True,
              [(L(0.5), L(300.0)), (L(0.01), L(100.0)), (0.0, 1.0)]),
        Plant("second_order", sc / "second_order.yaml", ps / "SecondOrderUnstable", True,
              [(L(1e-4), L(10.0)), (L(0.5), L(1e5)), (L(1.0), L(1e5))], kp_sign=-1.0, td_log=True),
        Plant("heat_exchanger_lag", BENCH_SCENARIOS / "heat_exchanger_lag.yaml", BENCH_PLANTS / "HeatExchanger", False,
              [(L(0.05), L(200.0)), (L(0.5), L(2000.0)), (0.0, 30.0)]),
        Plant("heat_exchanger_delay", BENCH_SCENARIOS / "heat_exchanger_delay.yaml", BENCH_PLANTS / "HeatExchanger",
              False, [(L(0.005), L(20.0)), (L(0.2), L(500.0)), (0.0, 30.0)]),
        Plant("rc_ladder4", BENCH_SCENARIOS / "rc_ladder4.yaml", BENCH_PLANTS / "RCLadder4", False,
              [(L(0.01), L(50.0)), (L(0.1), L(100.0)), (0.0, 5.0)]),
        Plant("inverse_response", BENCH_SCENARIOS / "inverse_response.yaml", BENCH_PLANTS / "InverseResponse", False,
              [(L(1e-4), L(2.0)), (L(0.5), L(1000.0)), (0.0, 60.0)]),
    ]
    return {p.name: p for p in plants}


# ----------------------------------------------------------------------------------- discrete models

@dataclass
class Discrete:
    """ZOH-sampled plant: state space (A, B, C) of the delay-free part, d samples of input delay, and
    P(z) = Np(z)/Dp(z) (positive powers of z, delay included)."""
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    d: int
    Np: np.ndarray
    Dp: np.ndarray
    Ts: float
    zeros: np.ndarray          # roots of Np (for the closed-loop sos)


def _strip(p: np.ndarray) -> np.ndarray:
    p = np.atleast_1d(np.asarray(p, dtype=float))
    nz = np.flatnonzero(np.abs(p) > 1e-14 * np.max(np.abs(p)))
    return p[nz[0]:] if nz.size else np.array([0.0])


def discretise(plant: Plant) -> Discrete:
    Pc = control.tf(plant.num, plant.den)
    sd = control.c2d(control.ss(Pc), plant.Ts, method="zoh")
    assert np.allclose(np.asarray(sd.D), 0.0), "strictly proper plants only"
    td = control.c2d(Pc, plant.Ts, method="zoh")
    Np = _strip(np.asarray(td.num[0][0], dtype=float))
    Dp = np.polymul(np.asarray(td.den[0][0], dtype=float), np.r_[1.0, np.zeros(plant.d)])
    return Discrete(np.asarray(sd.A), np.asarray(sd.B).ravel(), np.asarray(sd.C).ravel(), plant.d, Np, Dp,
                    plant.Ts, np.roots(Np))


def pid_poly(Kp: float, Ti: float, Td: float, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """C(z) = Nc/Dc with Dc = z(z - 1): Kp [z(z-1) + Ts/Ti z^2 + Td/Ts (z-1)^2]."""
    ki = Ts / Ti if math.isfinite(Ti) else 0.0
    Nc = Kp * (np.array([1.0, -1.0, 0.0]) + ki * np.array([1.0, 0.0, 0.0]) + Td / Ts * np.array([1.0, -2.0, 1.0]))
    return Nc, np.array([1.0, -1.0, 0.0])


def pid_tf(Kp, Ti, Td, Ts) -> control.TransferFunction:
    Nc, Dc = pid_poly(Kp, Ti, Td, Ts)
    return control.tf(Nc, Dc, Ts)


# ------------------------------------------------------------------ time recursion of the law (truth)

def simulate(P: Discrete, Kp, Ti, Td, N: int, r=None, load=None, noise=None, b=None, lti_start=False):
    """The closed loop sample by sample. r, load (added to the plant input), noise (added to the
    measurement): arrays of N or None. b None: the tool's law (derivative on e, e(-1) := e(0), or e(-1) = 0
    with lti_start); b in [0, 1]: 2-DOF law, P term on b r - y, derivative on -y with y(-1) := y(0).
    Returns (y, u) of the plant output and the controller output, shape (N,)."""
    zero = np.zeros(N)
    r = zero if r is None else np.asarray(r, float)
    load = zero if load is None else np.asarray(load, float)
    noise = zero if noise is None else np.asarray(noise, float)
    A, B, C, d, Ts = P.A, P.B, P.C, P.d, P.Ts
    inv_ti = 1.0 / Ti if math.isfinite(Ti) else 0.0
    x = np.zeros(A.shape[0])
    v = np.zeros(N + d)                     # plant input; v[k] acts at k + d
    y_out, u_out = np.empty(N), np.empty(N)
    I = 0.0
    prev = None
    for k in range(N):
        y = float(C @ x)
        ym = y + noise[k]
        e = r[k] - ym
        I += e * Ts
        if b is None:
            if prev is None:
                prev = 0.0 if lti_start else e
            D = (e - prev) / Ts
            prev = e
            u = Kp * (e + I * inv_ti + Td * D)
        else:
            if prev is None:
                prev = ym
            D = -(ym - prev) / Ts
            prev = ym
            u = Kp * (b * r[k] - ym + I * inv_ti + Td * D)
        v[k + d] = u + load[k]
        x = A @ x + B * v[k]
        y_out[k], u_out[k] = y, u
    return y_out, u_out


# ------------------------------------------------------------------------- transfer-function path

@dataclass
class Loop:
    P: Discrete
    Kp: float
    Ti: float
    Td: float
    Nc: np.ndarray
    Dc: np.ndarray
    Dcl: np.ndarray
    poles: np.ndarray

    @property
    def rho(self) -> float:
        return float(np.max(np.abs(self.poles)))

    @property
    def stable(self) -> bool:
        return self.rho < 1.0 - 1e-9

    def needed(self) -> int:
        """Samples until the slowest mode has decayed to DECAY (uncapped)."""
        rho = self.rho
        n = 200 if rho <= 0 else math.log(DECAY) / math.log(max(rho, 1e-300))
        return int(max(200, min(math.ceil(n), 10**15) + 5 * self.P.d + 50))

    def horizon(self) -> int:
        return min(N_MAX, self.needed())

    @property
    def truncated(self) -> bool:
        return self.needed() > N_MAX

    def response(self, num: np.ndarray, x: np.ndarray, zeros: np.ndarray | None = None) -> np.ndarray:
        """Output of num(z)/Dcl(z) for input x (proper, zero initial state), as second-order sections."""
        num = _strip(num)
        lead = num[0] / self.Dcl[0]
        z = np.roots(num) if zeros is None else zeros
        rel = len(self.Dcl) - len(num)  # relative degree: a delay of rel samples
        sos = signal.zpk2sos(np.r_[z, np.zeros(rel)], self.poles, lead)  # z^rel num/Dcl, biproper
        y = signal.sosfilt(sos, x)
        return np.r_[np.zeros(rel), y[:len(y) - rel]] if rel else y

    def S(self, theta: np.ndarray) -> np.ndarray:
        z = np.exp(1j * theta)
        return np.polyval(np.polymul(self.P.Dp, self.Dc), z) / np.polyval(self.Dcl, z)


def close(P: Discrete, Kp, Ti, Td) -> Loop:
    Nc, Dc = pid_poly(Kp, Ti, Td, P.Ts)
    Dcl = np.polyadd(np.polymul(P.Dp, Dc), np.polymul(P.Np, Nc))
    return Loop(P, Kp, Ti, Td, Nc, Dc, Dcl, np.roots(Dcl))


THETA_GRID = np.geomspace(THETA_MIN, math.pi, GRID_POINTS)


def peak_sensitivity(loop: Loop) -> tuple[float, float]:
    """(Ms, w*Ts of the peak): max |S| on THETA_GRID, then three times refined on a 41-point grid
    between the neighbours of the peak."""
    grid = THETA_GRID
    mag = np.abs(loop.S(grid))
    for _ in range(3):
        i = int(np.argmax(mag))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        grid = np.linspace(lo, hi, 41)
        mag = np.abs(loop.S(grid))
    i = int(np.argmax(mag))
    return float(mag[i]), float(grid[i])


def load_iae(loop: Loop, step: float = 1.0) -> float:
    N = loop.horizon()
    y = loop.response(np.polymul(loop.P.Np, loop.Dc), np.full(N, step),
                      zeros=np.r_[loop.P.zeros, 0.0, 1.0])
    return float(np.sum(np.abs(y)) * loop.P.Ts)


def setpoint_response_tf(loop: Loop, step: float, N: int, b: float = 1.0):
    """(y, u) for a setpoint step at k = 0 from rest. Under the tool's law e(-1) := e(0) = r and y(-1) = 0,
    so D(k) = -(y(k) - y(k-1))/Ts for every k: the law is then the 2-DOF law with b = 1 and the derivative on
    -y, u = Cff r - C y with Cff = Kp (b + Ts/Ti z/(z-1)) (run_checks verifies the missing kick separately).
    y/r = P Cff S, u/r = Cff S."""
    r = np.full(N, step)
    Kp, Ti, Ts = loop.Kp, loop.Ti, loop.P.Ts
    ki = Ts / Ti if math.isfinite(Ti) else 0.0
    Nff = Kp * (b * np.array([1.0, -1.0, 0.0]) + ki * np.array([1.0, 0.0, 0.0]))  # over Dc = z(z - 1)
    return loop.response(np.polymul(loop.P.Np, Nff), r), loop.response(np.polymul(Nff, loop.P.Dp), r)


def noise_gain(loop: Loop) -> float:
    """H2 norm of C S (std(u) per std of white measurement noise, per sample) by Parseval:
    sqrt((1/pi) int_0^pi |CS(e^(j theta))|^2 d theta), on a linear grid refined around every closed-loop
    pole (a Lyapunov solution on a realisation of the polynomials is ill-conditioned when poles crowd z = 1)."""
    num, den = np.polymul(loop.Nc, loop.P.Dp), loop.Dcl
    grids = [np.linspace(0.0, math.pi, 2 ** 18 + 1)]
    for p in loop.poles:
        width = max(1.0 - abs(p), 1e-12)
        c = abs(math.atan2(p.imag, p.real))
        grids.append(np.clip(c + width * np.linspace(-200.0, 200.0, 40001), 0.0, math.pi))
    theta = np.unique(np.concatenate(grids))
    z = np.exp(1j * theta)
    mag2 = np.abs(np.polyval(num, z) / np.polyval(den, z)) ** 2
    return float(math.sqrt(np.trapezoid(mag2, theta) / math.pi))


# -------------------------------------------------------------------------------- evaluation of a row

@dataclass
class Row:
    label: str
    Kp: float
    Ti: float
    Td: float
    stable: bool = False
    load_iae: float = math.nan
    sp_ise: float = math.nan
    overshoot: float = math.nan
    tv: float = math.nan
    noise: float = math.nan
    Ms: float = math.nan
    ratio: float = math.nan
    ratio_own: float = math.nan
    check: float = math.nan    # worst relative difference of the cross-checks
    truncated: bool = False    # load IAE over N_MAX samples only: a lower bound
    note: str = ""


def step_metrics(y: np.ndarray, u: np.ndarray, step: float, Ts: float):
    e = step - y
    ise = float(np.sum(e ** 2) * Ts)
    overshoot = max(0.0, float(np.max(y / step)) - 1.0) * 100.0
    tv = float(np.sum(np.abs(np.diff(np.r_[0.0, u]))))
    return ise, overshoot, tv


ILL_CONDITIONED = 1e-4     # 1 - max |pole| below this: the polynomial path loses digits (roots near z = 1)
TOL_WELL, TOL_ILL = 1e-8, 1e-2   # sos of a degree-23 polynomial (20-sample dead time) reaches ~1e-9


def _assert_close(a, b, rel, what):
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = max(float(np.max(np.abs(b))), 1e-300)
    err = float(np.max(np.abs(a - b))) / scale
    assert err <= rel, f"{what}: relative difference {err:.3g} > {rel:g}"
    return err


def evaluate(plant: Plant, P: Discrete, label: str, Kp, Ti, Td) -> Row:
    """Every column of a row from the time recursion of the law, each closed-loop number checked against
    a second computation (transfer functions; Parseval vs the recursion's impulse response; |S| vs a
    simulated sinusoid). The cross-check tolerance is TOL_WELL, or TOL_ILL for a loop with a pole within
    ILL_CONDITIONED of the unit circle (its closed-loop polynomial's roots are then only known to a few digits)."""
    row = Row(label, Kp, Ti, Td)
    loop = close(P, Kp, Ti, Td)
    row.stable = loop.stable
    if not loop.stable:
        row.note = f"closed loop unstable (max |pole| {loop.rho:.6f})"
        return row
    N = loop.horizon()
    Ts = P.Ts
    tol = TOL_WELL if 1.0 - loop.rho > ILL_CONDITIONED else TOL_ILL
    notes, errs = [], []
    row.truncated = loop.truncated
    if row.truncated:
        tau = -Ts / math.log(loop.rho)
        notes.append(f"slowest mode |z| = {loop.rho:.10g} (time constant {tau:.3g} s): IAE and ISE over the first "
                     f"{N * Ts:.4g} s only, lower bounds")
    # load step: recursion vs transfer function
    y_l, _ = simulate(P, Kp, Ti, Td, N, load=np.full(N, plant.load_step))
    row.load_iae = float(np.sum(np.abs(y_l)) * Ts)
    errs.append(_assert_close(row.load_iae, load_iae(loop, plant.load_step), tol,
                              f"{label}: load IAE, recursion vs TF"))
    # setpoint step under the law
    y_s, u_s = simulate(P, Kp, Ti, Td, N, r=np.full(N, plant.setpoint_step))
    y_t, u_t = setpoint_response_tf(loop, plant.setpoint_step, N)
    errs.append(_assert_close(y_s, y_t, tol, f"{label}: setpoint y, recursion vs TF"))
    errs.append(_assert_close(u_s, u_t, tol, f"{label}: setpoint u, recursion vs TF"))
    row.sp_ise, row.overshoot, row.tv = step_metrics(y_s, u_s, plant.setpoint_step, Ts)
    # noise gain: Parseval on the frequency grid vs the recursion's response to a noise impulse (LTI start:
    # stationary noise has no first sample; the law's e(-1) := e(0) would drop the impulse's derivative kick)
    row.noise = noise_gain(loop)
    imp = np.zeros(N)
    imp[0] = 1.0
    _, h = simulate(P, Kp, Ti, Td, N, noise=imp, lti_start=True)
    errs.append(_assert_close(math.sqrt(float(np.sum(h ** 2))), row.noise, max(tol, 1e-7),
                              f"{label}: noise gain, impulse response vs Parseval"))
    # Ms, and |S| at the peak against a simulated sinusoid through the law (measurement disturbance)
    row.Ms, theta = peak_sensitivity(loop)
    if loop.needed() <= N_MAX // 2:
        errs.append(check_sinusoid(P, loop, theta, row.Ms, label))
    else:
        notes.append("no sinusoid check of Ms (the loop does not settle within the simulation)")
    row.check = max(errs)
    row.note = "; ".join(notes)
    return row


def check_sinusoid(P: Discrete, loop: Loop, theta: float, ms: float, label: str) -> float:
    """Steady-state amplitude of the measured output y + n for n = cos(theta k), fitted by least squares
    over the last periods, equals |S(e^(j theta))| (S maps a measurement disturbance n to y + n)."""
    settle = min(loop.horizon(), N_MAX // 2)
    period = 2 * math.pi / theta
    window = int(min(max(20 * period, 400), 200_000))
    N = settle + window
    k = np.arange(N)
    n = np.cos(theta * k)  # cos: the peak may sit at Nyquist, where sin(pi k) = 0
    y, _ = simulate(P, loop.Kp, loop.Ti, loop.Td, N, noise=n)
    ym = (y + n)[-window:]
    kk = k[-window:]
    X = np.c_[np.sin(theta * kk), np.cos(theta * kk)]
    coef, *_ = np.linalg.lstsq(X, ym, rcond=None)
    amp = float(np.hypot(*coef)) if abs(theta - math.pi) > 1e-9 else abs(float(coef[1]))
    assert abs(amp - ms) <= 1e-6 * ms, f"{label}: |S| at the peak {ms:.9g} vs simulated sinusoid {amp:.9g}"
    return abs(amp - ms) / ms


# ------------------------------------------------------------------------------------ the optimum

def _gains(plant: Plant, x) -> tuple[float, float, float]:
    Kp = plant.kp_sign * 10.0 ** x[0]
    Ti = 10.0 ** x[1]
    Td = 10.0 ** x[2] if plant.td_log else max(float(x[2]), 0.0)
    return Kp, Ti, Td


def _x(plant: Plant, Kp, Ti, Td):
    return np.array([math.log10(abs(Kp)), math.log10(Ti),
                     math.log10(max(Td, 1e-12)) if plant.td_log else Td])


def _objective(x, plant: Plant, P: Discrete, limit: float) -> float:
    Kp, Ti, Td = _gains(plant, x)
    loop = close(P, Kp, Ti, Td)
    if not loop.stable:
        return 1e3 + loop.rho
    ms, _ = peak_sensitivity(loop)
    iae = load_iae(loop)
    return math.log(max(iae, 1e-300)) + PENALTY * max(0.0, ms - limit)


def least_ms(plant: Plant, P: Discrete, quick: bool) -> tuple[float, tuple, str]:
    """(least Ms, gains, gains at the search bound) of the law over the plant's search box: differential
    evolution, then Nelder-Mead."""
    def f(x):
        loop = close(P, *_gains(plant, x))
        return 1e3 + loop.rho if not loop.stable else peak_sensitivity(loop)[0]
    de = optimize.differential_evolution(f, plant.bounds, seed=0, polish=False, tol=1e-10, init="sobol",
                                         maxiter=30 if quick else 150, popsize=10 if quick else 20)
    res = optimize.minimize(f, de.x, method="Nelder-Mead", bounds=plant.bounds,
                            options={"xatol": 1e-7, "fatol": 1e-11, "maxiter": 4000})
    hit = [name for name, xi, (lo, hi) in zip(("Kp", "Ti", "Td"), res.x, plant.bounds)
           if (xi - lo) < 1e-4 * (hi - lo) or (hi - xi) < 1e-4 * (hi - lo)]
    return float(res.fun), _gains(plant, res.x), ", ".join(hit)


@dataclass
class Optimum:
    Kp: float
    Ti: float
    Td: float
    iae_unit: float            # load IAE for a unit load step
    Ms: float
    at_bound: str
    seconds: float


def optimum(plant: Plant, P: Discrete, limit: float, quick: bool, starts=()) -> Optimum:
    """min load IAE s.t. Ms <= limit: differential evolution over the plant's box with an exact penalty,
    then Nelder-Mead from the DE result and from each start (gains triples) inside the box; the best."""
    t0 = time.time()
    bounds = plant.bounds
    de = optimize.differential_evolution(
        _objective, bounds, args=(plant, P, limit), seed=0, polish=False, tol=1e-10,
        maxiter=30 if quick else 150, popsize=10 if quick else 20, init="sobol")
    candidates = [de.x]
    for g in starts:
        x = _x(plant, *g)
        if all(lo <= xi <= hi for xi, (lo, hi) in zip(x, bounds)):
            candidates.append(x)
    best = None
    for x0 in candidates:
        res = optimize.minimize(_objective, x0, args=(plant, P, limit), method="Nelder-Mead",
                                bounds=bounds, options={"xatol": 1e-7, "fatol": 1e-11, "maxiter": 4000})
        if best is None or res.fun < best.fun:
            best = res
    Kp, Ti, Td = _gains(plant, best.x)
    loop = close(P, Kp, Ti, Td)
    ms, _ = peak_sensitivity(loop)
    hit = [name for name, xi, (lo, hi) in zip(("Kp", "Ti", "Td"), best.x, bounds)
           if (xi - lo) < 1e-4 * (hi - lo) or (hi - xi) < 1e-4 * (hi - lo)]
    if not plant.td_log and best.x[2] - bounds[2][0] < 1e-4 * (bounds[2][1] - bounds[2][0]):
        hit = [h for h in hit if h != "Td"]  # Td = 0 (a PI) is a legitimate answer, not a bound
    return Optimum(Kp, Ti, Td, load_iae(loop), ms, ", ".join(hit), time.time() - t0)


# ------------------------------------------------------------------------------------ rule designs

def fopdt_half_rule(plant: Plant):
    """(k, tau1, theta) and SOPDT (k, tau1, tau2, theta) by Skogestad's half rule, for the stable plants;
    theta includes Ts/2. None where the plant has no such model."""
    name, p, h = plant.fmu_name, plant.params, plant.Ts / 2
    if name == "HeatExchanger":
        return (p["K"], p["T"], p["L"] + h), None
    if name == "RCLadder4":
        t = p["R"] * p["C"]  # four equal lags
        return (1.0, t + t / 2, t / 2 + 2 * t + h), (1.0, t, t + t / 2, t / 2 + t + h)
    if name == "InverseResponse":
        t, a = p["tau"], p["alpha"]  # three equal lags, inverse-response time constant a
        return (p["K"], t + t / 2, t / 2 + t + a + h), (p["K"], t, t + t / 2, t / 2 + a + h)
    return None, None


def step_fopdt(plant: Plant):
    """Astrom & Hagglund's FOPDT fit of the continuous step response: K static gain, L where the tangent
    at the steepest point crosses zero, T = t63 - L (y(t63) = 1 - 1/e of the final value); then L + Ts/2
    for the hold."""
    Pc = control.tf(plant.num, plant.den)
    K = plant.gain
    tmax = 40.0 * float(np.max(np.abs(np.roots(plant.den)) ** -1))
    t = np.linspace(0.0, tmax, 400_001)
    _, y = control.step_response(Pc, t)
    y = np.asarray(y).ravel() / K
    slope = np.gradient(y, t)
    i = int(np.argmax(slope))
    L = t[i] - y[i] / slope[i]
    t63 = float(np.interp(1.0 - math.exp(-1.0), y[i:], t[i:]))  # y is monotone after the steepest point
    return K, t63 - L, L + plant.delay + plant.Ts / 2  # the dead time is outside num/den


def simc_pi(k, tau1, theta):
    tc = theta
    return 1.0 / k * tau1 / (tc + theta), min(tau1, 4.0 * (tc + theta)), 0.0


def simc_pid_sopdt(k, tau1, tau2, theta):
    """SIMC series PID (Kc, tauI, tauD = tau2) converted to the ideal form of the law."""
    tc = theta
    kc, ti, td = 1.0 / k * tau1 / (tc + theta), min(tau1, 4.0 * (tc + theta)), tau2
    return kc * (1.0 + td / ti), ti + td, ti * td / (ti + td)


def simc_integrating(kv, theta):
    tc = theta
    return 1.0 / (kv * (tc + theta)), 4.0 * (tc + theta), 0.0


def amigo_fopdt(K, T, L):
    return (0.2 + 0.45 * T / L) / K, (0.4 * L + 0.8 * T) / (L + 0.1 * T) * L, 0.5 * L * T / (0.3 * L + T)


def amigo_integrating(kv, L):
    return 0.45 / (kv * L), 8.0 * L, 0.5 * L


def rule_designs(plant: Plant) -> tuple[list[tuple[str, tuple]], str]:
    """[(label, (Kp, Ti, Td))] of the SIMC and AMIGO designs, and a note on the models used."""
    h = plant.Ts / 2
    if plant.fmu_name == "FirstOrderUnstable":
        kv = plant.params["b"]
        return ([("SIMC PI (integrating)", simc_integrating(kv, h)),
                 ("AMIGO PID (integrating)", amigo_integrating(kv, h))],
                f"SIMC / AMIGO model: integrating approximation {kv:g} e^(-{h:g} s)/s of b/(s - a) "
                f"(|1/a| = {1 / plant.params['a']:.3g} s >> theta = Ts/2), tau_c = theta")
    if plant.fmu_name == "SecondOrderUnstable":
        return [], ("SIMC / AMIGO: no rule (two unstable poles and a right-half-plane zero; no FOPDT or "
                    "integrating model)")
    fo, so = fopdt_half_rule(plant)
    K, T, L = step_fopdt(plant)
    designs = [("SIMC PI (FOPDT)", simc_pi(*fo))]
    note = f"SIMC FOPDT (half rule, + Ts/2): k {fo[0]:g}, tau1 {fo[1]:.4g} s, theta {fo[2]:.4g} s"
    if so is not None:
        designs.append(("SIMC PID (SOPDT)", simc_pid_sopdt(*so)))
        note += f"; SOPDT: tau1 {so[1]:.4g} s, tau2 {so[2]:.4g} s, theta {so[3]:.4g} s"
    designs.append(("AMIGO PID", amigo_fopdt(K, T, L)))
    note += f"; tau_c = theta. AMIGO FOPDT (step response: tangent, 63 %; + Ts/2): K {K:g}, T {T:.4g} s, L {L:.4g} s"
    return designs, note


# ----------------------------------------------------------------------------------- the tool's search

class _Timeout(Exception):
    pass


def tool_fixed_pid(plant: Plant, timeout_s: float):
    """(Kp, Ti, Td, seconds) of tune_fixed_pid run as `tune` runs it, or (None, reason)."""
    from prlpid_fmi.scenario.load import load_scenario
    from prlpid_fmi.tuning.fixed_pid import tune_fixed_pid

    if not plant.bundled:
        from prlpid_fmi.fmu import build_fmu
        build_fmu(plant.fmu_name, out_dir=FMU_DIR, source_dir=plant.model_dir)
    s = load_scenario(plant.scenario)
    assert abs(s.tuning.sample_time_s - plant.Ts) < 1e-12
    t0 = time.time()

    def watchdog(done, expected):
        if time.time() - t0 > timeout_s:
            raise _Timeout(f"{done}/{expected} evaluations after {time.time() - t0:.0f} s")

    try:
        fixed = tune_fixed_pid(s.tuning, seed=s.agent.seed, episodes=s.baseline.episodes, maxiter=s.baseline.maxiter,
                               popsize=s.baseline.popsize, max_sensitivity=float(s.deploy.max_sensitivity),
                               callback=watchdog)
    except _Timeout as exc:
        return None, f"tool search over {timeout_s:.0f} s ({exc}): plant skipped"
    seconds = time.time() - t0
    g = fixed.gains
    # what the tool itself believes about the result's robustness (its FMU identification), for the note
    import dataclasses
    from prlpid_fmi.robustness.margins import margins_of, operating_point
    cfg = dataclasses.replace(s.tuning, forecast_horizon=0)
    m = margins_of(cfg, fixed.gains_values(), operating_point(cfg))
    belief = f"the tool's own Ms estimate {m.Ms:.3g}" + ("" if m.reliable else " (flagged unreliable by the tool)")
    return (float(g.Kp[0]), float(g.Ti[0]), float(g.Td[0]), seconds, belief), ""


# ------------------------------------------------------------------------------------------ checks

def fmu_step(plant: Plant, du: float, n: int) -> np.ndarray:
    """y(k) - y(0), k = 0..n-1, of the FMU after a step du of its control input at t = 0 (fmpy directly)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    from prlpid_fmi.fmu import build_fmu

    path = (build_fmu(plant.fmu_name, out_dir=FMU_DIR, source_dir=plant.model_dir) if not plant.bundled
            else build_fmu(plant.fmu_name))
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    start = {v.name: float(v.start) for v in md.modelVariables if v.start is not None}
    unzip = extract(str(path))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="bench_pid_design")
    fmu.instantiate()
    try:
        scenario_params = _yaml(plant.scenario)["plant"].get("parameters") or {}
        for k, v in scenario_params.items():
            fmu.setReal([vr[k]], [float(v)])
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        u0 = start.get(plant.input_name, 0.0)
        y = []
        t = 0.0
        for _ in range(n):
            y.append(fmu.getReal([vr[plant.output_name]])[0])
            fmu.setReal([vr[plant.input_name]], [u0 + du])
            fmu.doStep(currentCommunicationPoint=t, communicationStepSize=plant.Ts)
            t += plant.Ts
        fmu.terminate()
    finally:
        fmu.freeInstance()
    y = np.array(y)
    return y - y[0]


def run_checks(plants: list[Plant], discs: dict[str, Discrete]) -> list[str]:
    """Checks of this benchmark's own code, before any measurement (assertions)."""
    lines = []
    for plant in plants:
        P = discs[plant.name]
        # 1. the sampled model against the FMU: a step of the control input
        n = 60 + 2 * P.d
        du = 0.1 if plant.bundled else plant.load_step
        y_fmu = fmu_step(plant, du, n)
        y_mod, _ = simulate(P, 0.0, math.inf, 0.0, n, load=np.full(n, du))
        err_fmu = float(np.max(np.abs(y_fmu - y_mod))) / max(float(np.max(np.abs(y_mod))), 1e-12)
        assert err_fmu < 1e-6, f"{plant.name}: ZOH model vs FMU step, relative difference {err_fmu:.3g}"
        # 2. the recursion (LTI start e(-1) = 0) against control.forced_response on the interconnection
        Kp = plant.kp_sign * 10 ** np.mean(plant.bounds[0])
        Ti = 10 ** np.mean(plant.bounds[1])
        Td = 10 ** np.mean(plant.bounds[2]) if plant.td_log else 0.3 * plant.bounds[2][1]
        # state-space interconnection: the plant's sampled (A, B, C) in series with a d-sample delay
        Pd = control.ss(P.A, P.B.reshape(-1, 1), P.C.reshape(1, -1), 0.0, P.Ts)
        if P.d:
            Pd = Pd * control.ss(control.tf([1.0], np.r_[1.0, np.zeros(P.d)], P.Ts))
        Cd = control.ss(pid_tf(Kp, Ti, Td, P.Ts))
        N = 300
        t = np.arange(N) * P.Ts
        errs = []
        y_rec, u_rec = simulate(P, Kp, Ti, Td, N, r=np.ones(N), lti_start=True)
        errs.append(_assert_close(y_rec, control.forced_response(control.feedback(Cd * Pd, 1), T=t, U=np.ones(N)).y[0],
                                  1e-9, f"{plant.name}: setpoint y, recursion vs forced_response"))
        errs.append(_assert_close(u_rec, control.forced_response(control.feedback(Cd, Pd), T=t, U=np.ones(N)).y[0],
                                  1e-9, f"{plant.name}: setpoint u, recursion vs forced_response"))
        y_rec, _ = simulate(P, Kp, Ti, Td, N, load=np.ones(N))
        errs.append(_assert_close(y_rec, control.forced_response(control.feedback(Pd, Cd), T=t, U=np.ones(N)).y[0],
                                  1e-9, f"{plant.name}: load y, recursion vs forced_response"))
        # the law's missing kick: forced_response with the LTI loop plus the kick at the controller output
        y_law, _ = simulate(P, Kp, Ti, Td, N, r=np.ones(N))
        w = np.zeros(N)
        w[0] = -Kp * Td / P.Ts
        ref = (control.forced_response(control.feedback(Cd * Pd, 1), T=t, U=np.ones(N)).y[0]
               + control.forced_response(control.feedback(Pd, Cd), T=t, U=w).y[0])
        errs.append(_assert_close(y_law, ref, 1e-9, f"{plant.name}: law's setpoint y vs forced_response + kick"))
        lines.append(f"- {plant.name}: ZOH model vs FMU step {err_fmu:.1e}; recursion vs forced_response "
                     f"(setpoint y/u, load y, law's kick; Kp {Kp:.3g}, Ti {Ti:.3g}, Td {Td:.3g}, {N} samples) "
                     f"max {max(errs):.1e} (relative to the peak)")
    # 3. Ms: the grid with refinement against a brute-force grid of 2^20 points, on stable loops
    fine = np.geomspace(THETA_MIN, math.pi, 2 ** 20)
    probes = [("first_order", 9.36, 1.23, 0.0008), ("first_order", 20.0, 0.3, 0.03),
              ("heat_exchanger_delay", 0.5, 10.0, 2.0), ("rc_ladder4", 1.0, 3.0, 0.5),
              ("inverse_response", 0.05, 20.0, 5.0), ("second_order", -0.00233, 1065.0, 5041.0)]
    worst, checked = 0.0, []
    for name, Kp, Ti, Td in probes:
        if name not in discs:
            continue
        loop = close(discs[name], Kp, Ti, Td)
        if not loop.stable:
            continue
        checked.append(name)
        ms, _ = peak_sensitivity(loop)
        ms_fine = float(np.max(np.abs(loop.S(fine))))
        rel = (ms - ms_fine) / ms_fine
        assert -1e-6 <= rel <= 1e-4, f"{name}: Ms {ms:.8g} vs brute-force grid {ms_fine:.8g}"
        worst = max(worst, abs(rel))
    lines.append(f"- Ms (grid of {GRID_POINTS} + refinement) vs a 2^20-point grid, {len(checked)} stable probe loops "
                 f"({', '.join(checked)}): max relative difference {worst:.1e}")
    # 4. the 2-DOF law with b = 1 is the tool's law for a step at k = 0; b does not change the load response
    if "first_order" in discs:
        P = discs["first_order"]
        N = 400
        a, _ = simulate(P, 9.36, 1.23, 0.05, N, r=np.ones(N))
        b1, _ = simulate(P, 9.36, 1.23, 0.05, N, r=np.ones(N), b=1.0)
        _assert_close(b1, a, 1e-12, "2-DOF b = 1 vs 1-DOF")
        l0, _ = simulate(P, 9.36, 1.23, 0.05, N, load=np.ones(N), b=0.0)
        l1, _ = simulate(P, 9.36, 1.23, 0.05, N, load=np.ones(N))
        _assert_close(l0, l1, 1e-12, "2-DOF load response vs 1-DOF")
        lines.append("- 2-DOF law: b = 1 equals the tool's law for a setpoint step from rest; the load response "
                     "does not depend on b (both to 1e-12)")
    return lines


# --------------------------------------------------------------------------------------- 2-DOF hint

def setpoint_weight_hint(plant: Plant, P: Discrete, opt: Optimum) -> list[str]:
    """With the optimum's gains: the b in [0, 1] with the shortest 2 % settling time at overshoot <= 5 %."""
    loop = close(P, opt.Kp, opt.Ti, opt.Td)
    N = loop.horizon()
    Ts = P.Ts
    r = np.ones(N)
    rows = []
    for b in np.round(np.linspace(0.0, 1.0, 101), 2):
        y, u = simulate(P, opt.Kp, opt.Ti, opt.Td, N, r=r, b=float(b))
        ise, os_, tv = step_metrics(y, u, 1.0, Ts)
        outside = np.flatnonzero(np.abs(y - 1.0) > 0.02)
        settle = (outside[-1] + 1) * Ts if outside.size else 0.0
        i10, i90 = np.argmax(y >= 0.1), np.argmax(y >= 0.9)
        rows.append((float(b), os_, settle, (i90 - i10) * Ts, ise, tv))
    ok = [r_ for r_ in rows if r_[1] <= 5.0]
    best = min(ok, key=lambda r_: (r_[2], -r_[0])) if ok else None
    y0, _ = simulate(P, opt.Kp, opt.Ti, opt.Td, N, load=np.ones(N), b=0.0 if best is None else best[0])
    iae_b = float(np.sum(np.abs(y0)) * Ts)
    assert abs(iae_b - opt.iae_unit) <= 1e-9 * opt.iae_unit, "load IAE depends on b"
    out = [f"\n#### Setpoint weight hint, {plant.name}: optimum's gains Kp {opt.Kp:.4g}, Ti {opt.Ti:.4g} s, "
           f"Td {opt.Td:.4g} s; P term on b r - y, derivative on -y\n",
           "| b | overshoot % | 2 % settling s | rise 10-90 % s | setpoint ISE | TV(u) |", "|---|---|---|---|---|---|"]
    picks = {0.0, 0.25, 0.5, 0.75, 1.0} | ({best[0]} if best else set())
    for b, os_, settle, rise, ise, tv in rows:
        if b in picks:
            mark = " **(chosen)**" if best and b == best[0] else ""
            out.append(f"| {b:.2f}{mark} | {os_:.3g} | {settle:.3g} | {rise:.3g} | {ise:.4g} | {tv:.4g} |")
    if best:
        out.append(f"\nBest b = {best[0]:.2f}: overshoot {best[1]:.3g} %, settling {best[2]:.3g} s; load IAE "
                   f"{iae_b:.4g} at that b, equal to the 1-DOF optimum's {opt.iae_unit:.4g} (b does not enter the "
                   f"load response).")
    else:
        least = min(rows, key=lambda r_: r_[1])
        neg = []
        for b in (-0.25, -0.5, -1.0):
            y, _ = simulate(P, opt.Kp, opt.Ti, opt.Td, N, r=r, b=b)
            neg.append(f"b = {b:g}: {max(0.0, float(np.max(y)) - 1.0) * 100:.3g} %")
        out.append(f"\nNo b in [0, 1] keeps the overshoot at or below 5 %: the least is {least[1]:.3g} % at b = "
                   f"{least[0]:.2f} (settling {least[2]:.3g} s); a negative b does not help either "
                   f"({', '.join(neg)}): the overshoot comes from the integral term, which b does not weight. "
                   f"Load IAE {iae_b:.4g} at b = 0, equal to the 1-DOF "
                   f"optimum's {opt.iae_unit:.4g} (b does not enter the load response).")
    return out


# --------------------------------------------------------------------------------------------- main

def print_table(plant: Plant, rows: list[Row], tool: tuple, opt: Optimum, note: str, feasible: bool = True) -> None:
    """The plant's header lines and markdown table."""
    box = plant.gain_box
    in_box = all(lo <= v <= hi for v, (lo, hi) in
                 zip((opt.Kp, opt.Ti, opt.Td), ((box[k][0], box[k][1]) for k in ("Kp", "Ti", "Td"))))
    where = (f"{'contains' if in_box else 'does not contain'} the Ms ≤ {MS_LIMIT:g} optimum" if feasible
             else f"no Ms ≤ {MS_LIMIT:g} optimum")
    unit = "unit" if plant.bundled else "10 % of range"
    print(f"load step {fmt(plant.load_step)} at the plant input ({unit}: u_limits {plant.u_limits}); setpoint step "
          f"{fmt(plant.setpoint_step)} ({unit}: setpoint_range {plant.setpoint_range}); tool search "
          f"{tool[3]:.0f} s; scenario gain box Kp {box['Kp'][:2]}, Ti {box['Ti'][:2]}, Td {box['Td'][:2]} "
          f"({where})")
    print(note + "\n")
    header = ["design", "Kp", "Ti s", "Td s", "load IAE", "setpoint ISE", "overshoot %", "TV(u)", "noise gain",
              "Ms", "IAE ÷ opt (Ms ≤ 2)", "IAE ÷ opt (own Ms)", "cross-check", "note"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in rows:
        lb = "≥ " if r.truncated else ""
        bound = lambda x, nd=4: (lb if math.isfinite(x) else "") + fmt(x, nd)  # noqa: E731
        print("| " + " | ".join([r.label, fmt(r.Kp), fmt(r.Ti), fmt(r.Td), bound(r.load_iae), bound(r.sp_ise),
                                 fmt(r.overshoot, 3), fmt(r.tv), fmt(r.noise), fmt(r.Ms, 4), bound(r.ratio, 3),
                                 bound(r.ratio_own, 3), f"{r.check:.0e}" if math.isfinite(r.check) else "n/a",
                                 r.note]) + " |")
    print(f"\ncross-check: worst relative difference, per row, of the time recursion of the law against transfer "
          f"functions (load IAE, setpoint y and u; asserted ≤ {TOL_WELL:g}, or ≤ {TOL_ILL:g} with a pole within "
          f"{ILL_CONDITIONED:g} of the unit circle), of H2 by Parseval against the recursion's impulse response, "
          f"and of |S| "
          f"at the peak against a simulated sinusoid (≤ 1e-6).", flush=True)


def poly_str(c: np.ndarray) -> str:
    """s-polynomial as text, e.g. [1000, 300, 30, 1] -> '1000 s^3 + 300 s^2 + 30 s + 1'."""
    n = len(c) - 1
    terms = []
    for i, a in enumerate(c):
        if a == 0:
            continue
        p = n - i
        mag = abs(a)
        coef = "" if (mag == 1 and p) else f"{mag:g}"
        var = "" if p == 0 else ("s" if p == 1 else f"s^{p}")
        sign = "-" if a < 0 else "+"
        terms.append((sign, (coef + " " + var).strip()))
    text = ("-" if terms[0][0] == "-" else "") + terms[0][1]
    return text + "".join(f" {sg} {t}" for sg, t in terms[1:])


def fmt(x, nd=4):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:.{nd}g}"


def main(argv=None) -> int:
    all_plants = plant_list()
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--plants", nargs="+", default=list(all_plants), choices=list(all_plants))
    p.add_argument("--quick", action="store_true", help="fewer differential-evolution iterations for the optima")
    p.add_argument("--search-timeout", type=float, default=SEARCH_TIMEOUT_S,
                   help=f"skip a plant whose tool search runs longer [s] (default {SEARCH_TIMEOUT_S:g})")
    a = p.parse_args(argv)
    t_all = time.time()
    plants = [all_plants[n].load() for n in a.plants]
    discs = {pl.name: discretise(pl) for pl in plants}

    print("### Checks of the benchmark's own closed-loop code\n", flush=True)
    for line in run_checks(plants, discs):
        print(line, flush=True)

    summary = []
    for plant in plants:
        t_plant = time.time()
        P = discs[plant.name]
        G = f"({poly_str(plant.num)})/({poly_str(plant.den)})"
        dead = f" e^(-{plant.delay:g} s)" if plant.delay else ""
        print(f"\n### {plant.name}: G(s) = {G}{dead}, Ts {plant.Ts:g} s\n", flush=True)
        tool, reason = tool_fixed_pid(plant, a.search_timeout)
        if tool is None:
            print(f"{plant.name}: {reason}")
            summary.append([plant.name, "skipped", "", "", "", ""])
            continue
        designs, note = rule_designs(plant)
        starts = [tool[:3]] + [g for _, g in designs]
        opt = optimum(plant, P, MS_LIMIT, a.quick, starts)
        rows = [evaluate(plant, P, "tool's fixed PID", *tool[:3])]
        rows += [evaluate(plant, P, label, *g) for label, g in designs]
        rows[0].note = "; ".join(filter(None, [tool[4], rows[0].note]))
        feasible = opt.Ms <= MS_LIMIT * (1.0 + 1e-6)
        if not feasible:
            ms_min, g_min, g_bound = least_ms(plant, P, a.quick)
            if ms_min <= MS_LIMIT:  # the penalised search missed the feasible region: start from the least-Ms PID
                opt = optimum(plant, P, MS_LIMIT, a.quick, starts + [g_min])
                feasible = opt.Ms <= MS_LIMIT * (1.0 + 1e-6)
        if not feasible:
            row = evaluate(plant, P, "least-Ms PID of the law", *g_min)
            row.note = "; ".join(filter(None, [f"Ms ≤ {MS_LIMIT:g} is infeasible for this PID law in the search box "
                                               f"(least Ms found {ms_min:.4g}"
                                               + (f", at the search bound in {g_bound}" if g_bound else "")
                                               + ")", row.note]))
            rows.append(row)
            print_table(plant, rows, tool, opt, note, feasible=False)
            summary.append([f"{plant.name} (Ms ≤ {MS_LIMIT:g} infeasible for the law: least Ms {ms_min:.3g})", "n/a",
                            "n/a", "n/a", fmt(rows[0].Ms, 3), fmt(rows[0].overshoot, 3)])
            print(f"({plant.name}: {time.time() - t_plant:.0f} s)", flush=True)
            continue
        rows.append(evaluate(plant, P, f"optimum, Ms ≤ {MS_LIMIT:g}", opt.Kp, opt.Ti, opt.Td))
        opt_iae = rows[-1].load_iae
        _assert_close(opt_iae, opt.iae_unit * plant.load_step, 1e-9, "optimum's load IAE")
        own_cache = {}
        for row in rows[:-1]:
            if not row.stable:
                continue
            row.ratio = row.load_iae / opt_iae
            if row.Ms > OWN_MS_MAX:
                row.note = "; ".join(filter(None, [row.note, f"Ms > {OWN_MS_MAX:g}: no own-Ms optimum"]))
                continue
            key = round(row.Ms, 6)
            if key not in own_cache:
                own_cache[key] = optimum(plant, P, row.Ms, a.quick,
                                         starts + [(opt.Kp, opt.Ti, opt.Td), (row.Kp, row.Ti, row.Td)])
            own = own_cache[key]
            row.ratio_own = row.load_iae / (own.iae_unit * plant.load_step)
            at_bound = f" (at the search bound in {own.at_bound})" if own.at_bound else ""
            row.note = "; ".join(filter(None, [row.note, f"own-Ms optimum Kp {own.Kp:.4g}, Ti {own.Ti:.4g}, "
                                                        f"Td {own.Td:.4g}{at_bound}"]))
        rows[-1].ratio = rows[-1].ratio_own = 1.0
        rows[-1].note = "; ".join(filter(None, [rows[-1].note, f"DE + Nelder-Mead {opt.seconds:.0f} s" + (
            f"; at the search bound in {opt.at_bound}" if opt.at_bound else "")]))
        print_table(plant, rows, tool, opt, note)
        print(f"({plant.name}: {time.time() - t_plant:.0f} s)", flush=True)
        simc = next((r for r in rows if r.label.startswith("SIMC PID")), None) or \
            next((r for r in rows if r.label.startswith("SIMC")), None)
        amigo = next((r for r in rows if r.label.startswith("AMIGO")), None)
        kind = lambda r: f" ({r.label.split()[1]})" if r else ""  # noqa: E731
        lb0 = "≥ " if rows[0].truncated else ""
        summary.append([plant.name, lb0 + fmt(rows[0].ratio, 3), (fmt(simc.ratio, 3) + kind(simc)) if simc else "n/a",
                        fmt(amigo.ratio, 3) if amigo else "n/a", fmt(rows[0].Ms, 3), fmt(rows[0].overshoot, 3)])
        if plant.name == "first_order":
            for line in setpoint_weight_hint(plant, P, opt):
                print(line)

    print("\n### Summary (load IAE ÷ the Ms ≤ 2 optimum of the same PID law)\n")
    print("| plant | tool's fixed PID | SIMC | AMIGO | tool's Ms | tool's overshoot % |")
    print("|---|---|---|---|---|---|")
    for row in summary:
        print("| " + " | ".join(row) + " |")
    print(f"\ntotal wall time {time.time() - t_all:.0f} s" + (" (--quick)" if a.quick else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
