"""gains.csv: the evaluation's trajectory, one row per control step."""
from __future__ import annotations

import csv
import decimal
import io

import numpy as np


# -- trajectories to CSV ---------------------------------------------------------------------------
def sample_times(steps: int, sample_time_s: float) -> np.ndarray:
    """t = k·Ts for k = 0..steps-1 [s], rounded to the decimals of Ts (0.3, not 0.30000000000000004)."""
    decimals = max(0, -decimal.Decimal(repr(float(sample_time_s))).as_tuple().exponent)
    return np.round(np.arange(steps) * sample_time_s, decimals)


def trajectory_csv(traj, loop_names: list[str], sample_time_s: float) -> str:
    """gains.csv text of a loop.evaluation.Trajectory: one row per control step k (t = k·Ts, rounded to the
    sample time's decimals): setpoint, measurement, control signal and gains (Ki = Kp/Ti, Kd = Kp·Td)."""
    gains = traj.gains
    n = traj.steps
    times = sample_times(n, sample_time_s)
    header = ["step", "time_s"]
    for name in loop_names:
        header += [f"setpoint[{name}]", f"measurement[{name}]", f"control_signal[{name}]",
                   f"Kp[{name}]", f"Ti[{name}]", f"Td[{name}]", f"Ki[{name}]", f"Kd[{name}]"]
    coupling = gains.get("coupling")
    if coupling is not None:
        from prlpid_fmi.control import COUPLING_NAMES
        header += list(COUPLING_NAMES)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for k in range(n):
        row = [k, repr(float(times[k]))]
        for i in range(len(loop_names)):
            kp, ti, td = gains["Kp"][k][i], gains["Ti"][k][i], gains["Td"][k][i]
            row += [repr(float(v)) for v in (traj.setpoint[k][i], traj.measurement[k][i],
                                            traj.control_signal[k][i], kp, ti, td, kp / ti, kp * td)]
        if coupling is not None:
            row += [repr(float(v)) for v in coupling[k]]
        w.writerow(row)
    return buf.getvalue()
