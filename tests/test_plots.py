"""Report figures: valid, non-trivial PNGs written atomically, for SISO, MIMO (coupled) and training logs;
what an engineer reads off them (gain axes, baseline and range limits, disturbance markers, legends);
the Trajectory record and gains.csv's times."""
import csv
import dataclasses
import io
import json
from decimal import Decimal

import matplotlib.image
import matplotlib.pyplot as plt
import numpy as np
import pytest

from prlpid_fmi.config import Disturbance
from prlpid_fmi.loop.core import Termination
from prlpid_fmi.loop.evaluation import Trajectory, constant_gains, gains_rollout, rollout
from prlpid_fmi.report.plots import (
    control_signal_figure, events, gain_axis_limits, gains_figure, load_monitor_csvs, plot_control_signal, plot_gains,
    plot_learning_curve, plot_response, response_figure, step_response_figure, transient_span)
from prlpid_fmi.scenario.presets import preset
from prlpid_fmi.run.gains_csv import trajectory_csv

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SISO = dataclasses.replace(preset("first_order"), setpoint_schedule=((0, (0.5,)), (60, (-0.5,))), episode_steps=120)
QUAD = dataclasses.replace(preset("quadrotor"), setpoint_schedule=((0, (0.2, -0.1, 0.0)),), episode_steps=60)
# an actuator pulse from step 80 to 90 and a measurement step at 100 (Ts = 0.1 s: t = 8 s, 9 s, 10 s)
DISTURBED = dataclasses.replace(SISO, disturbances=(Disturbance("actuator", "y", 80, -2.0, 90),
                                                    Disturbance("measurement", "y", 100, 0.1)))
FIXED = {"Kp": [2.0], "Ti": [0.4], "Td": [0.01]}  # Ti 0.4 s constant: once drawn as "4e-01" on every tick


def varying(obs):
    """Gains that move with the error, so the gain plot has something to show."""
    n = obs.size // 4
    e = obs.reshape(n, 4)[:, 2]
    return np.concatenate([np.stack([np.tanh(e), -0.2 + 0 * e, -0.8 + 0 * e], 1).ravel(),
                           np.full(6 if n == 3 else 0, 0.1)]).astype(np.float32)


@pytest.fixture(scope="module")
def trajs():
    fixed = constant_gains(FIXED["Kp"], FIXED["Ti"], FIXED["Td"])
    return {"siso": rollout(varying, SISO), "baseline": rollout(lambda o: np.array([0.0, 0.0, -1.0], np.float32), SISO),
            "quad": rollout(varying, QUAD), "fixed": gains_rollout(fixed, DISTURBED),
            "disturbed": rollout(varying, DISTURBED)}


def assert_png(path):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 10_000
    img = matplotlib.image.imread(path)
    assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 400
    assert float(np.var(img[..., :3])) > 1e-3  # not a single colour
    assert not list(path.parent.glob("*.part"))  # atomic write leaves no temporary file


def test_siso_figures_with_baseline(trajs, tmp_path):
    t, b = trajs["siso"], trajs["baseline"]
    assert_png(plot_response(t, SISO, tmp_path / "response.png", "first order", baseline_traj=b))
    assert_png(plot_control_signal(t, SISO, tmp_path / "control.png", baseline_traj=b))
    assert_png(plot_gains(t, SISO, tmp_path / "gains.png"))


def test_coupled_mimo_figures(trajs, tmp_path):
    t = trajs["quad"]
    assert_png(plot_response(t, QUAD, tmp_path / "figs" / "response.png", "quadrotor attitude"))
    assert_png(plot_control_signal(t, QUAD, tmp_path / "figs" / "control.png"))
    assert_png(plot_gains(t, QUAD, tmp_path / "figs" / "gains.png"))


def test_overwriting_replaces_the_figure(trajs, tmp_path):
    path = tmp_path / "r.png"
    plot_response(trajs["siso"], SISO, path, "one")
    first = path.read_bytes()
    plot_response(trajs["baseline"], SISO, path, "two")
    assert path.read_bytes() != first
    assert_png(path)


def _write_monitor(path, episodes, t0=0.0):
    with open(path, "w") as f:
        f.write("#" + json.dumps({"t_start": 1700000000.0, "env_id": "None"}) + "\n")
        f.write("r,l,t\n")
        for j, (r, l) in enumerate(episodes):
            f.write(f"{r},{l},{t0 + j:.6f}\n")


