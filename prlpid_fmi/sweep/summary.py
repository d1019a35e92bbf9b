"""A sweep's summary: per variant, mean and 95 % confidence interval over seeds, for four controllers.

Controllers, from each trial's metrics.json:
- ``policy``: the trained policy on the evaluation (metrics.json "policy");
- ``schedule``: its gain schedule replayed as a plain PID ("schedule_replay");
- ``fixed_pid``: the tuned fixed PID ("fixed_pid");
- ``deployed``: whichever of schedule and fixed PID the run chose to deploy ("deployed"; its assessment metrics);
  nothing when the run deployed nothing.

Metrics: ISE, IAE, overshoot [%], settling time [s], and for regulation segments (no setpoint step)
peak deviation and recovery time; overall (summed over loops for ISE / IAE, worst loop otherwise:
metrics.overall_metric) and per evaluation interval. For each (variant, controller, interval, metric):
n = seeds where the metric is defined (not NaN: e.g. no overshoot without a setpoint step, no segment
starting in the interval), n_finite = those with a finite value (a loop that never settles has an infinite
settling time), mean and the Student-t 95 % interval mean ± t(0.975, n_finite - 1) · s / sqrt(n_finite)
over the finite values (none for fewer than two). ended_early counts the trials whose evaluation of that
controller stopped before its last sample (their integral metrics cover fewer samples).

Files: trials.csv (one value per trial, controller, interval and metric), summary.csv (the statistics),
summary.md (tables), learning_curves.png (episode reward over training steps: per variant the mean over
seeds of each seed's rolling mean, with a band of ± one standard deviation), metrics.png (overall means
with their 95 % intervals).
"""
from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np

from prlpid_fmi import rundir as rd
from prlpid_fmi.deliver.rule import Deployed
from prlpid_fmi.metrics import overall_metric
from prlpid_fmi.run.record import RunRecord
from prlpid_fmi.rundir import write_atomic

CONTROLLERS = {"policy": "adaptive policy", "schedule": "replayed schedule", "fixed_pid": "fixed PID",
               "deployed": "deployed"}
METRICS = ("ISE", "IAE", "Overshoot", "SettlingTime", "PeakDeviation", "RecoveryTime")
UNITS = {"Overshoot": " [%]", "SettlingTime": " [s]", "RecoveryTime": " [s]"}
OVERALL = "overall"
SUMMARY_COLUMNS = ("variant", "controller", "interval", "metric", "n", "n_finite", "mean", "ci95_low", "ci95_high",
                   "ci95_half_width", "ended_early")
ROLLING_EPISODES = 20


def controller_metrics(metrics: dict) -> dict:
    """{controller: compute_metrics dict or None} of one run's metrics.json."""
    def inner(entry):
        return entry.get("metrics") if isinstance(entry, dict) else None

    out = {"policy": metrics.get("policy"), "schedule": inner(metrics.get("schedule_replay")),
           "fixed_pid": inner(metrics.get("fixed_pid"))}
    out["deployed"] = {Deployed.SCHEDULE: out["schedule"],
                       Deployed.CLASSICAL: inner(metrics.get("classical_schedule_replay")),
                       Deployed.FIXED_PID: inner(metrics.get("fixed_pid_assessment"))}.get(Deployed.read(metrics.get("deployed")))
    return out


def _ended_early(m: dict) -> bool:
    return bool(m.get("termination") or m.get("terminated"))


def interval_label(iv: dict) -> str:
    return f"{iv['start_step']}-{iv['end_step']}"


def trial_rows(variant: str, seed: int, metrics: dict) -> list[dict]:
    """One row per controller, interval (overall first) and metric of one trial."""
    rows = []
    for controller, m in controller_metrics(metrics).items():
        if not m:
            continue
        scopes = [(OVERALL, m["overall"])] + [(interval_label(iv), iv) for iv in m.get("intervals", ())]
        for scope, values in scopes:
            for metric in METRICS:
                rows.append({"variant": variant, "seed": seed, "controller": controller, "interval": scope,
                             "metric": metric, "value": overall_metric(values, metric),
                             "ended_early": _ended_early(m)})
    return rows


def mean_ci(values) -> tuple[int, float, float]:
    """(n_finite, mean, 95 % half-width) over the finite values; half-width NaN below two values."""
    from scipy import stats

    x = np.asarray([v for v in values if math.isfinite(v)], float)
    n = x.size
    if n == 0:
        return 0, math.nan, math.nan
    if n == 1:
        return 1, float(x[0]), math.nan
    half = float(stats.t.ppf(0.975, n - 1) * x.std(ddof=1) / math.sqrt(n))
    return n, float(x.mean()), half


