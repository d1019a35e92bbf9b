"""The zoo plants' equations written again in Python, from the cited physics (not from the C code): the truth the
tests (tests/test_zoo_plants.py) check the FMUs against, and the models benchmarks/bench_zoo.py designs its
reference PIDs and computes its optima on.

- Linear batch: `linear_model(parameters)` -> (num, den, dead time) of N(s)/D(s) e^(-sL) (s-polynomials, highest
  power first) from a scenario's LinearBatch parameters.
- Nonlinear plants: `NONLINEAR[name]` -> `Nonlinear` with the state equations f(x, u, p) (time in s), the output,
  the steady state x(u) at a constant input, the input u(y) that holds an output y at steady state on the branch
  the scenario works on, and a dead time. `linearise` gives the continuous (A, B, C) at the steady state of y.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import brentq


def linear_model(params: dict) -> tuple[np.ndarray, np.ndarray, float]:
    """(num, den, L) of the LinearBatch plant: num_k, den_k are the coefficients of s^k; leading zeros dropped."""
    num = np.array([float(params.get(f"num{k}", 1.0 if k == 0 else 0.0)) for k in range(3, -1, -1)])
    den = np.array([float(params.get(f"den{k}", 1.0 if k in (0, 1) else 0.0)) for k in range(8, -1, -1)])
    num = np.trim_zeros(num, "f")
    den = np.trim_zeros(den, "f")
    return num, den, float(params.get("L", 0.0))


@dataclass
class Nonlinear:
    """One nonlinear zoo plant: f(x, u, p) -> dx/dt [per s], output(x, p), steady state x_ss(u, p), the input
    that holds output y at steady state on the scenario's branch u_of_y(y, p), dead time [s] at the input."""
    fmu: str
    input: str
    output: str
    defaults: dict
    f: Callable
    output_of: Callable
    x_ss: Callable
    u_of_y: Callable
    delay: Callable = field(default=lambda p: 0.0)


# --- Van de Vusse (Engell & Klatt 1993; Bequette 2003), rates per minute -----------------------------------
def _vdv_f(x, u, p):
    ca, cb = x
    return np.array([u * (p["Caf"] - ca) - p["k1"] * ca - p["k3"] * ca * ca,
                     -u * cb + p["k1"] * ca - p["k2"] * cb]) / 60.0


def _vdv_ss(u, p):
    b = p["k1"] + u
    ca = (-b + math.sqrt(b * b + 4.0 * p["k3"] * u * p["Caf"])) / (2.0 * p["k3"])
    return np.array([ca, p["k1"] * ca / (u + p["k2"])])


def _vdv_u(y, p):   # the low-D branch: Cb rises with D up to the maximum near D = 1.29 1/min
    return brentq(lambda u: _vdv_ss(u, p)[1] - y, 1e-9, 1.29)


# --- ball and beam (Hauser, Sastry & Kokotovic 1992) with a servo lag -----------------------------------------
def _bb_f(x, u, p):
    pos, vel, th = x
    w = (u - th) / p["tau_s"]
    return np.array([vel, p["B"] * (pos * w * w + p["g"] * math.sin(th)), w])


# --- bioreactor with substrate inhibition (Bequette 1998; Henson & Seborg 1997), rates per hour ---------------
def _mu(S, p):
    return p["mu_max"] * S / (p["k_m"] + S + p["k_1"] * S * S)


def _bio_f(x, u, p):
    X, S = x
    r = _mu(S, p)
    return np.array([(r - u) * X, u * (p["S_f"] - S) - r * X / p["Y"]]) / 3600.0


def _bio_ss(u, p):   # the stable branch (smaller root of D k1 S^2 + (D - mu_max) S + D km = 0)
    a, b, c = u * p["k_1"], u - p["mu_max"], u * p["k_m"]
    S = (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)
    return np.array([p["Y"] * (p["S_f"] - S), S])


def _bio_u(y, p):    # both branches: S = S_f - X / Y, D = mu(S)
    return _mu(p["S_f"] - y / p["Y"], p)


