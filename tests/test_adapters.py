"""FMI 2.0 model-exchange-only and FMI 1.0 co-simulation FMUs as plants (and, where they can, priors).

Both are builds of the bundled plants (prlpid_fmi.fmu.build: interface="model-exchange", fmi_version=1), so
the co-simulation build of the same C model is the reference: FMI 1.0 runs the same RK4 code (equal to the
last bit), model exchange is integrated by FMPy's CVode (equal within its tolerance), and both follow the
analytic step response of dx/dt = a x + b u.
"""
import dataclasses
import zipfile

import numpy as np
import pytest
import yaml

from prlpid_fmi.cli import main
from prlpid_fmi.loop.evaluation import evaluate, model_policy
from prlpid_fmi.fmu import FmuPlant, describe_fmu
from prlpid_fmi.fmu.build import bundled_fmu
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.tuning.agent import train
from test_cli import _small_copy


@pytest.fixture(scope="module")
def me_fmu():
    return bundled_fmu("FirstOrderUnstable", 2, interface="model-exchange")


@pytest.fixture(scope="module")
def fmi1_fmu():
    return bundled_fmu("FirstOrderUnstable", 1)


def _inputs(n):
    return 1.0 + 0.5 * np.sin(0.3 * np.arange(n))  # a varying input: the steps are not all alike


def _run(path, u, **kw):
    with FmuPlant(path, inputs=["u"], outputs=["y"], sample_time_s=0.1, parameters={"a": -1.0}, **kw) as plant:
        return np.array([plant.step([v])[0] for v in u])


def test_builds_declare_their_interface(me_fmu, fmi1_fmu):
    me, f1 = describe_fmu(me_fmu), describe_fmu(fmi1_fmu)
    assert (me.fmi_version, me.model_exchange, me.co_simulation, me.n_states) == ("2.0", True, False, 1)
    assert me.can_get_and_set_state and me.can_serialize_state
    assert (f1.fmi_version, f1.co_simulation, f1.can_get_and_set_state) == ("1.0", True, False)
    with zipfile.ZipFile(fmi1_fmu) as zf:
        assert 'fmiVersion="1.0"' in zf.read("modelDescription.xml").decode()


def test_fmi1_steps_exactly_like_the_fmi2_build(fmi1_fmu):
    u = _inputs(60)
    assert np.array_equal(_run(fmi1_fmu, u), _run(bundled_fmu("FirstOrderUnstable"), u))


def test_model_exchange_follows_the_analytic_response(me_fmu):
    # dx/dt = -x + 1 from 0: x(t) = 1 - exp(-t); the CS build (RK4) is the reference for a varying input
    y = _run(me_fmu, np.ones(30))
    t = 0.1 * np.arange(1, 31)
    assert np.max(np.abs(y - (1 - np.exp(-t)))) < 1e-6
    u = _inputs(60)
    assert np.max(np.abs(_run(me_fmu, u) - _run(bundled_fmu("FirstOrderUnstable"), u))) < 1e-6


def test_model_exchange_state_copy_and_reset(me_fmu):
    plant = FmuPlant(me_fmu, inputs=["u"], outputs=["y"], sample_time_s=0.1, instance_name="plant")
    prior = FmuPlant(me_fmu, inputs=["u"], outputs=["y"], sample_time_s=0.1, instance_name="prior")
    first = [plant.step([0.5])[0] for _ in range(10)]
    plant.copy_state_to(prior)
    assert prior.time == pytest.approx(1.0)
    ahead = [plant.step([-2.0])[0] for _ in range(5)]
    assert [prior.step([-2.0])[0] for _ in range(5)] == pytest.approx(ahead, abs=1e-9)
    plant.reset()
    assert [plant.step([0.5])[0] for _ in range(10)] == pytest.approx(first, abs=1e-9)
    # unstable a = 1: x(t) = 0.5 (e^t - 1)
    assert first[-1] == pytest.approx(0.5 * (np.e - 1), rel=1e-5)  # CVode, relative tolerance 1e-8 per step
    plant.close(), prior.close()


def test_fmi1_cannot_be_its_own_prior_one_line(fmi1_fmu, tmp_path, capsys):
    doc = yaml.safe_load(scenario_path("first_order").read_text())
    doc["plant"]["fmu"] = str(fmi1_fmu)
    path = tmp_path / "fmi1.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "strategies.forecast_horizon" in err[0] and "canGetAndSetFMUstate" in err[0]


def test_fmi1_co_simulation_tunes_end_to_end(fmi1_fmu, tmp_path, capsys):
    doc = yaml.safe_load(scenario_path("first_order").read_text())
    doc["plant"]["fmu"] = str(fmi1_fmu)
    doc["strategies"]["forecast_horizon"] = 0
    src = tmp_path / "src.yaml"
    src.write_text(yaml.safe_dump(doc))
    scenario = _small_copy(src, tmp_path / "fmi1.yaml")
    run = tmp_path / "run"
    assert main(["tune", str(scenario), "--timesteps", "256", "--out", str(run), "--no-progress"]) == 0
    assert (run / "model.zip").is_file() and (run / "report.md").is_file() and (run / "gains.csv").is_file()


def test_model_exchange_plant_and_prior_train_and_evaluate(me_fmu, tmp_path):
    """Training with the reward forecast on a model-exchange prior (state copied in each step), then an
    evaluation on the model-exchange plant: the tuning path end to end, on a tiny budget (the CLI's
    margin assessment multiplies the ~0.1 ms CVode step by 10^5 plant steps)."""
    doc = yaml.safe_load(scenario_path("first_order").read_text())
    doc["plant"]["fmu"] = str(me_fmu)
    path = tmp_path / "me.yaml"
    path.write_text(yaml.safe_dump(doc))
    s = load_scenario(path)
    assert s.tuning.forecast_horizon == 3
    agent = dataclasses.replace(s.agent, total_timesteps=256, n_envs=1, n_steps=128, batch_size=64,
                                checkpoint_every=128)
    model = train(s.tuning, agent, tmp_path / "run")
    metrics, trajectory = evaluate(model_policy(model), s.evaluation_config())
    assert np.isfinite(metrics["overall"]["IAE"])
    assert len(trajectory["measurement"]) == s.evaluation.episode_steps + 1  # with the initial measurement
    assert (tmp_path / "run" / "model.zip").is_file()