def test_learning_curve_from_monitor_csvs(tmp_path):
    rng = np.random.default_rng(0)
    mon = tmp_path / "monitor"
    mon.mkdir()
    # two envs, interleaved in wall time; rewards improve with noise
    _write_monitor(mon / "0.monitor.csv", [(-300 + 5 * j + rng.normal(0, 20), 200) for j in range(40)], t0=0.0)
    _write_monitor(mon / "1.monitor.csv", [(-300 + 5 * j + rng.normal(0, 20), 200) for j in range(40)], t0=0.5)
    steps, rewards = load_monitor_csvs(mon)
    assert steps.tolist() == [200.0 * (k + 1) for k in range(80)] and rewards.shape == (80,)
    assert_png(plot_learning_curve(mon, tmp_path / "learning.png"))


def test_learning_curve_of_an_empty_run_still_draws(tmp_path):
    (tmp_path / "monitor").mkdir()
    path = plot_learning_curve(tmp_path / "monitor", tmp_path / "learning.png")
    assert path.read_bytes()[:8] == PNG_MAGIC


# -- what the figures say ------------------------------------------------------------------------------
def test_a_nearly_constant_gain_draws_nearly_flat():
    # Td = 0.1 s moving by 0.001 s on the range [0, 5] s: at least a tenth of the range is shown
    bottom, top, log = gain_axis_limits([0.1, 0.1005, 0.101], 0.0, 5.0, "linear")
    assert not log and bottom <= 0.1 and top >= 0.101
    assert 0.001 / (top - bottom) < 0.01
    # the magnitude rule alone (an unbounded range): the axis spans at least 20 % of |value|
    bottom, top, _ = gain_axis_limits([100.0, 100.001], -np.inf, np.inf, "linear")
    assert top - bottom >= 20.0 and bottom < 100.0 < top
    # a constant gain on a log range: a real interval, at least a factor 1.2, on a linear axis
    bottom, top, log = gain_axis_limits([0.4] * 50, 0.1, 20.0, "log")
    assert bottom < 0.4 < top and top / bottom >= 1.2 and not log


def test_a_gain_that_moves_fills_its_axis_and_a_wide_one_gets_log_ticks():
    bottom, top, log = gain_axis_limits(np.linspace(2.0, 6.0, 30), 0.5, 50.0, "log")
    assert bottom <= 2.0 and top >= 6.0 and (6.0 - 2.0) / (top - bottom) > 0.8 and not log
    bottom, top, log = gain_axis_limits([0.3, 40.0], 0.1, 100.0, "log")
    assert log and bottom <= 0.3 and top >= 40.0


def test_the_axis_moves_inside_the_gain_range_and_shows_a_near_limit():
    # Td = 0.0017 s near the low limit 0 of [0, 0.2]: the axis starts at the limit, not at -0.01
    bottom, top, _ = gain_axis_limits([0.0017], 0.0, 0.2, "linear")
    assert bottom < 0.0 < bottom + 0.1 * (top - bottom) and top - bottom >= 0.02
    # a negative linear Kp range [-1, -0.01]
    bottom, top, _ = gain_axis_limits([-0.2], -1.0, -0.01, "linear")
    assert bottom < -0.2 < top and top - bottom >= 0.099 and top <= -0.01 + 0.1


def _visible_tick_labels(ax):
    ax.figure.canvas.draw()
    lo, hi = sorted(ax.get_ylim())
    return [t.get_text() for t in ax.get_yticklabels(which="both") if lo <= t.get_position()[1] <= hi and t.get_text()]


def test_gains_figure_baseline_range_and_readable_ticks(trajs):
    fig = gains_figure(trajs["fixed"], DISTURBED, baseline_gains=FIXED)
    try:
        kp_ax, ti_ax, td_ax = fig.axes[:3]
        for ax, key in ((kp_ax, "Kp"), (ti_ax, "Ti"), (td_ax, "Td")):
            labels = _visible_tick_labels(ax)
            assert len(labels) >= 2 and len(set(labels)) == len(labels), (key, labels)
            dashed = [l for l in ax.get_lines() if l.get_linestyle() == "--"]
            assert [list(l.get_ydata()) for l in dashed] == [[FIXED[key][0]] * 2], key
            legend = [t.get_text() for t in ax.get_legend().get_texts()]
            assert legend[:2] == ["adaptive policy", "fixed PID"]
            loop = DISTURBED.loops[0]
            rng = getattr(loop, key)
            assert any(f"{rng.low:g} … {rng.high:g}" in text for text in legend), (key, legend)
        # Td's range [0, 0.2] starts on scale: shaded below 0; Kp's [0.5, 30] is off scale around Kp = 2
        shaded = [a for a in td_ax.patches if a.get_gid() == "gain range"]
        assert len(shaded) == 1 and shaded[0].get_extents().height > 0
        assert not [a for a in kp_ax.patches if a.get_gid() == "gain range"]
        assert "gain range 0.5 … 30 (off scale)" in [t.get_text() for t in kp_ax.get_legend().get_texts()]
    finally:
        plt.close(fig)