def aggregate(rows: list[dict], variants: list[str]) -> list[dict]:
    """summary.csv rows: statistics per (variant, controller, interval, metric), in variant order."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["variant"], r["controller"], r["interval"], r["metric"]), []).append(r)
    order = {v: i for i, v in enumerate(variants)}
    controllers = list(CONTROLLERS)
    out = []
    for key in sorted(groups, key=lambda k: (order[k[0]], controllers.index(k[1]), k[2] != OVERALL,
                                             _interval_start(k[2]), METRICS.index(k[3]))):
        g = groups[key]
        defined = [r["value"] for r in g if not math.isnan(r["value"])]  # NaN: not defined there (see metrics.py)
        n_finite, mean, half = mean_ci(defined)
        out.append(dict(zip(SUMMARY_COLUMNS, (*key, len(defined), n_finite, mean, mean - half, mean + half, half,
                                              sum(r["ended_early"] for r in g)))))
    return out


def _interval_start(label: str) -> int:
    return -1 if label == OVERALL else int(label.split("-")[0])


def _csv(rows: list[dict], columns) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({k: repr(v) if isinstance(v, float) else v for k, v in r.items()})
    return buf.getvalue()


# -- markdown --------------------------------------------------------------------------------------
def _cell(stat: dict | None) -> str:
    if stat is None or stat["n"] == 0:
        return "—"
    if stat["n_finite"] == 0:
        return f"not finite ({stat['n']}/{stat['n']})"
    text = f"{stat['mean']:.4g}"
    if math.isfinite(stat["ci95_half_width"]):
        text += f" ± {stat['ci95_half_width']:.2g}"
    notes = []
    if stat["n_finite"] < stat["n"]:
        notes.append(f"{stat['n'] - stat['n_finite']} of {stat['n']} not finite")
    if stat["ended_early"]:
        notes.append(f"{stat['ended_early']} ended early")
    return text + (f" ({'; '.join(notes)})" if notes else "")


def _deployed_counts(choices: list[str]) -> str:
    names = {Deployed.SCHEDULE: "schedule", Deployed.CLASSICAL: "classical schedule", Deployed.FIXED_PID: "fixed PID",
             Deployed.NONE: "none"}
    return ", ".join(f"{names.get(c, c)} {choices.count(c)}" for c in dict.fromkeys(choices)) or "—"


def _markdown(sweep, out: Path, stats: list[dict], finished: dict, deployed: dict, failed: list[str],
              wall: dict) -> str:
    index = {(s["variant"], s["controller"], s["interval"], s["metric"]): s for s in stats}
    variants = [v.name for v in sweep.variants]
    shown = [m for m in METRICS if any(s["metric"] == m and s["n_finite"] for s in stats)]
    intervals = sorted({s["interval"] for s in stats if s["interval"] != OVERALL}, key=_interval_start)
    n_trials = len(variants) * len(sweep.seeds)
    lines = [f"# Sweep {sweep.name}", "",
             f"Sweep file `{sweep.path}`; base scenario `{sweep.base}`; seeds {', '.join(map(str, sweep.seeds))}; "
             + (f"{sweep.timesteps} training steps per trial." if sweep.timesteps else "the scenario's training budget."),
             "", f"Finished trials: {sum(len(f) for f in finished.values())} of {n_trials}."]
    if failed:
        lines += ["", "Failed in the last invocation:", ""] + [f"- {f}" for f in failed]
    lines += ["", "Values: mean ± half-width of the 95 % confidence interval (Student t over the seeds with a finite "
              "value); lower is better. Controllers: the trained policy, its gain schedule replayed as a plain PID, "
              "the tuned fixed PID, and the one the run deployed.", ""]
    common = [f"`{k}: {json.dumps(val)}`" for k, val, origin in sweep.variants[0].overrides if origin == "set"]
    lines += ["## Variants", ""] + ([f"Every variant: {', '.join(common)}.", ""] if common else [])
    lines += ["| variant | keys | finished seeds | deployed | trial wall time [s] |", "|---|---|---|---|---|"]
    for v in sweep.variants:
        keys = ", ".join(f"`{k}: {json.dumps(val)}`" for k, val, origin in v.overrides if origin != "set") or "—"
        w = wall.get(v.name) or []
        wtext = f"{np.mean(w):.0f} (mean of {len(w)})" if w else "—"
        lines.append(f"| {v.name} | {keys} | {len(finished.get(v.name, []))} | "
                     f"{_deployed_counts(deployed.get(v.name, []))} | {wtext} |")
    lines += ["", "## Overall", ""]
    for metric in shown:
        lines += [f"### {metric}{UNITS.get(metric, '')}", "",
                  "| variant | " + " | ".join(CONTROLLERS.values()) + " |", "|---" * (1 + len(CONTROLLERS)) + "|"]
        for v in variants:
            lines.append(f"| {v} | " + " | ".join(_cell(index.get((v, c, OVERALL, metric))) for c in CONTROLLERS)
                         + " |")
        lines.append("")
    if len(intervals) > 1:
        lines += ["## Per evaluation interval [samples]", ""]
        for metric in shown:
            if not any(index.get((v, c, i, metric), {}).get("n_finite") for v in variants for c in CONTROLLERS
                       for i in intervals):
                continue
            lines += [f"### {metric}{UNITS.get(metric, '')} per interval", "",
                      "| variant | controller | " + " | ".join(intervals) + " |", "|---" * (2 + len(intervals)) + "|"]
            for v in variants:
                for c, cname in CONTROLLERS.items():
                    cells = [_cell(index.get((v, c, i, metric))) for i in intervals]
                    if any(x != "—" for x in cells):
                        lines.append(f"| {v} | {cname} | " + " | ".join(cells) + " |")
            lines.append("")
    lines += ["## Figures", "", "![learning curves](learning_curves.png)", "", "![overall metrics](metrics.png)", ""]
    invocations = _invocations(out)
    if invocations:
        lines += ["## Invocations", "", "| started (UTC) | command | backend | trials run | failed | wall time [s] |",
                  "|---|---|---|---|---|---|"]
        for inv in invocations:
            command = " ".join(["prlpid-fmi", *inv.get("command", [])[1:]])
            backend = inv.get("backend", "")
            backend += f" ({inv['workers']} processes)" if inv.get("workers") and inv.get("trials_run") else (
                f" ({inv['ray_address']})" if inv.get("ray_address") else "")
            run = f"{inv.get('trials_run', '')}" + (" (interrupted)" if inv.get("interrupted") else "")
            lines.append(f"| {inv.get('started', '')} | `{command}` | {backend} | {run} | "
                         f"{len(inv.get('failed', {}))} | {inv.get('wall_s', float('nan')):.1f} |")
        lines.append("")
    return "\n".join(lines)


def _invocations(out: Path) -> list[dict]:
    """The invocation records of sweep.json (runner.py), oldest first."""
    try:
        return json.loads((out / "sweep.json").read_text()).get("invocations", [])
    except (OSError, json.JSONDecodeError):
        return []


# -- figures ---------------------------------------------------------------------------------------
def seed_curve(monitor_dir: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """(training steps, rolling mean of the episode reward) of one trial, or None without finished episodes."""
    from prlpid_fmi.report.plots import load_monitor_csvs

    steps, rewards = load_monitor_csvs(monitor_dir)
    if not rewards.size:
        return None
    w = max(1, min(ROLLING_EPISODES, rewards.size // 5))
    return steps[w - 1:], np.convolve(rewards, np.ones(w) / w, mode="valid")


def band(curves: list[tuple[np.ndarray, np.ndarray]], points: int = 200):
    """(grid, mean, std) of several curves on the steps all of them cover (linear interpolation)."""
    lo = max(c[0][0] for c in curves)
    hi = min(c[0][-1] for c in curves)
    grid = np.linspace(lo, hi, points) if hi > lo else np.array([lo])
    ys = np.array([np.interp(grid, s, r) for s, r in curves])
    return grid, ys.mean(axis=0), ys.std(axis=0)


def curve_seeds(sweep, variant: str, finished: dict) -> tuple:
    """The seeds whose learning curves a variant's band is drawn from: its finished trials, or, before any
    has finished, every seed (the band covers only the steps all its curves reach, so an unfinished
    trial beside finished ones would cut their curves short)."""
    return tuple(finished.get(variant) or sweep.seeds)


def plot_learning_curves(sweep, out: Path, path: Path, finished: dict | None = None) -> Path:
    """finished: {variant: seeds of its finished trials} (see curve_seeds; None: every seed)."""
    from prlpid_fmi.report.plots import new_figure, save_figure

    fig, ax = new_figure(figsize=(9, 5))
    drawn = 0
    for i, v in enumerate(sweep.variants):
        seeds = curve_seeds(sweep, v.name, finished or {})
        curves = [c for c in (seed_curve(out / v.name / f"seed{s}" / rd.MONITOR) for s in seeds) if c]
        if not curves:
            continue
        grid, mean, std = band(curves)
        color = f"C{i % 10}"
        ax.plot(grid, mean, color=color, lw=1.8, label=f"{v.name} (n = {len(curves)})")
        if len(curves) > 1:
            ax.fill_between(grid, mean - std, mean + std, color=color, alpha=0.2, lw=0)
        drawn += 1
    if not drawn:
        ax.text(0.5, 0.5, "no finished episodes yet", ha="center", va="center", transform=ax.transAxes)
    else:
        ax.legend(loc="best", fontsize=8)
    ax.set_xlabel("training steps [samples]")
    ax.set_ylabel(f"episode reward, rolling mean of up to {ROLLING_EPISODES} episodes [1]")
    ax.set_title(f"{sweep.name}: learning curves, mean over seeds ± 1 standard deviation")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_metrics(sweep, stats: list[dict], rows: list[dict], path: Path) -> Path:
    """Overall mean per variant and controller with 95 % intervals and each seed's value, one panel per metric."""
    from prlpid_fmi.report.plots import new_figure, save_figure

    index = {(s["variant"], s["controller"], s["metric"]): s for s in stats if s["interval"] == OVERALL}
    shown = [m for m in METRICS if any(s["metric"] == m and s["n_finite"] for s in index.values())] or ["ISE"]
    variants = [v.name for v in sweep.variants]
    fig, axes = new_figure(len(shown), 1, figsize=(max(7, 1.4 * len(variants) + 3), 2.8 * len(shown)),
                             squeeze=False)
    width = 0.8 / len(CONTROLLERS)
    x = np.arange(len(variants))
    for ax, metric in zip(axes[:, 0], shown):
        for j, (c, cname) in enumerate(CONTROLLERS.items()):
            s = [index.get((v, c, metric)) for v in variants]
            mean = np.array([st["mean"] if st else np.nan for st in s])
            half = np.array([st["ci95_half_width"] if st else np.nan for st in s])
            at = x + (j - (len(CONTROLLERS) - 1) / 2) * width
            upper = np.nan_to_num(half)  # every metric here is >= 0: the interval is cut at 0 below
            ax.bar(at, mean, width, yerr=[np.minimum(upper, np.nan_to_num(mean)), upper], capsize=2, color=f"C{j}",
                   label=cname)
            for k, v in enumerate(variants):
                seeds = [r["value"] for r in rows if r["variant"] == v and r["controller"] == c
                         and r["interval"] == OVERALL and r["metric"] == metric and math.isfinite(r["value"])]
                ax.plot([at[k]] * len(seeds), seeds, "o", color="black", mfc="white", ms=4, label="seeds" if (j, k) == (0, 0) else None)
        positive = [st["mean"] for st in index.values() if st["metric"] == metric and st["n_finite"]]
        if positive and min(positive) > 0 and max(positive) / min(positive) > 30:
            ax.set_yscale("log")
        ax.set_ylabel(metric + UNITS.get(metric, ""))
        ax.set_xticks(x, variants, rotation=20 if len(variants) > 4 else 0, ha="right" if len(variants) > 4 else "center",
                      fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
    axes[0, 0].set_title(f"{sweep.name}: overall metrics, mean and 95 % interval over seeds (cut at 0)")
    fig.tight_layout(rect=(0, 0.35 / fig.get_figheight(), 1, 1))
    return save_figure(fig, path)


# -- all of it -------------------------------------------------------------------------------------
def write_summary(sweep, out: Path, trials, failed: list[str] = ()) -> list[Path]:
    """Read every finished trial of the sweep and write trials.csv, summary.csv, summary.md and the figures."""
    rows, finished, deployed, wall = [], {}, {}, {}
    for t in trials:
        d = Path(t.run_dir)
        record = RunRecord.read(d)
        try:
            metrics = json.loads((d / rd.METRICS).read_text())
        except (OSError, json.JSONDecodeError):
            continue
        if record is None or not record.finished:
            continue
        finished.setdefault(t.variant, []).append(t.seed)
        deployed.setdefault(t.variant, []).append(metrics.get("deployed") or "none")
        rows += trial_rows(t.variant, t.seed, metrics)
        if record.started and not record.resumed:
            from datetime import datetime

            seconds = (datetime.fromisoformat(record.finished) - datetime.fromisoformat(record.started)).total_seconds()
            wall.setdefault(t.variant, []).append(seconds)
    stats = aggregate(rows, [v.name for v in sweep.variants])
    files = [write_atomic(out / "trials.csv", _csv(rows, ("variant", "seed", "controller", "interval", "metric", "value",
                                                          "ended_early"))),
             write_atomic(out / "summary.csv", _csv(stats, SUMMARY_COLUMNS)),
             write_atomic(out / "summary.md", _markdown(sweep, out, stats, finished, deployed, list(failed), wall)),
             plot_learning_curves(sweep, out, out / "learning_curves.png", finished),
             plot_metrics(sweep, stats, rows, out / "metrics.png")]
    return files
