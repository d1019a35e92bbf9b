"""Report figures (matplotlib, Agg backend: no display needed), each written to a PNG atomically.

Trajectories are the dicts of prlpid_fmi.evaluate.rollout / evaluate (or schedule.replay_schedule):
time_s (n+1,), setpoint, measurement, control_signal (n+1, n_loops), gains {Kp, Ti, Td: (n, n_loops),
coupling: (n, 6)}. Signal names and units come from the config's loops (the FMU variable names).
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Optional

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib import ticker  # noqa: E402
import numpy as np  # noqa: E402

from .config import TuningConfig  # noqa: E402
from .control import COUPLING_NAMES  # noqa: E402
from .rundir import write_atomic  # noqa: E402

DPI = 110

__all__ = ["plot_response", "plot_control_signal", "plot_gains", "plot_learning_curve", "load_monitor_csvs"]


def _save(fig, path) -> Path:
    """Save fig as PNG atomically (rundir.write_atomic); close fig."""
    try:
        return write_atomic(path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI))
    finally:
        plt.close(fig)


def _units(config: TuningConfig) -> tuple[list[str], list[str]]:
    """Units of each loop's output and input from the FMU description, "" where unknown or unreadable."""
    try:
        from .env import resolve_fmu
        from .fmu import describe_fmu

        d = describe_fmu(resolve_fmu(config.fmu, config.fmi_version))

        def unit(name):
            v = d.variable(name)
            return (v.unit or "") if v is not None else ""

        return [unit(l.output) for l in config.loops], [unit(l.input) for l in config.loops]
    except Exception:  # a figure must not fail because the FMU moved; fall back to unit-less labels
        return [""] * config.n_loops, [""] * config.n_loops


def _label(name: str, unit: str) -> str:
    return f"{name} [{unit}]" if unit else name


def _axes(n: int, height: float = 2.6):
    fig, axes = plt.subplots(n, 1, figsize=(8, 0.8 + height * n), sharex=True, squeeze=False)
    return fig, axes[:, 0]


def plot_response(traj: dict, config: TuningConfig, path, title: str = "Closed-loop response",
                  baseline_traj: Optional[dict] = None, baseline_label: str = "fixed PID") -> Path:
    """Measurement and setpoint against time, one panel per loop; optional baseline measurement overlay."""
    y_units, _ = _units(config)
    fig, axes = _axes(config.n_loops)
    t = traj["time_s"]
    for i, (ax, loop) in enumerate(zip(axes, config.loops)):
        ax.plot(t, traj["setpoint"][:, i], "k--", lw=1.2, label=f"setpoint {loop.output}")
        if baseline_traj is not None:
            ax.plot(baseline_traj["time_s"], baseline_traj["measurement"][:, i], color="tab:orange", lw=1.3,
                    label=f"{loop.output} ({baseline_label})")
        ax.plot(t, traj["measurement"][:, i], color="tab:blue", lw=1.5, label=f"{loop.output} (tuned)")
        ax.set_ylabel(_label(loop.output, y_units[i]))
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(title + (" (terminated: diverged)" if traj.get("terminated") else ""))
    fig.tight_layout()
    return _save(fig, path)