def test_gains_figure_draws_a_schedule_replay_dotted_and_each_loop_once(trajs):
    fig = gains_figure(trajs["quad"], QUAD, baseline_gains={"Kp": [1.0, 2.0, 3.0]}, schedule_traj=trajs["quad"])
    try:
        kp_ax = fig.axes[0]
        legend = [t.get_text() for t in kp_ax.get_legend().get_texts()]
        # colours name the loops, line styles the controllers, each once
        assert legend[:3] == ["adaptive policy", "fixed PID", "gain schedule"]
        assert [x for x in legend if x in ("phi", "theta", "psi")] == ["phi", "theta", "psi"]
        dotted = [l for l in kp_ax.get_lines() if l.get_linestyle() == ":" and len(l.get_xdata())]
        assert len(dotted) == 3
        assert np.array_equal(dotted[1].get_ydata()[:-1], trajs["quad"].gains["Kp"][:, 1])
        dashed = sorted(float(l.get_ydata()[0]) for l in kp_ax.get_lines() if l.get_linestyle() == "--"
                        and len(l.get_xdata()))
        assert dashed == [1.0, 2.0, 3.0]
        bottom, top = kp_ax.get_ylim()
        assert bottom <= 1.0 and top >= 3.0  # the fixed PID's gains are on scale
    finally:
        plt.close(fig)


def _disturbance_artists(ax):
    lines = [l for l in ax.get_lines() if l.get_gid() == "disturbance"]
    spans = [p for p in ax.patches if p.get_gid() == "disturbance"]
    texts = [t.get_text().strip() for t in ax.texts if t.get_gid() == "disturbance"]
    return sorted(float(l.get_xdata()[0]) for l in lines), spans, texts


@pytest.mark.parametrize("figure", [response_figure, control_signal_figure])
def test_disturbances_marked_and_both_controllers_named(trajs, figure):
    fig = figure(trajs["disturbed"], DISTURBED, baseline_traj=trajs["fixed"], schedule_traj=trajs["fixed"])
    try:
        (ax,) = fig.axes
        starts, spans, texts = _disturbance_artists(ax)
        assert starts == pytest.approx([8.0, 10.0])  # start_step · Ts
        assert len(spans) == 1  # the pulse's duration; the step lasts to the end
        assert (spans[0].get_x(), spans[0].get_x() + spans[0].get_width()) == pytest.approx((8.0, 9.0))
        assert texts == ["u -2 (actuator offset) for 1 s", "y +0.1 (measurement offset)"]  # u: the loop's input
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        assert {"adaptive policy", "fixed PID", "gain schedule", "disturbance"} <= set(legend)
        words = " ".join(legend + [t.get_text() for a in fig.axes for t in a.texts] + [ax.get_title()])
        assert "tuned" not in words
    finally:
        plt.close(fig)


def test_an_early_end_is_marked_where_it_happened(trajs):
    ended = dataclasses.replace(trajs["siso"], terminated=True,
                                termination=Termination("diverged", 50, 5.0, "diverged"))
    fig = response_figure(ended, SISO, "t")
    try:
        ax = fig.axes[0]
        assert "adaptive policy ended: diverged" in [t.get_text() for t in ax.get_legend().get_texts()]
        assert ax.get_title() == "t (adaptive policy ended early (diverged, t = 5 s))"
    finally:
        plt.close(fig)
    fig = response_figure(ended, SISO, "t", baseline_traj=ended)
    try:
        assert fig.axes[0].get_title() == "t (fixed PID and adaptive policy ended early (diverged, t = 5 s))"
    finally:
        plt.close(fig)


