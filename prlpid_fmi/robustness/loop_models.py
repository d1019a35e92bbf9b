"""The closed loop of several PID loops on their local models, in state space: load responses and stability.

Each loop j has its local model P_j (robustness.local_model.LocalModel, identified from its own measurement's response
y_j / u_j measured with the other loops closed: robustness.identification); the plant is taken as diag(P_1 .. P_n):
loop j's input moves only loop j's measurement, and the coupling is the controller's alone. The
controller is control.pid's feedback law at a constant setpoint (output limits and anti-windup ignored), on the
coupled error of eq. 27 where the loops are coupled (control.pid.CoupledPID; uncoupled: M = -I):

    u_i = Kp_i (1 + Td_i Fd_i (1 - q) / Ts) (M F y)_i + Kp_i Ts / (Ti_i (1 - q)) (M y)_i,     M = C - I

F = diag(F_j) the measurement filters, Fd_i the derivative filter of Td_i / N, C the coupling matrix. Every block is
realised in state space (observer canonical form of its polynomials in q = z^-1) and the blocks are connected into one
closed-loop system x_{k+1} = A x_k + B d_k, y_k = Y x_k, u_k = U x_k with a step d at the plant inputs (the models
are strictly proper: no algebraic loop). For one loop without coupling this is
robustness.local_model.load_responses' B Dc / (A Dc + B Nc).
"""
from __future__ import annotations

import math

import numpy as np

from prlpid_fmi.robustness.local_model import LocalModel, derivative_denominator, measurement_filter


def _realise(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C, D) in observer canonical form of num(q) / den(q), polynomials in ascending powers of q = z^-1
    (den[0] != 0): x_{k+1} = A x_k + B u_k, y_k = C x_k + D u_k."""
    length = max(len(num), len(den))
    n = np.zeros(length)
    d = np.zeros(length)
    n[:len(num)] = num
    d[:len(den)] = den
    n, d = n / d[0], d / d[0]
    order = length - 1
    if order == 0:
        return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[n[0]]])
    A = np.zeros((order, order))
    A[:, 0] = -d[1:]
    A[:order - 1, 1:] = np.eye(order - 1)
    B = (n[1:] - n[0] * d[1:])[:, None]
    C = np.zeros((1, order))
    C[0, :1] = 1.0
    return A, B, C, np.array([[n[0]]])


def _proportional_derivative(Kp: float, Td: float, Ts: float, N: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Kp (1 + Td Fd (1 - q) / Ts), Fd the backward-Euler derivative filter of Td / N, as (num, den) in q."""
    dd = derivative_denominator(Td, N, Ts)
    return Kp * (dd + Td * np.array([1.0, -1.0])), dd


