"""What `probe` identifies and `init` proposes for each plant kind, on the analytic plants the tests build with
pythonfmu (tests/data/pythonfmu/), and whether the single PID init centres its ranges on settles the FMU.

    python benchmarks/bench_init_mechanisms.py

Per plant: the mechanism the probe names, the loop init chooses, its sample time, the centre of its Kp, Ti and
Td ranges (the design) and the ranges, the setpoint hold, and the design's closed loop on the FMU itself,
run on the scenario's own evaluation (its two setpoint steps): settled when the last 10 samples of each step
are within 2 % of the step (as tests/test_open_loop.py judges a tuned PID). Nothing here is asserted: it is a
measurement (tests/test_proposal.py asserts the identification and the choices).
"""
from __future__ import annotations

import datetime as dt
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from prlpid_fmi.loop.evaluation import evaluate_gains
from prlpid_fmi.probe.proposal import choose_loop, propose_loop
from prlpid_fmi.probe.open_loop import probe_outputs
from prlpid_fmi.scenario.draft import init_scenario
from prlpid_fmi.scenario.load import load_scenario

DATA = Path(__file__).parent.parent / "tests" / "data" / "pythonfmu"
ZERO = {name: 0.0 for name in ("b0", "b1", "b2", "a0", "a1", "a2", "a3", "L")}
PLANTS = [  # (label, FMU, parameters)
    ("lag 2/(5s+1)", "TransferFunction", {"b0": 2.0, "a1": 5.0, "a0": 1.0}),
    ("lag with delay 2e^(-2s)/(5s+1)", "TransferFunction", {"b0": 2.0, "a1": 5.0, "a0": 1.0, "L": 2.0}),
    ("delay 2e^(-s)", "TransferFunction", {"b0": 2.0, "a0": 1.0, "L": 1.0}),
    ("pure integrator 0.5/s", "TransferFunction", {"b0": 0.5, "a1": 1.0}),
    ("integrator with lag 0.5/(s(3s+1))", "TransferFunction", {"b0": 0.5, "a2": 3.0, "a1": 1.0}),
    ("double integrator 0.5/s²", "TransferFunction", {"b0": 0.5, "a2": 1.0}),
    ("oscillator 4/(s²+0.4s+4)", "TransferFunction", {"b0": 4.0, "a2": 1.0, "a1": 0.4, "a0": 4.0}),
    ("inverse response 2(1-5s)/((30s+1)(15s+1))", "TransferFunction",
     {"b0": 2.0, "b1": -10.0, "a2": 450.0, "a1": 45.0, "a0": 1.0}),
    ("unstable 1/(s-0.5)", "TransferFunction", {"b0": 1.0, "a1": 1.0, "a0": -0.5}),
    ("free inertia (angle, speed)", "FreeInertia", {}),
    ("mass on a spring (velocity, position)", "MassSpringDamper", {}),
    ("magnetic levitation with stops", "MagLev", {}),
]


def _settled(path: Path, design: dict) -> str:
    s = load_scenario(path)
    _, traj = evaluate_gains(lambda core: ([design["Kp"]], [design["Ti"]], [design["Td"]], None),
                             s.evaluation_config(), intervals=s.evaluation.intervals)
    y, r = traj["measurement"][:, 0], traj["setpoint"][:, 0]
    verdicts = []
    for start, end in s.evaluation.intervals:
        if end > len(y):
            return "diverged"
        step = abs(r[end - 1] - (r[start - 1] if start else y[0]))
        verdicts.append(np.max(np.abs(y[end - 10:end] - r[end - 10:end])) < 0.02 * step)
    return "yes" if all(verdicts) else "no"


def main() -> None:
    out = Path(tempfile.mkdtemp(prefix="mechanisms-"))
    built = {}
    for name in sorted({fmu for _, fmu, _ in PLANTS}):
        subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(DATA / f"{name}.py"), "-d", str(out)],
                       check=True, capture_output=True)
        built[name] = out / f"{name}.fmu"
    print(f"# bench_init_mechanisms.py, {dt.date.today()}")
    print("| plant | probe: mechanism | init: input -> output | sample time | design Kp, Ti, Td | Kp range | "
          "Ti range | Td range | hold | design settles on the FMU |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for label, fmu, parameters in PLANTS:
        start = {**ZERO, **parameters} if fmu == "TransferFunction" else {}
        results = probe_outputs(built[fmu], start_values=start)
        chosen, why = choose_loop(results)
        loop = propose_loop(chosen, why)
        mech = loop.response.mechanism
        path = out / f"{label.split()[0]}-{len(label)}.yaml"
        path.write_text(init_scenario(built[fmu], start_values=start))
        d, g = loop.design, loop.gains
        print(f"| {label} | {mech} | {loop.input} -> {loop.output} | {loop.sample_time_s:g} s | "
              f"{d['Kp']:.3g}, {d['Ti']:.3g} s, {d['Td']:.3g} s | {g['Kp'][0]:g} to {g['Kp'][1]:g} | "
              f"{g['Ti'][0]:g} to {g['Ti'][1]:g} s | 0 to {g['Td'][1]:g} s | {loop.hold_steps} | "
              f"{_settled(path, d)} |")


if __name__ == "__main__":
    main()
