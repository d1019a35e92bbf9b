"""Report figures: valid, non-trivial PNGs written atomically, for SISO, MIMO (coupled) and training logs."""
import dataclasses
import json

import matplotlib.image
import numpy as np
import pytest

from prlpid_fmi.evaluate import rollout
from prlpid_fmi.plots import (load_monitor_csvs, plot_control_signal, plot_gains, plot_learning_curve,
                              plot_response)
from prlpid_fmi.presets import preset

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SISO = dataclasses.replace(preset("first_order"), setpoint_schedule=((0, (0.5,)), (60, (-0.5,))), episode_steps=120)
QUAD = dataclasses.replace(preset("quadrotor"), setpoint_schedule=((0, (0.2, -0.1, 0.0)),), episode_steps=60)


def varying(obs):
    """Gains that move with the error, so the gain plot has something to show."""
    n = obs.size // 4
    e = obs.reshape(n, 4)[:, 2]
    return np.concatenate([np.stack([np.tanh(e), -0.2 + 0 * e, -0.8 + 0 * e], 1).ravel(),
                           np.full(6 if n == 3 else 0, 0.1)]).astype(np.float32)


@pytest.fixture(scope="module")
def trajs():
    return {"siso": rollout(varying, SISO), "baseline": rollout(lambda o: np.array([0.0, 0.0, -1.0], np.float32), SISO),
            "quad": rollout(varying, QUAD)}


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
