"""CPU time of one reward forecast call: the one-call C forecast vs the standard FMI path (issue 7).

Run:  python benchmarks/bench_forecast.py            (repeats 15, 2000 calls each)
      python benchmarks/bench_forecast.py --quick    (repeats 5, 300 calls each)

For first_order, two_tank and quadrotor (the bundled scenarios' training configs: loops, limits,
scales, anti-windup, plant parameters, reward weights), a plant FMU and a prior FMU of the same file
are warmed up for 50 samples in closed loop with mid-range gains; then `mean_reward` is called with
fixed arguments, through NativeForecast (one C call) and FmiForecast (get/serialize/deserialize/set
state, then N set/doStep/get through FMI with the Python PID and reward). Each cell is the median
over repeats of process CPU time per call; within a repeat both paths run back to back in an order
that alternates, so load on the shared machine hits both alike. Both paths return the same value
(checked, ==) before timing. The FMU's RK4 sub-steps are included in both columns.
"""
from __future__ import annotations

import argparse
import math
import statistics
import time

from prlpid_fmi.control import PID, CoupledPID
from prlpid_fmi.loop.forecast import make_forecast
from prlpid_fmi.loop.core import control_scales
from prlpid_fmi.fmu.resolve import resolve_fmu
from prlpid_fmi.fmu import FmuPlant
from prlpid_fmi.scenario.presets import preset

SCENARIOS = ("first_order", "two_tank", "quadrotor")
HORIZONS = (3, 10)


def _mid(g) -> float:
    return math.sqrt(g.low * g.high) if g.scale == "log" and g.low > 0 else 0.5 * (g.low + g.high)


def setup(name: str, horizon: int):
    """(native forecast, FMI-path forecast, mean_reward arguments, closer) for one scenario and N."""
    c = preset(name)
    path = resolve_fmu(c.fmu, c.fmi_version)
    inputs, outputs = [l.input for l in c.loops], [l.output for l in c.loops]
    plant = FmuPlant(path, inputs, outputs, c.sample_time_s, c.plant_parameters, "plant")
    prior = FmuPlant(path, inputs, outputs, c.sample_time_s, c.plant_parameters, "prior")
    n = len(c.loops)
    u_min, u_max = [l.u_min for l in c.loops], [l.u_max for l in c.loops]
    pid_args = dict(u_min=u_min, u_max=u_max, anti_windup=c.anti_windup, derivative_filter_N=c.derivative_filter_N)
    pid = CoupledPID(c.sample_time_s, **pid_args) if c.coupled else PID(c.sample_time_s, n, **pid_args)
    Kp, Ti, Td = ([_mid(getattr(l, g)) for l in c.loops] for g in ("Kp", "Ti", "Td"))
    coupling = [0.05, -0.05, 0.02, 0.0, -0.02, 0.01] if c.coupled else None
    setpoint = [0.5 * (l.setpoint_range[0] + l.setpoint_range[1]) + 0.25 * (l.setpoint_range[1] - l.setpoint_range[0])
                for l in c.loops]
    y = plant.read_outputs().tolist()
    for _ in range(50):
        if c.coupled:
            u = pid.step_values(setpoint, y, Kp, Ti, Td, coupling)
        else:
            u = pid.step_values([setpoint[i] - y[i] for i in range(n)], Kp, Ti, Td)
        y = plant.step_values(u)
    kw = dict(horizon=horizon, scale=[l.measurement_scale for l in c.loops], bound=[l.divergence_bound for l in c.loops],
              penalty=c.divergence_penalty, weights=c.reward, u_scale=control_scales(c))
    native = make_forecast(plant, prior, pid, path="native", **kw)
    fmi = make_forecast(plant, prior, pid, path="fmi", **kw)
    args = (setpoint, y, Kp, Ti, Td, coupling, u)
    assert native.mean_reward(*args) == fmi.mean_reward(*args), name

    def close():
        plant.close()
        prior.close()
    return native, fmi, args, close


def cpu_us_per_call(forecast, args, calls: int) -> float:
    call = forecast.mean_reward
    t0 = time.process_time()
    for _ in range(calls):
        call(*args)
    return (time.process_time() - t0) / calls * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats and calls")
    a = parser.parse_args()
    repeats, calls = (5, 300) if a.quick else (15, 2000)
    print(f"µs CPU per forecast call, median of {repeats} repeats x {calls} calls")
    print(f"{'scenario':<12} {'N':>3} {'native':>9} {'FMI path':>9} {'FMI/native':>11}")
    for name in SCENARIOS:
        for horizon in HORIZONS:
            native, fmi, args, close = setup(name, horizon)
            times = {"native": [], "fmi": []}
            for r in range(repeats):
                order = (("native", native), ("fmi", fmi)) if r % 2 == 0 else (("fmi", fmi), ("native", native))
                for label, forecast in order:
                    times[label].append(cpu_us_per_call(forecast, args, calls))
            close()
            t_native, t_fmi = statistics.median(times["native"]), statistics.median(times["fmi"])
            print(f"{name:<12} {horizon:>3} {t_native:>9.1f} {t_fmi:>9.1f} {t_fmi / t_native:>10.1f}x")


if __name__ == "__main__":
    main()