def plot_control_signal(traj: dict, config: TuningConfig, path, baseline_traj: Optional[dict] = None,
                        title: str = "Control signal", baseline_label: str = "fixed PID") -> Path:
    """Control signal (after saturation) per loop as a zero-order hold, with the output limits."""
    _, u_units = _units(config)
    fig, axes = _axes(config.n_loops)
    for i, (ax, loop) in enumerate(zip(axes, config.loops)):
        if baseline_traj is not None:
            ax.step(baseline_traj["time_s"], baseline_traj["control_signal"][:, i], where="post",
                    color="tab:orange", lw=1.1, label=f"{loop.input} ({baseline_label})")
        ax.step(traj["time_s"], traj["control_signal"][:, i], where="post", color="tab:blue", lw=1.3,
                label=f"{loop.input} (tuned)")
        for limit in (loop.u_min, loop.u_max):
            if np.isfinite(limit):
                ax.axhline(limit, color="gray", ls=":", lw=1)
        ax.set_ylabel(_label(loop.input, u_units[i]))
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_gains(traj: dict, config: TuningConfig, path, title: str = "PID parameters set by the policy") -> Path:
    """Kp, Ti, Td against time (one panel each, one line per loop), plus the coupling coefficients if present.

    Gains of step k apply from t = k*Ts to (k+1)*Ts, drawn as a zero-order hold.
    """
    y_units, u_units = _units(config)
    g = traj["gains"]
    n = len(g["Kp"])
    t = np.asarray(traj["time_s"][: n + 1])
    panels = [("Kp", None), ("Ti", "s"), ("Td", "s")] + ([("coupling", "1")] if "coupling" in g else [])
    fig, axes = _axes(len(panels), height=2.0)

    def hold(v):
        return np.append(v, v[-1]) if len(v) else v

    for ax, (key, unit) in zip(axes, panels):
        values = np.asarray(g[key])
        if key == "coupling":
            for j, name in enumerate(COUPLING_NAMES):
                ax.step(t, hold(values[:, j]), where="post", lw=1.2, label=name)
            ax.set_ylabel("coupling [1]")
        else:
            for i, loop in enumerate(config.loops):
                ax.step(t, hold(values[:, i]), where="post", lw=1.3, label=loop.output)
            if key == "Kp":
                units = {f"{u or 'u'}/{y or 'y'}" for u, y in zip(u_units, y_units)}
                unit = units.pop() if len(units) == 1 else "u/y"
            ax.set_ylabel(f"{key} [{unit}]")
            rng = [getattr(l, key) for l in config.loops]
            if all(r.scale == "log" for r in rng) and np.all(values > 0):
                ax.set_yscale("log")
                ax.yaxis.set_major_formatter(ticker.FormatStrFormatter("%g"))
                ax.yaxis.set_minor_formatter(ticker.LogFormatter(labelOnlyBase=False, minor_thresholds=(1, 0.5)))
        ax.grid(True, alpha=0.3, which="both")
        ax.legend(loc="best", fontsize=8, ncol=3 if key == "coupling" else 1)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(title)
    fig.tight_layout()
    return _save(fig, path)


def load_monitor_csvs(monitor_dir) -> tuple[np.ndarray, np.ndarray]:
    """Episodes from SB3 Monitor files ``*.monitor.csv`` (a JSON comment line, then columns r, l, t).

    Returns (timesteps, rewards), ordered by wall time t across files; timesteps is the cumulative
    episode length (l) at the end of each episode, summed over all environments.
    """
    rows = []
    for f in sorted(Path(monitor_dir).glob("*.monitor.csv")):
        with open(f, newline="") as fh:
            lines = [line for line in fh if not line.startswith("#")]
        offset = last = 0.0  # a resumed training appends with its clock restarted at 0: continue it
        for rec in csv.DictReader(lines):
            try:
                t = float(rec["t"])
                row = (t + offset if t + offset >= last else t + last, float(rec["r"]), int(float(rec["l"])))
            except (KeyError, TypeError, ValueError):
                continue  # a line being written by a still-running training
            if row[0] != t + offset:
                offset = last
            last = row[0]
            rows.append(row)
    rows.sort(key=lambda r: r[0])
    rewards = np.array([r[1] for r in rows], float)
    steps = np.cumsum([r[2] for r in rows]).astype(float)
    return steps, rewards


def plot_learning_curve(monitor_dir, path, window: int = 20, title: str = "Learning curve") -> Path:
    """Episode reward against training timesteps from Monitor CSVs, with a rolling mean over `window` episodes."""
    steps, rewards = load_monitor_csvs(monitor_dir)
    fig, ax = plt.subplots(figsize=(8, 4))
    if rewards.size:
        ax.plot(steps, rewards, ".", color="tab:blue", alpha=0.35, ms=4, label="episode reward")
        w = max(1, min(window, rewards.size // 5))  # keep a visible curve for short runs
        mean = np.convolve(rewards, np.ones(w) / w, mode="valid")
        ax.plot(steps[w - 1:], mean, color="tab:red", lw=2, label=f"rolling mean ({w} episodes)")
        ax.legend(loc="best", fontsize=8)
    else:
        ax.text(0.5, 0.5, f"no finished episodes in {monitor_dir}", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("training timesteps [samples]")
    ax.set_ylabel("episode reward [1]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)