# -- the Trajectory record and gains.csv ------------------------------------------------------------------
def test_trajectory_fields_by_attribute_and_by_name(trajs):
    t = trajs["siso"]
    assert isinstance(t, Trajectory) and t.steps == SISO.episode_steps == len(t.reward)
    assert t["measurement"] is t.measurement and t["gains"]["Kp"] is t.gains["Kp"]
    assert t.time_s.shape == (t.steps + 1,) and t.setpoint.shape == t.measurement.shape == (t.steps + 1, 1)
    assert t.pid_output.shape == (t.steps, 1) and t.termination is None and not t.terminated
    assert t.scheduling_value is None and t.get("nope", 7) == 7
    with pytest.raises(KeyError):
        t["nope"]


def test_gains_csv_times_are_multiples_of_the_sample_time(trajs):
    text = trajectory_csv(trajs["siso"], ["y"], SISO.sample_time_s)
    rows = list(csv.DictReader(io.StringIO(text)))
    assert len(rows) == SISO.episode_steps
    ts = Decimal(repr(SISO.sample_time_s))
    for k, row in enumerate(rows):  # the decimal k·Ts, written as such: 0.3, never 0.30000000000000004
        assert row["time_s"] == repr(float(k * ts)), row["time_s"]
    assert rows[3]["time_s"] == "0.3"


# -- transients, zoomed -----------------------------------------------------------------------------------------
def test_a_first_order_step_lasts_tau_ln_50_to_two_percent():
    tau, ts = 1.0, 0.01
    t = np.arange(0, 20.0, ts)
    deviation = -np.exp(-t / tau)  # y - r of y = 1 - exp(-t/tau) after a unit setpoint step at t = 0
    assert transient_span(t, deviation, 0.0, 20.0) == pytest.approx(tau * np.log(50), abs=0.03)
    # measurement noise of 1 % of the step does not stretch it to the end of the segment
    noisy = deviation + np.random.default_rng(0).normal(0.0, 0.01, t.size)
    assert 3.0 < transient_span(t, noisy, 0.0, 20.0, size=1.0) < 5.0
    # settled from the start: no transient; never settling: the whole segment
    assert transient_span(t, np.zeros_like(t), 0.0, 20.0) == 0.0
    assert transient_span(t, np.sin(t), 0.0, 20.0) == pytest.approx(20.0, abs=0.05)


def test_the_events_are_setpoint_changes_and_disturbances(trajs):
    found = events(trajs["fixed"], DISTURBED)
    assert found == [(0.0, "setpoint y 0 → 0.5"), (6.0, "setpoint y 0.5 → -0.5"),
                     (8.0, "u -2 (actuator offset) for 1 s"), (10.0, "y +0.1 (measurement offset)")]


def test_the_step_response_zooms_each_transient(trajs):
    damped = gains_rollout(constant_gains([8.0], [0.25], [0.0]), DISTURBED)  # near the tuned fixed PID: settles in 1 s
    fig = step_response_figure([("fixed PID", damped), ("adaptive policy", trajs["fixed"])], DISTURBED,
                               "t", deployed="fixed PID")
    try:
        top = fig.axes[:4]  # first row: the measurement, one column per event
        assert [ax.get_title() for ax in top] == ["t = 0 s: setpoint y 0 → 0.5", "t = 6 s: setpoint y 0.5 → -0.5",
                                                  "t = 8 s: u -2 (actuator offset) for 1 s",
                                                  "t = 10 s: y +0.1 (measurement offset)"]
        starts, ends = zip(*(ax.get_xlim() for ax in top))
        # each panel starts at most a tenth of its width before its event and ends by the next one
        for (a, b), t0, t1 in zip(zip(starts, ends), (0.0, 6.0, 8.0, 10.0), (6.0, 8.0, 10.0, 12.0)):
            assert t0 - 0.1 * (b - a) - 1e-9 <= a <= t0 and t0 < b <= t1 + 1e-9
        assert ends[1] == pytest.approx(8.0)  # the ringing PID (Kp 2, Ti 0.4 s) does not settle before the pulse
        fig_damped = step_response_figure([("fixed PID", damped)], DISTURBED, "t")
        assert fig_damped.axes[0].get_xlim()[1] < 2.0  # alone, the damped one's first step fits in 2 s
        plt.close(fig_damped)
        assert top[0].get_ylabel() == "y" and fig.axes[4].get_ylabel() == "u"
        legend = [t.get_text() for t in fig.axes[3].get_legend().get_texts()]
        assert legend == ["setpoint", "fixed PID (deployed)", "adaptive policy"]
    finally:
        plt.close(fig)
