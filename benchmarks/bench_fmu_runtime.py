"""Per-call costs of the FMU runtime: step, state copy, get/set state; FMPy's convenience API as baseline.

Run: python benchmarks/bench_fmu_runtime.py [--calls N]
Prints microseconds per call for FMI 2.0 and 3.0 builds of each bundled plant, and the ratio of
FmuPlant.step to the same set/doStep/get sequence through FMPy's FMU2Slave/FMU3Slave methods.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from prlpid_fmi.fmu import FmuPlant, bundled_fmu, bundled_plant_names


def per_call_us(fn, calls: int) -> float:
    fn()  # warm up
    start = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - start) / calls * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--calls", type=int, default=20000)
    args = parser.parse_args()
    print(f"{'plant':<24}{'FMI':>4}{'step us':>10}{'fmpy step us':>14}{'ratio':>7}{'copy us':>10}{'get+set us':>12}")
    for name in bundled_plant_names():
        for version in (2, 3):
            path = bundled_fmu(name, version)
            plant = FmuPlant(path, sample_time_s=0.1)
            prior = FmuPlant(path, sample_time_s=0.1, instance_name="prior")
            u = np.zeros(len(plant.inputs))

            def step():  # reset now and then so unstable plants stay finite
                if plant.time > 5.0:
                    plant.reset()
                plant.step(u)

            fmu = plant._fmu
            in_vr = [plant.description.variable(n).value_reference for n in plant.inputs]
            out_vr = [plant.description.variable(n).value_reference for n in plant.outputs]
            setter = fmu.setFloat64 if version == 3 else fmu.setReal
            getter = fmu.getFloat64 if version == 3 else fmu.getReal

            def fmpy_step():
                if plant.time > 5.0:
                    plant.reset()
                setter(in_vr, list(u))
                fmu.doStep(currentCommunicationPoint=plant.time, communicationStepSize=0.1)
                plant.time += 0.1
                getter(out_vr)

            blob = plant.get_state()
            t_step = per_call_us(step, args.calls)
            t_fmpy = per_call_us(fmpy_step, args.calls)
            plant.reset()
            t_copy = per_call_us(lambda: plant.copy_state_to(prior), args.calls)
            t_getset = per_call_us(lambda: prior.set_state(blob), args.calls)
            print(f"{name:<24}{version:>4}{t_step:>10.2f}{t_fmpy:>14.2f}{t_fmpy / t_step:>7.2f}"
                  f"{t_copy:>10.2f}{t_getset:>12.2f}")
            plant.close()
            prior.close()


if __name__ == "__main__":
    main()
