"""What the supervised `tune` (prlpid_fmi.run.supervise) costs: the parent's fork, the memory it keeps while it waits,
and the crumb its child's FMU calls write (FmuPlant.step_values with and without it, first_order's plant).

    python benchmarks/bench_supervise.py
"""
import os
import resource
import statistics
import time

started = time.perf_counter()
import prlpid_fmi.cli  # noqa: E402,F401 - what the parent has imported when it forks

imported_s = time.perf_counter() - started
forks = []
for _ in range(20):
    t = time.perf_counter()
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    os.waitpid(pid, 0)
    forks.append(time.perf_counter() - t)
print(f"parent at the fork: imports {imported_s * 1e3:.0f} ms, max RSS "
      f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB; fork + exit + wait: median "
      f"{statistics.median(forks) * 1e3:.2f} ms")

from prlpid_fmi.fmu import FmuPlant, worker  # noqa: E402
from prlpid_fmi.fmu.resolve import resolve_fmu  # noqa: E402

path = resolve_fmu("FirstOrderUnstable", 2)


def per_step(n: int = 200_000) -> float:
    """The best of 5 timings of n / 5 steps [s per step]."""
    best = []
    with FmuPlant(path, ["u"], ["y"], 1e-3, {"a": -1.0}) as plant:
        for _ in range(5):
            t = time.perf_counter()
            for _ in range(n // 5):
                plant.step_values([0.1])
            best.append((time.perf_counter() - t) / (n // 5))
    return min(best)


plain = per_step()
crumb = worker.new_crumb_file()
worker.attach_crumb(crumb)
marked = per_step()
worker.remove_crumb_file(crumb)
print(f"FmuPlant.step_values: {plain * 1e6:.2f} us without the crumb, {marked * 1e6:.2f} us with it "
      f"(+{(marked - plain) * 1e9:.0f} ns a step)")
