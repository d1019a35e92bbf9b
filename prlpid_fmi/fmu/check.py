"""Open-loop step-response check of every bundled plant against its analytic or reference value."""
from __future__ import annotations

import math

import numpy as np

from prlpid_fmi.fmu.build import bundled_fmu, bundled_plant_names
from prlpid_fmi.fmu.plant import FmuPlant

# name -> (inputs, held input values, output, steps at 0.1 s, expected output, what the expectation is)
STEP_CHECKS = {
    "FirstOrderUnstable": (["u"], [1.0], "y", 20, math.e ** 2 - 1.0, "(e^{at}-1)/a at t = 2 s, a = 1"),
    "SecondOrderUnstable": (["u"], [1.0], "y", 50, "eq17", "scipy.signal.step of eq. 17 at t = 5 s"),
    "TimeVaryingFirstOrder": (["u"], [1.0], "y", 20, "eq22", "scipy solve_ivp of eq. 22-23 at t = 2 s"),
    "TwoTank": (["q_in"], [25.0], "h2", 6000, (25.0 / 7.89) ** 2, "equilibrium h2 = (q_in/k2)^2 after 600 s"),
    "QuadrotorAttitude": (["U_phi", "U_theta", "U_psi"], [0.04, 0.0, 0.0], "phi", 10,
                          0.5 * 0.04 / 0.4 * 1.0 ** 2, "phi(1 s) = U t^2 / (2 Ix) without coupling"),
}


def _reference(key: str) -> float:
    """Values from scipy for the plants without a closed form (independent of the FMU code)."""
    if key == "eq17":
        from scipy import signal

        _, y = signal.step(([-0.2679 * -41.667, -0.2679], [279.03, -2.9781, 1.0]), T=np.linspace(0, 5, 501))
        return float(y[-1])
    from scipy.integrate import solve_ivp

    def rhs(t, x):
        return [(0.5 + 0.25 * (math.sin(0.2 * math.pi * t) + 1.0)) * x[0] + 1.0]

    return float(solve_ivp(rhs, (0, 2), [0.0], rtol=1e-11, atol=1e-12).y[0, -1])


def step_response_report(fmi_version: int = 2) -> str:
    """Build (if needed) and step every bundled plant; one line per plant with the measured value."""
    lines = [f"{'plant':<24}{'output':>8}{'t (s)':>8}{'measured':>16}{'expected':>16}  reference"]
    for name in bundled_plant_names():
        inputs, values, output, steps, expected, what = STEP_CHECKS[name]
        with FmuPlant(bundled_fmu(name, fmi_version), inputs=inputs, outputs=[output]) as plant:
            y = plant.reset()
            for _ in range(steps):
                y = plant.step(np.array(values))
        if isinstance(expected, str):
            expected = _reference(expected)
        exp = f"{expected:16.9g}"
        lines.append(f"{name:<24}{output:>8}{steps * 0.1:>8.1f}{y[0]:>16.9g}{exp:>16}  {what}")
    return "\n".join(lines)