def closed_loop(models: list[LocalModel], Kp: list[float], Ti: list[float], Td: list[float], sample_time_s: float,
                derivative_filter_N: float | None, tf: list[float], filter_order: int,
                coupling: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """(A, B, Y, U) of the module docstring's closed loop: states x (m,), loads d (n,) at the plant inputs,
    x_{k+1} = A x_k + B d_k, measurements y_k = Y x_k (n,), PID outputs u_k = U x_k (n,): no direct path from d, the
    models being strictly proper.
    coupling: the (n, n) matrix C of eq. 27 (zero diagonal) or None (uncoupled)."""
    n, Ts = len(models), float(sample_time_s)
    M = (np.zeros((n, n)) if coupling is None else np.asarray(coupling, float)) - np.eye(n)
    plants = [_realise(m.numerator, m.denominator) for m in models]
    filters = [_realise(*measurement_filter(tf[j], filter_order, Ts)) for j in range(n)]
    pds = [_realise(*_proportional_derivative(Kp[i], Td[i], Ts, derivative_filter_N)) for i in range(n)]
    integrals = [_realise(np.array([Kp[i] * Ts / Ti[i]]), np.array([1.0, -1.0])) if math.isfinite(Ti[i]) else
                 _realise(np.array([0.0]), np.array([1.0])) for i in range(n)]  # Ti = inf: no integral term
    blocks = [plants, filters, pds, integrals]
    sizes = [[b[0].shape[0] for b in group] for group in blocks]
    m = sum(sum(s) for s in sizes)
    offsets, at = [], 0
    for group in sizes:
        row = []
        for s in group:
            row.append(slice(at, at + s))
            at += s
        offsets.append(row)
    # signals as linear maps of the state x: y = Y x, yf = Yf x, u = U x
    Y = np.zeros((n, m))
    for j, (_, _, C, _) in enumerate(plants):
        Y[j, offsets[0][j]] = C[0]
    Yf = np.zeros((n, m))
    for j, (_, _, C, D) in enumerate(filters):
        Yf[j, offsets[1][j]] = C[0]
        Yf[j] += D[0, 0] * Y[j]
    S, Sf = M @ Y, M @ Yf  # the coupled errors' feedback parts, (n, m)
    U = np.zeros((n, m))
    for i in range(n):
        _, _, C, D = pds[i]
        U[i, offsets[2][i]] += C[0]
        U[i] += D[0, 0] * Sf[i]
        _, _, C, D = integrals[i]
        U[i, offsets[3][i]] += C[0]
        U[i] += D[0, 0] * S[i]
    A = np.zeros((m, m))
    B = np.zeros((m, n))
    for j, (Ap, Bp, _, _) in enumerate(plants):  # x_p' = Ap x_p + Bp (u_j + d_j)
        rows = offsets[0][j]
        A[rows, rows] += Ap
        A[rows] += Bp @ U[j][None, :]
        B[rows, j] = Bp[:, 0]
    for group, signals in ((1, Y), (2, Sf), (3, S)):  # filters on y, PD parts on M yf, integrals on M y
        for i, (Ab, Bb, _, _) in enumerate(blocks[group]):
            rows = offsets[group][i]
            A[rows, rows] += Ab
            A[rows] += Bb @ signals[i][None, :]
    return A, B, Y, U


def stable(A: np.ndarray) -> bool:
    """Every eigenvalue of A strictly inside the unit circle (finite A)."""
    return bool(np.all(np.isfinite(A))) and (A.size == 0 or bool(np.max(np.abs(np.linalg.eigvals(A))) < 1.0))


def step_responses(A: np.ndarray, B: np.ndarray, Y: np.ndarray, U: np.ndarray, steps: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(dy, du), each (steps, n outputs, n inputs): the measurements' and PID outputs' change at sample k after a
    unit step at each plant input from sample 0 on, the loop at rest before (x_0 = 0): x_k = sum_{j<k} A^j B, the
    powers A^j B by doubling ([B] -> [B, A B] -> [B, A B, A^2 B, A^3 B] ...)."""
    steps = int(steps)
    m, n = B.shape
    powers = B[None, :, :]  # (j, m, n): A^j B
    square = A
    with np.errstate(over="ignore", invalid="ignore"):
        while len(powers) < steps - 1:
            powers = np.concatenate([powers, square @ powers])
            square = square @ square
        x = np.zeros((steps, m, n))
        x[1:] = np.cumsum(powers[:steps - 1], axis=0)
        return Y @ x, U @ x


def loop_plants(models: list[LocalModel], Kp: list[float], Ti: list[float], Td: list[float], sample_time_s: float,
                derivative_filter_N: float | None, tf: list[float], filter_order: int, coupling: np.ndarray | None,
                omega: np.ndarray) -> np.ndarray:
    """(n, W) complex: each loop's effective plant at omega (W,) [rad/s] as the margin experiment measures it
    (robustness.identification): loop i open at its plant input, the other loops closed by their PIDs,
    P_i = -(M y)_i / u_i with y = diag(P_j) u (the coupled error's plant; -y_i / u_i uncoupled). Loop i's loop
    transfer broken at its input is then C_i P_i, C_i its own PID (robustness.margins)."""
    n, Ts = len(models), float(sample_time_s)
    w = np.asarray(omega, float)
    M = (np.zeros((n, n)) if coupling is None else np.asarray(coupling, float)) - np.eye(n)
    q = np.exp(-1j * w * Ts)

    def response(num, den):
        return np.polyval(np.asarray(num)[::-1], q) / np.polyval(np.asarray(den)[::-1], q)

    P = np.array([m.response(w) for m in models])  # (n, W)
    F = np.array([response(*measurement_filter(tf[j], filter_order, Ts)) for j in range(n)])
    PD = np.array([response(*_proportional_derivative(Kp[i], Td[i], Ts, derivative_filter_N)) for i in range(n)])
    integral = np.array([response([Kp[i] * Ts / Ti[i]], [1.0, -1.0]) if math.isfinite(Ti[i]) else np.zeros(len(w))
                         for i in range(n)])
    # u = G y, G_ij = PD_i M_ij F_j + I_i M_ij; with y = P u the closed loops: u = G P u
    G = (PD.T[:, :, None] * M[None, :, :] * F.T[:, None, :]) + integral.T[:, :, None] * M[None, :, :]  # (W, n, n)
    GP = G * P.T[:, None, :]
    out = np.empty((n, len(w)), complex)
    for i in range(n):
        others = [j for j in range(n) if j != i]
        u = np.zeros((len(w), n), complex)
        u[:, i] = 1.0
        if others:
            A = np.eye(n - 1)[None] - GP[:, others][:, :, others]
            u[:, others] = np.linalg.solve(A, GP[:, others, i][:, :, None])[:, :, 0]
        y = P.T * u
        out[i] = -(y @ M[i])
    return out
