"""An analytic linear plant, y(s) = (b2 s^2 + b1 s + b0) / (a3 s^3 + a2 s^2 + a1 s + a0) u(s) e^(-L s).

Its kind is set by its parameters (the highest nonzero a_i gives the order; a0 = 0 an integrator, a0 = a1 = 0
a double integrator, a zero b1/b0 < 0 an inverse response, a0 < 0 an unstable pole, L a transport delay; order
0 is a static gain b0/a0; x2_0, the second state's start value, starts an order >= 2 plant off equilibrium: for
1/(s (s + 1)) the free response settles at x2_0). Controllable canonical form, stepped exactly for an input held piecewise constant (the zero-order-hold
transition matrix, split where the delayed input changes inside a step); before t = 0 the input was 0.
"""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class TransferFunction(Fmi2Slave):
    author = "prlpid-fmi tests"
    description = "rational transfer function of order <= 3 with a transport delay"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.b0, self.b1, self.b2 = 1.0, 0.0, 0.0
        self.a0, self.a1, self.a2, self.a3 = 1.0, 1.0, 0.0, 0.0
        self.L = 0.0
        self.x2_0 = 0.0
        self.u = 0.0
        self.y = 0.0
        self._x = None
        self._cache = {}
        self._u_start = 0.0          # the input before t = 0 (its start value)
        self._history = []          # (time from which the input holds, value)
        for name in ("b0", "b1", "b2", "a0", "a1", "a2", "a3", "L", "x2_0"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def _system(self):
        a = [self.a0, self.a1, self.a2, self.a3]
        n = max(i for i in range(4) if a[i] != 0.0)
        lead = a[n]
        return n, [c / lead for c in a[:n]], [c / lead for c in (self.b0, self.b1, self.b2)[:max(n, 1)]]

    def _delayed(self, t):
        """The input acting at time t: the value held from the last change at or before t - L."""
        value = self._history[0][1]
        for since, v in self._history:
            if since <= t + 1e-12:
                value = v
        return value

    def _transition(self, h):
        """(Phi, Gamma) of the zero-order-hold step of length h: exp([[A, B], [0, 0]] h) by scaling and squaring."""
        if h not in self._cache:
            n, a, _ = self._system()
            m = [[0.0] * (n + 1) for _ in range(n + 1)]
            for i in range(n - 1):
                m[i][i + 1] = h
            for j in range(n):
                m[n - 1][j] = -a[j] * h
            m[n - 1][n] = h
            norm = max(sum(abs(v) for v in row) for row in m)
            squarings = max(0, math.ceil(math.log2(norm / 0.25))) if norm > 0.25 else 0
            m = [[v / 2 ** squarings for v in row] for row in m]
            size = n + 1
            result = [[float(i == j) for j in range(size)] for i in range(size)]
            term = [row[:] for row in result]
            for k in range(1, 20):
                term = [[sum(term[i][l] * m[l][j] for l in range(size)) / k for j in range(size)] for i in range(size)]
                result = [[result[i][j] + term[i][j] for j in range(size)] for i in range(size)]
            for _ in range(squarings):
                result = [[sum(result[i][l] * result[l][j] for l in range(size)) for j in range(size)]
                          for i in range(size)]
            self._cache[h] = ([row[:n] for row in result[:n]], [row[n] for row in result[:n]])
        return self._cache[h]

    def do_step(self, current_time, step_size):
        n, a, b = self._system()
        if self._x is None:
            self._x = [0.0] * n
            if n >= 2:
                self._x[1] = self.x2_0
            self._history = [(-math.inf, self._u_start)]
        self._history.append((current_time + self.L, self.u))
        end = current_time + step_size
        cuts = sorted({current_time, end} | {s for s, _ in self._history if current_time < s < end})
        x = self._x
        for t0, t1 in zip(cuts, cuts[1:]):
            if n:
                phi, gamma = self._transition(t1 - t0)
                u = self._delayed(t0)
                x = [sum(phi[i][j] * x[j] for j in range(n)) + gamma[i] * u for i in range(n)]
        self._x = x
        u_end = self._delayed(end)
        self.y = self.b0 / self.a0 * u_end if n == 0 else sum(b[i] * x[i] for i in range(min(n, len(b))))
        return True
