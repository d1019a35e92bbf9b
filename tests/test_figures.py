"""run.figures: the load-step figure replays exactly the design's load experiment (its load IAE recomputed by hand
from the recorded episodes)."""
import numpy as np
import pytest

from prlpid_fmi.loop.evaluation import constant_gains, gains_rollout
from prlpid_fmi.loop.gains import gains_from_values
from prlpid_fmi.report.plots import load_step_figure
from prlpid_fmi.run.figures import load_responses
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.tuning.load_experiment import load_experiment


def test_the_load_steps_drawn_are_the_load_experiments():
    scenario = load_scenario(scenario_path("first_order"))
    gains = gains_from_values([8.0], [0.25], [0.001])
    fn = constant_gains(*gains.values())

    def run(cfg):
        return gains_rollout(fn, cfg, seed=0)

    runs = load_responses(scenario, {"fixed PID": run})
    config = scenario.tuning
    ts, hold = config.sample_time_s, config.setpoint_hold_steps
    (found,) = runs.values()
    assert [r.point for r in found] == [[-1.0], [0.0], [1.0]]
    iae = []
    for r in found:
        assert r.hold_steps == hold and abs(r.loads[0]) == pytest.approx(0.1 * 20.0)  # 10 % of the span [-10, 10]
        dev = r.loaded.measurement[hold:, 0] - r.unloaded.measurement[hold:, 0]
        assert np.allclose(r.loaded.measurement[:hold, 0], r.unloaded.measurement[:hold, 0])  # the load acts at hold
        iae.append(np.sum(np.abs(dev)) * ts / abs(r.loads[0]))
    assert np.mean(iae) == pytest.approx(load_experiment(config, scenario.baseline.load_step, run), rel=1e-9)
    fig = load_step_figure(runs, config, "t", deployed="fixed PID")
    titles = [ax.get_title() for ax in fig.axes[:3]]
    assert titles[0] == f"setpoint y = -1\nload {found[0].loads[0]:+.3g} on u" and titles[1].startswith("setpoint y = 0\n")
    assert fig.axes[-1].get_xlabel() == "time since the load step [s]"
