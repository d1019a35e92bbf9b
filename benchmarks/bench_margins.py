"""Cost and accuracy of loop_margins at the breakpoints of a gain schedule.

Run: python benchmarks/bench_margins.py [--points K]
For each bundled scenario, fixed PID gains and K operating points across the loop's setpoint range
(the first loop's range for every loop of the quadrotor): CPU seconds per operating point, the
estimated Ms, gain and phase margin, and for the linear first-order plants the exact Ms of the ZOH
discretisation times the PID's C(z) on a 40 000-point grid, with the relative error.
Target: a few CPU seconds per operating point; Ms within 1 % of the exact value.

     python benchmarks/bench_margins.py --period
The multisine period (issue 36): every case at its middle setpoint, measured twice in the same run, with the period
sized from the loop (robustness.margins: the loop's settling time, 1024 samples at least) and with every
experiment starting at the fixed 4096 samples of before (SHORTEST_PERIOD set to DEFAULT_PERIOD): FMU samples of the
experiments (the transient waits included), CPU seconds, Ms, and their ratios; the Ms error against the exact loop
where there is one.
"""
from __future__ import annotations

import argparse
import time

import control
import numpy as np

from prlpid_fmi.robustness import identification, margins
from prlpid_fmi.robustness.margins import format_margins, loop_margins, pid_transfer_function
from prlpid_fmi.scenario.presets import preset

CASES = {  # scenario: (Kp, Ti, Td) per loop, exact plant pole a of 1/(s - a) or None
    "first_order": ((3.0, 2.0, 0.05), 1.0),
    "first_order fast": ((6.0, 0.2, 0.0), 1.0),
    "first_order_1p5": ((4.0, 1.5, 0.1), 1.5),
    "two_tank": ((5.0, 20.0, 0.0), None),
    "quadrotor": ((2.0, 5.0, 0.6), None),
    "time_varying": ((5.0, 2.0, 0.05), None),
}


def exact_ms(a: float, gains, Ts: float) -> float:
    L = pid_transfer_function(*gains, Ts) * control.c2d(control.tf([1.0], [1.0, -a]), Ts, "zoh")
    w = np.geomspace(1e-5, np.pi / Ts, 40_000)
    return float(np.max(np.abs(1 / (1 + L(np.exp(1j * w * Ts))))))


def measured(config, gains, setpoint: float, shortest: int) -> tuple:
    """(Margins, FMU samples, CPU s) of loop_margins with margins.SHORTEST_PERIOD = shortest."""
    n = config.n_loops
    samples = []

    def counted(*args):
        response = identification.measure_response(*args)
        wait = int(min(response.period, max(identification.MIN_WAIT, args[-1])))
        samples.append(wait + response.periods * response.period)
        return response

    saved = margins.SHORTEST_PERIOD, margins.measure_response
    margins.SHORTEST_PERIOD, margins.measure_response = shortest, counted
    try:
        start = time.process_time()
        m = loop_margins(config, [gains[0]] * n, [gains[1]] * n, [gains[2]] * n, [setpoint] * n,
                         coupling=[0.0] * 6 if config.coupled else None)
        return m, sum(samples), time.process_time() - start
    finally:
        margins.SHORTEST_PERIOD, margins.measure_response = saved


def periods() -> None:
    print("| scenario | Kp, Ti, Td | samples fixed 4096 | samples sized | ratio | CPU s fixed | CPU s sized | ratio | "
          "Ms fixed | Ms sized | Ms error sized (exact) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    totals = np.zeros(4)
    for name, (gains, a) in CASES.items():
        config = preset(name.split()[0])
        low, high = config.loops[0].setpoint_range
        r = 0.5 * (low + high)
        fixed = measured(config, gains, r, margins.DEFAULT_PERIOD)
        sized = measured(config, gains, r, margins.SHORTEST_PERIOD)
        totals += [fixed[1], sized[1], fixed[2], sized[2]]
        error = f"{sized[0].Ms / exact_ms(a, gains, config.sample_time_s) - 1:+.1e}" if a is not None else "-"
        print(f"| {name} | {', '.join(f'{g:g}' for g in gains)} | {fixed[1]} | {sized[1]} | {sized[1] / fixed[1]:.2f} "
              f"| {fixed[2]:.2f} | {sized[2]:.2f} | {sized[2] / fixed[2]:.2f} | {fixed[0].Ms:.4f} | {sized[0].Ms:.4f} "
              f"| {error} |")
    print(f"| all | | {totals[0]:.0f} | {totals[1]:.0f} | {totals[1] / totals[0]:.2f} | {totals[2]:.2f} | "
          f"{totals[3]:.2f} | {totals[3] / totals[2]:.2f} | | | |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--points", type=int, default=5, help="operating points per scenario")
    parser.add_argument("--period", action="store_true", help="the sized period against a fixed 4096 (issue 36)")
    args = parser.parse_args()
    if args.period:
        periods()
        return
    print(f"{'scenario':<17}{'setpoint':>9}{'CPU s':>7}{'Ms':>9}{'exact Ms':>10}{'error':>9}  margins")
    for name, (gains, a) in CASES.items():
        config = preset(name.split()[0])
        n = config.n_loops
        low, high = config.loops[0].setpoint_range
        coupling = [0.0] * 6 if config.coupled else None
        times = []
        for r in np.linspace(low, high, args.points):
            start = time.process_time()
            m = loop_margins(config, [gains[0]] * n, [gains[1]] * n, [gains[2]] * n, [float(r)] * n,
                             coupling=coupling)
            times.append(time.process_time() - start)
            exact = exact_ms(a, gains, config.sample_time_s) if a is not None else None
            error = f"{m.Ms / exact - 1:+.1e}" if exact is not None else "-"
            exact_text = f"{exact:.4f}" if exact is not None else "-"
            print(f"{name:<17}{r:>9.3g}{times[-1]:>7.2f}{m.Ms:>9.4f}{exact_text:>10}{error:>9}  {format_margins(m)}")
        print(f"{name:<17}{'mean':>9}{np.mean(times):>7.2f}   max {max(times):.2f} s per operating point")


if __name__ == "__main__":
    main()
