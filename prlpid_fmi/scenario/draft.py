"""Draft a ready-to-edit scenario for an FMU from a step and trim test (prlpid-fmi init)."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Optional

import yaml

from prlpid_fmi.control.pid import ANTI_WINDUP_MODES
from prlpid_fmi.control.smoothing import SMOOTHING_METHODS
from prlpid_fmi.errors import PlantError, ScenarioError
from prlpid_fmi.scenario.load import schema_uri
from prlpid_fmi.schema import ALGORITHMS, default
from prlpid_fmi.schema import model as m


def _probed_loop(fmu_path: str | Path, output: Optional[str], start_values: dict):
    """(the FMU's description, the loop its step and trim test proposes); ScenarioError with one line when the FMU
    cannot be read, cannot be a plant, or cannot be probed."""
    from prlpid_fmi.fmu import describe_fmu
    from prlpid_fmi.probe.proposal import choose_loop, propose_loop
    from prlpid_fmi.probe.open_loop import probe_outputs

    try:
        d = describe_fmu(Path(fmu_path))
    except PlantError as exc:  # its message already names the file
        raise ScenarioError(str(exc)) from None
    problems = d.plant_problems()
    if problems:
        raise ScenarioError(f"{fmu_path}: cannot be a plant: {'; '.join(problems)} "
                            f"(got {d.model_name!r}; expected an FMU with scalar real inputs and outputs)")
    try:
        results = probe_outputs(Path(fmu_path), outputs=[output] if output else None, start_values=start_values)
        if output:
            return d, propose_loop(results[output])
        chosen, why = choose_loop(results)
        return d, propose_loop(chosen, why)
    except PlantError as exc:
        text = str(exc)
        for prefix in (f"{fmu_path}: ", f"{Path(fmu_path)}: "):
            text = text[len(prefix):] if text.startswith(prefix) else text
        raise ScenarioError(f"{fmu_path}: no loop to tune: {text}") from None


def init_scenario(fmu_path: str | Path, output: Optional[str] = None,
                  start_values: Optional[dict] = None) -> str:
    """YAML text of a ready-to-edit scenario for an FMU, from a step and trim test (prlpid_fmi.probe).

    The measured output is `output`, else the one an engineer would pick (probe.proposal.choose_loop: a nonzero
    steady effect; of a position and its rate, the one the identified mechanism calls for); the loop's input is the one that moves it most, never a
    disturbance-like input while another one moves it, never one that acts on/off; u_limits, setpoint range, sample time and gain
    ranges, setpoint hold and episode length come from the probe's identified model and the FMU's declared
    min, max and nominal values, each with a comment saying where it came from. start_values {parameter or input: value}: the operating point to probe at
    (parameters are written to plant.parameters). An FMU that crashed a worker process in this process (init_isolated)
    gets plant.isolation: process, with the crash in its comment. Raises ScenarioError with one line when the FMU cannot
    be read or probed.
    """
    from prlpid_fmi.fmu.worker import crash_seen

    p = Path(fmu_path)
    start_values = dict(start_values or {})
    d, loop = _probed_loop(fmu_path, output, start_values)
    tunable = [v for v in d.parameters if v.variability == "tunable" and v.scalar_real]

    def unit(name):
        u = d.unit_of(name)
        return f" [{u}]" if u else ""

    params = "\n".join(f"  #   {v.name}: {v.start}{'   # ' + v.unit if v.unit else ''}" for v in tunable[:20])
    given = {k: v for k, v in start_values.items() if k not in d.input_names}
    others = "\n".join(f"    #   {line}" for line in loop.others) or "    #   none"
    strategies, agent = m.StrategiesModel(), m.AgentModel()
    n_train = loop.episode_steps
    n_eval = 2 * n_train
    prior_problems = d.prior_problems()
    if prior_problems:
        forecast = (f"forecast_horizon: 0   # this FMU cannot be its own prior ({'; '.join(prior_problems)}); "
                    "give prior.fmu + prior.state_map to use the reward forecast")
    else:
        forecast = f"forecast_horizon: {strategies.forecast_horizon}   # reward forecast over N steps on a copy of the FMU; 0 = off"
    fmu_text = yaml.safe_dump(str(p.resolve()), default_style='"').strip()
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", d.model_name).strip("-") or "my-plant"
    lo, hi = loop.setpoint_range
    sp1, sp2 = (float(f"{lo + f * (hi - lo):.4g}") for f in (0.3, 0.7))
    parameters = "{" + ", ".join(f"{k}: {v!r}" for k, v in given.items()) + "}"
    gains = {g: f"[{a!r}, {b!r}, {s}]" for g, (a, b, s) in loop.gains.items()}
    w = loop.why
    crash = crash_seen([p])
    isolation = (f"\n  isolation: process   # {crash}: the plant runs in a worker process of its own (auto | process | "
                 "none)" if crash else "")
    return f"""\
# yaml-language-server: $schema={schema_uri()}
# Scenario for {d.model_name} ({p.name}), written by `prlpid-fmi init` from an open-loop step and trim test
# (`prlpid-fmi probe` shows it with a plot). Check it with `prlpid-fmi validate <this file>`.
# Every key, unit and default: docs/scenarios.md. Lines marked ADJUST need your plant's numbers.
name: {name}
plant:
  fmu: {fmu_text}   # a relative path resolves against this file's folder
  sample_time: {loop.sample_time_s!r}   # s, control period: {w['sample_time']}
  parameters: {parameters}   # {{FMU parameter: value}} set before each episode{isolation}
  # tunable parameters of this FMU (start values):
{params or '  #   none'}
  loops:
    # inputs not chosen (each held at its start value; a disturbance can be stepped in training.disturbances):
{others}
    - input: {loop.input}   # FMU input the PID drives{unit(loop.input)}: {w['input']}
      output: {loop.output}   # FMU output it measures{unit(loop.output)}{': ' + w['output'] if 'output' in w else ''}
      u_limits: [{loop.u_limits[0]!r}, {loop.u_limits[1]!r}]   # actuator saturation{unit(loop.input)}: {w['u_limits']}
      setpoint_range: [{lo!r}, {hi!r}]   # training setpoints{unit(loop.output)}: {w['setpoint_range']}
      measurement_scale: {loop.measurement_scale!r}   # typical setpoint step{unit(loop.output)}: half the setpoint range
      divergence_bound: 10.0   # |error| / measurement_scale that ends an episode as diverged
      gains:   # ranges the agent's actions map into: {w['gains']}
        Kp: {gains['Kp']}
        Ti: {gains['Ti']}   # s
        Td: {gains['Td']}   # s
controller:
  anti_windup: {default(m.ControllerModel, 'anti_windup')}   # {' | '.join(ANTI_WINDUP_MODES)}
strategies:
  {forecast}
  smoothing: {strategies.smoothing}   # {' | '.join(SMOOTHING_METHODS)}
agent:
  algorithm: {agent.algorithm}   # {' | '.join(ALGORITHMS)}
  total_timesteps: {agent.total_timesteps}
  seed: {agent.seed}
training:
  episode_steps: {n_train}   # two setpoint holds at least [samples]
  setpoint_hold_steps: {loop.hold_steps}   # samples between random setpoint changes: {w['hold']}
evaluation:
  episode_steps: {n_eval}
  setpoints:   # value: a number (one loop) or a list with one number per loop
    - {{at_step: 0, value: {sp1!r}}}
    - {{at_step: {n_eval // 2}, value: {sp2!r}}}
  intervals: [[0, {n_eval // 2}], [{n_eval // 2}, {n_eval}]]
"""


def init_isolated(fmu: str | Path, step_timeout_s: float | None = None, **kwargs) -> str:
    """init_scenario(fmu, **kwargs) in a worker process (fmu.isolate.run_isolated): the scenario's text; after a
    crash, init again with each FMU run in a worker (its scenario isolates the plant); a hang, garbage outputs or a
    probe that the crash leaves too short are one line (PlantError), and the FMU's stdout never reaches the text."""
    from prlpid_fmi.fmu.isolate import run_isolated

    return run_isolated(init_scenario, fmu, "init (the probe of the FMU)", step_timeout_s, **kwargs)
