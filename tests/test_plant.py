"""FmuPlant: state copies, save/restore, FMI 2.0 vs 3.0, discards, reset, and bad FMUs."""
import numpy as np
import pytest

from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu import FmuPlant, StepRejected
from conftest import PLANTS, fmu


def _random_inputs(plant, n, seed):
    return np.random.default_rng(seed).uniform(-0.5, 0.5, (n, len(plant.inputs)))


@pytest.mark.parametrize("name", PLANTS)
def test_copy_state_gives_bit_identical_outputs(name, fmi_version):
    path = fmu(name, fmi_version)
    with FmuPlant(path) as plant, FmuPlant(path, instance_name="prior") as prior:
        u = _random_inputs(plant, 1030, 3)
        for uk in u[:30]:
            plant.step(np.abs(uk) if name == "TwoTank" else uk)
        plant.copy_state_to(prior)
        assert prior.time == plant.time
        for uk in u[30:]:
            uk = np.abs(uk) * 40 if name == "TwoTank" else uk
            a, b = plant.step(uk), prior.step(uk)
            assert np.array_equal(a, b)


@pytest.mark.parametrize("name", PLANTS)
def test_saved_state_reproduces_trajectory(name, fmi_version):
    with FmuPlant(fmu(name, fmi_version)) as plant:
        u = np.abs(_random_inputs(plant, 100, 4))
        for uk in u[:20]:
            plant.step(uk)
        saved = plant.get_state()
        first = np.array([plant.step(uk) for uk in u[20:]])
        plant.set_state(saved)
        second = np.array([plant.step(uk) for uk in u[20:]])
    assert np.array_equal(first, second)


@pytest.mark.parametrize("name", PLANTS)
def test_fmi3_build_steps_exactly_like_fmi2(name):
    with FmuPlant(fmu(name, 2)) as p2, FmuPlant(fmu(name, 3)) as p3:
        assert p2.outputs == p3.outputs
        u = np.abs(_random_inputs(p2, 200, 5))
        a = np.array([p2.step(uk) for uk in u])
        b = np.array([p3.step(uk) for uk in u])
    assert np.array_equal(a, b)


def test_reset_in_place_restarts_identically(fmi_version):
    with FmuPlant(fmu("FirstOrderUnstable", fmi_version)) as plant:
        first = [plant.step([0.3])[0] for _ in range(10)]
        assert plant.reset()[0] == 0.0 and plant.time == 0.0
        second = [plant.step([0.3])[0] for _ in range(10)]
        plant.reset(parameters={"x0": 2.0})
        assert plant.read_outputs()[0] == 2.0
    assert first == second


def test_non_finite_state_is_discarded_and_last_good_state_kept(fmi_version):
    with FmuPlant(fmu("FirstOrderUnstable", fmi_version)) as plant:
        y = plant.step([1.0])
        with pytest.raises(StepRejected):
            plant.step([1e308])
        assert np.array_equal(plant.read_outputs(), y)
        assert plant.time == pytest.approx(0.1)
        plant.step([0.0])  # still usable


def test_deserialize_rejects_wrong_size_and_other_model(fmi_version):
    with FmuPlant(fmu("FirstOrderUnstable", fmi_version)) as a, FmuPlant(fmu("QuadrotorAttitude", fmi_version)) as q:
        blob = a.get_state()
        with pytest.raises(PlantError, match="bytes"):
            a.set_state(blob[:-3])
        with pytest.raises(PlantError):
            q.set_state(blob)
        with pytest.raises(PlantError, match="different FMUs"):
            a.copy_state_to(q)


def test_tunable_parameter_change_takes_effect_mid_run(fmi_version):
    with FmuPlant(fmu("FirstOrderUnstable", fmi_version), parameters={"a": -1.0}) as plant:
        for _ in range(100):
            y = plant.step([1.0])
        assert y[0] == pytest.approx(1.0, abs=1e-4)  # 1/(s+1) settles at 1
        plant.set({"b": 2.0})
        for _ in range(150):
            y = plant.step([1.0])
        assert y[0] == pytest.approx(2.0, abs=1e-5)


def test_bad_variable_names_and_files_give_plant_errors(tmp_path):
    path = fmu("TwoTank")
    with pytest.raises(PlantError, match="no variable 'level'"):
        FmuPlant(path, outputs=["level"])
    with pytest.raises(PlantError, match="causality 'output'"):
        FmuPlant(path, inputs=["h2"])
    not_fmu = tmp_path / "plant.fmu"
    not_fmu.write_text("hello")
    with pytest.raises(PlantError, match="not an FMU"):
        FmuPlant(not_fmu)
    with pytest.raises(PlantError, match="not found"):
        FmuPlant(tmp_path / "missing.fmu")
