"""The engineer's figures of a finished `tune`: what they show and the data they are drawn from.

- step_response.png: the evaluation zoomed to its transients (report.plots.step_response_figure), from the
  evaluation's trajectories (adaptive policy, fixed PID, adaptive schedule) and a replay of the classical schedule
  on the same evaluation where one was built (one episode).
- load_steps.png: the fixed-PID design's load experiment (tuning.load_experiment.load_experiment: a load step at the
  plant input at the low end, middle and high end of the setpoint range) replayed with every plain PID (fixed PID,
  classical and adaptive schedules where they exist): two short episodes per point and controller.
- schedule_gains.png: Kp, Ti, Td of the gain tables over their scheduling variable, beside the fixed PID.
- frequency/: per loop, the frequency responses the margin experiments measured (deliver.rule.Candidate's margins;
  no new experiment) as <loop>.csv (the Monte-Carlo parameter draws' too, with training.randomize), and the nominal
  plant's Nyquist, |S| and |T|, and Bode figures (report.frequency).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from prlpid_fmi import rundir as rd
from prlpid_fmi.fmu.resolve import loop_units
from prlpid_fmi.loop.evaluation import constant_gains, gains_rollout
from prlpid_fmi.report import frequency, plots
from prlpid_fmi.robustness.margins import setpoint_range_points
from prlpid_fmi.tuning.load_experiment import load_experiment
from prlpid_fmi.tuning.schedule.replay import replay_schedule


@dataclass
class RunFigures:
    """The figure files a run wrote (names relative to the run directory; None / empty where not drawn).
    frequency: {loop: {kind: path}} with kind csv, nyquist, sensitivity, bode (report.frequency)."""

    step_response: str | None = None
    load_steps: str | None = None
    schedule_gains: str | None = None
    frequency: dict = field(default_factory=dict)


def _runner(gains=None, table=None):
    """run(config) -> Trajectory of a fixed PID (loop.gains.Gains) or a replayed gain table, as deliver.evidence
    runs them in the load experiment."""
    if table is not None:
        return lambda cfg: replay_schedule(table, cfg, seed=0)[1]
    fn = constant_gains(*gains.values())
    return lambda cfg: gains_rollout(fn, cfg, seed=0)


def load_responses(scenario, controllers: dict) -> dict:
    """{name: [report.plots.LoadResponse per operating point]}: tuning.load_experiment.load_experiment of each controller
    in controllers {name: run(config) -> Trajectory}, every episode it runs kept (per point: the unloaded run,
    then the loaded one)."""
    config = scenario.tuning
    points = setpoint_range_points(config)
    out = {}
    for name, run in controllers.items():
        episodes = []

        def recorded(cfg, run=run, episodes=episodes):
            traj = run(cfg)
            episodes.append((cfg, traj))
            return traj

        load_experiment(config, scenario.baseline.load_step, recorded)
        out[name] = [_load_response(points[j], episodes[2 * j], episodes[2 * j + 1]) for j in range(len(points))]
    return out


def _load_response(point, unloaded: tuple, loaded: tuple) -> plots.LoadResponse:
    """A report.plots.LoadResponse from load_experiment's (config, Trajectory) of one point's two episodes."""
    cfg = loaded[0]
    return plots.LoadResponse(point, [d.value for d in cfg.disturbances], loaded[1], unloaded[1],
                              cfg.setpoint_hold_steps)


def write_run_figures(run_dir: Path, scenario, ev, choice, fixed_gains, adaptive=None, classical=None) -> RunFigures:
    """Every figure of the module docstring into run_dir. ev: run.evaluate.Evaluation; choice: run.tune.Choice (its
    Candidates carry the margins; None: no frequency figures); fixed_gains: loop.gains.Gains; adaptive, classical:
    the gain tables (tuning.schedule.table.GainSchedule) where built."""
    deployed = str(choice.decision.deploy) if choice is not None else None
    config = ev.config
    figures = RunFigures()
    pairs = [(plots.POLICY, ev.policy_traj), (plots.FIXED, ev.fixed_traj)]
    if classical is not None:
        pairs.append((plots.CLASSICAL, replay_schedule(classical, config, seed=scenario.evaluation.seed)[1]))
    pairs.append((plots.SCHEDULE, ev.schedule_traj))
    pairs = [(name, traj) for name, traj in pairs if traj is not None]
    plots.save_figure(plots.step_response_figure(pairs, config, f"{scenario.name}: transients", deployed),
                      run_dir / rd.STEP_RESPONSE_PLOT)
    figures.step_response = rd.STEP_RESPONSE_PLOT

    controllers = {plots.FIXED: _runner(gains=fixed_gains)}
    if classical is not None:
        controllers[plots.CLASSICAL] = _runner(table=classical)
    if adaptive is not None:
        controllers[plots.SCHEDULE] = _runner(table=adaptive)
    load_config = dataclasses.replace(scenario.tuning, forecast_horizon=0)
    plots.save_figure(plots.load_step_figure(load_responses(scenario, controllers), load_config,
                                             f"{scenario.name}: load steps at the plant input "
                                             f"({scenario.baseline.load_step:.0%} of the control span), the fixed-PID "
                                             "design's experiment", deployed),
                      run_dir / rd.LOAD_STEPS_PLOT)
    figures.load_steps = rd.LOAD_STEPS_PLOT

    tables = [(name, t) for name, t in ((plots.CLASSICAL, classical), (plots.SCHEDULE, adaptive))
              if t is not None and len(t.breakpoints) > 1]
    if tables:
        plots.save_figure(plots.schedule_gains_figure(tables, scenario.tuning, fixed_gains, deployed,
                                                      f"{scenario.name}: PID gains over the scheduling variable"),
                          run_dir / rd.SCHEDULE_GAINS_PLOT)
        figures.schedule_gains = rd.SCHEDULE_GAINS_PLOT

    if choice is not None:
        names = [l.output for l in scenario.tuning.loops]
        responses = frequency.loop_responses((choice.fixed, choice.classical, choice.schedule), names,
                                             scenario.tuning.sample_time_s, draws=True)
        ys, us = loop_units(scenario.tuning)
        written = frequency.write_frequency_files(run_dir / rd.FREQUENCY, responses, names, list(zip(ys, us)),
                                                  float(scenario.deploy.max_sensitivity), deployed)
        figures.frequency = {loop: {kind: f"{rd.FREQUENCY}/{name}" for kind, name in files.items()}
                             for loop, files in written.items()}
    return figures