# --- spherical tank ---------------------------------------------------------------------------------------------
def _tank_f(x, u, p):
    h = max(float(x[0]), 0.0)
    area = max(math.pi * h * (2.0 * p["R"] - h), p["A_min"])
    return np.array([(u - p["k"] * math.sqrt(h)) / 1000.0 / area])


# --- distillation-like column (Skogestad 1997): logarithmic composition, dead time at the input ----------------
def _dist_f(x, u, p):
    return np.array([(p["a"] + p["b"] * u - x[0]) / p["T"]])


def _dist_y(x, p):
    return 100.0 / (1.0 + math.exp(-x[0]))


NONLINEAR = {
    "VanDeVusse": Nonlinear(
        "VanDeVusse", "D", "Cb", {"k1": 5 / 6, "k2": 5 / 3, "k3": 1 / 6, "Caf": 10.0, "u0": 4 / 7},
        _vdv_f, lambda x, p: x[1], _vdv_ss, _vdv_u),
    "BallBeam": Nonlinear(
        "BallBeam", "theta_c", "p", {"B": 5 / 7, "g": 9.81, "tau_s": 0.05, "u0": 0.0},
        _bb_f, lambda x, p: x[0], lambda u, p: np.array([p.get("p0", 0.0), 0.0, u]),
        lambda y, p: 0.0),
    "Bioreactor": Nonlinear(
        "Bioreactor", "D", "X_out", {"mu_max": 0.53, "k_m": 0.12, "k_1": 0.4545, "Y": 0.4, "S_f": 4.0, "u0": 0.33},
        _bio_f, lambda x, p: x[0], _bio_ss, _bio_u),
    "SphericalTank": Nonlinear(
        "SphericalTank", "q_in", "h", {"R": 0.5, "k": math.sqrt(2.0), "A_min": 0.005, "u0": 1.0},
        _tank_f, lambda x, p: x[0], lambda u, p: np.array([(u / p["k"]) ** 2]), lambda y, p: p["k"] * math.sqrt(y)),
    "Distillation": Nonlinear(
        "Distillation", "R", "x_D", {"a": -3.8, "b": 4.0, "T": 864.0, "L": 180.0, "u0": 2.0},
        _dist_f, _dist_y, lambda u, p: np.array([p["a"] + p["b"] * u]),
        lambda y, p: (math.log(y / (100.0 - y)) - p["a"]) / p["b"], lambda p: p["L"]),
}


def steady_state_at(plant: Nonlinear, y: float, p: dict) -> tuple[np.ndarray, float]:
    """(x, u) of the steady state with output y on the scenario's branch. The ball and beam is at rest at any
    position with the beam level; the bioreactor's unstable branch has x = (y, S_f - y/Y)."""
    u = plant.u_of_y(y, p)
    if plant.fmu == "BallBeam":
        return np.array([y, 0.0, 0.0]), 0.0
    if plant.fmu == "Bioreactor":
        return np.array([y, p["S_f"] - y / p["Y"]]), u
    return plant.x_ss(u, p), u


def linearise(plant: Nonlinear, y: float, p: dict, eps: float = 1e-6):
    """Continuous (A, B, C) at the steady state of output y, by central differences (relative step eps)."""
    x0, u0 = steady_state_at(plant, y, p)
    n = len(x0)
    A = np.zeros((n, n))
    for i in range(n):
        h = eps * max(abs(x0[i]), 1e-3)
        dx = np.zeros(n)
        dx[i] = h
        A[:, i] = (plant.f(x0 + dx, u0, p) - plant.f(x0 - dx, u0, p)) / (2 * h)
    hu = eps * max(abs(u0), 1e-3)
    B = (plant.f(x0, u0 + hu, p) - plant.f(x0, u0 - hu, p)) / (2 * hu)
    C = np.zeros(n)
    for i in range(n):
        h = eps * max(abs(x0[i]), 1e-3)
        dx = np.zeros(n)
        dx[i] = h
        C[i] = (plant.output_of(x0 + dx, p) - plant.output_of(x0 - dx, p)) / (2 * h)
    return A, B, C
