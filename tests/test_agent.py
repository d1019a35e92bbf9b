"""Short training runs within CI's budget: learning happens, runs are reproducible, checkpoints are kept."""
import dataclasses

import numpy as np
import pytest

from prlpid_fmi.config import AgentConfig
from prlpid_fmi.loop.evaluation import evaluate, model_policy
from prlpid_fmi.scenario.presets import preset
from prlpid_fmi.tuning.agent import build_model, make_vec_env, train

# the paper's PRL-PID: eq. 2 (b = c = 1, no filter, positional gain change) and its episodes (no random load steps)
CONFIG = dataclasses.replace(preset("first_order"), forecast_horizon=3, smoothing="era", setpoint_weight=1.0,
                             derivative_weight=1.0, measurement_filter=0.0, load_disturbance=0.0,
                             gain_change="positional")
SERVO = dataclasses.replace(CONFIG, setpoint_schedule=((0, (1.0,)), (100, (-0.5,))), episode_steps=200)


def test_short_prl_pid_training_beats_the_untrained_policy(tmp_path):
    agent = AgentConfig(total_timesteps=40_960, seed=0)
    untrained = build_model(agent, make_vec_env(CONFIG, agent))
    before, _ = evaluate(model_policy(untrained), SERVO)
    model = train(CONFIG, agent, tmp_path / "run")
    after, traj = evaluate(model_policy(model), SERVO)
    assert not after["terminated"]
    assert after["overall"]["ISE"] < 0.8 * before["overall"]["ISE"]
    assert (tmp_path / "run" / "model.zip").is_file()
    assert list((tmp_path / "run" / "tensorboard").rglob("events.out.tfevents*"))
    assert list((tmp_path / "run" / "monitor").glob("*.monitor.csv"))


def _params(model):
    return np.concatenate([p.detach().numpy().ravel() for p in model.policy.parameters()])


def test_same_seed_same_policy_and_checkpoints(tmp_path):
    agent = AgentConfig(total_timesteps=2048, n_envs=1, n_steps=512, seed=7, checkpoint_every=1024)
    a = train(CONFIG, agent, tmp_path / "a")
    b = train(CONFIG, agent, tmp_path / "b")
    c = train(CONFIG, dataclasses.replace(agent, seed=8), tmp_path / "c")
    assert np.array_equal(_params(a), _params(b))
    assert not np.array_equal(_params(a), _params(c))
    assert sorted(p.name for p in (tmp_path / "a" / "checkpoints").glob("*.zip")) == \
        ["model_1024_steps.zip", "model_2048_steps.zip"]


def test_resume_continues_from_a_checkpoint(tmp_path):
    agent = AgentConfig(total_timesteps=1024, n_envs=1, n_steps=512, seed=1, checkpoint_every=512)
    train(CONFIG, agent, tmp_path / "run")
    model = train(CONFIG, agent, tmp_path / "run", resume_from=tmp_path / "run" / "checkpoints" / "model_1024_steps.zip",
                  total_timesteps=1024)
    assert model.num_timesteps == 2048


@pytest.mark.parametrize("algorithm", ["sac", "td3"])
def test_baseline_algorithms_train_on_the_same_env(tmp_path, algorithm):
    agent = AgentConfig(algorithm=algorithm, total_timesteps=300, learning_starts=100, batch_size=64, seed=0)
    model = train(CONFIG, agent, tmp_path / algorithm)
    assert model.num_timesteps == 300


def test_subprocess_vector_env_and_vecnormalize(tmp_path):
    agent = AgentConfig(total_timesteps=1024, n_steps=256, n_envs=2, vec_env="subproc", normalize=True, seed=3)
    model = train(CONFIG, agent, tmp_path / "run")
    assert model.num_timesteps == 1024
    assert (tmp_path / "run" / "vecnormalize.pkl").is_file()


def test_resume_with_vecnormalize_takes_the_checkpoints_own_statistics(tmp_path):
    """Resuming from checkpoint k loads the running mean saved at step k, not the final vecnormalize.pkl."""
    from stable_baselines3.common.vec_env import VecNormalize

    agent = AgentConfig(total_timesteps=1024, n_envs=1, n_steps=256, normalize=True, seed=2, checkpoint_every=512)
    run = tmp_path / "run"
    train(CONFIG, agent, run)
    at_512 = run / "checkpoints" / "model_vecnormalize_512_steps.pkl"
    saved = VecNormalize.load(str(at_512), make_vec_env(CONFIG, agent)).obs_rms.mean
    final = VecNormalize.load(str(run / "vecnormalize.pkl"), make_vec_env(CONFIG, agent)).obs_rms.mean
    assert not np.allclose(saved, final)  # the two statistics differ, so the check below can fail
    model = train(CONFIG, agent, run, resume_from=run / "checkpoints" / "model_512_steps.zip", total_timesteps=256)
    # 256 more steps counted on top of the checkpoint's 512 (+ a few reset observations), not on the final 1024
    resumed = model.get_vec_normalize_env().obs_rms
    assert resumed.count == pytest.approx(512 + 256, abs=8)


def test_torch_threads_above_the_cores_are_lowered_with_a_warning():
    """agent.torch_threads: 100000 once made torch start 10**5 threads; the FMU's library then failed to map."""
    import os
    import warnings

    from prlpid_fmi.tuning.agent import torch_threads

    cores = os.cpu_count()
    with pytest.warns(UserWarning, match=f"agent.torch_threads: 100000 is more than this machine's {cores} cores"):
        assert torch_threads(100_000) == cores
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert torch_threads(1) == 1 and torch_threads(cores) == cores


@pytest.mark.parametrize("algorithm, failure, expected", [
    ("ppo", RuntimeError("[enforce fail at alloc_cpu.cpp:127] err == 0. DefaultCPUAllocator: can't allocate memory: "
                         "you tried to allocate 40000000000 bytes. Error code 12 (Cannot allocate memory)"),
     "agent: the PPO model does not fit in this machine's memory (agent.net_arch [64, 64]: one tensor of 40 GB "
     "could not be allocated; expected smaller hidden layers)"),
    ("sac", MemoryError("Unable to allocate 14.6 TiB for an array with shape (1000000000000, 1, 4)"),
     "agent: the SAC model does not fit in this machine's memory (agent.net_arch [64, 64], agent.buffer_size "
     "200000: Unable to allocate 14.6 TiB for an array with shape (1000000000000, 1, 4); expected smaller hidden "
     "layers or replay buffer)")])
def test_a_model_too_large_for_memory_is_one_error_not_a_traceback(algorithm, failure, expected, tmp_path,
                                                                  monkeypatch):
    """net_arch [100000, 100000] once ended in torch's allocator traceback (40 GB for one weight matrix). The
    allocation failure is simulated: a real one would depend on the machine's memory and overcommit policy."""
    import prlpid_fmi.tuning.agent as train_module
    from prlpid_fmi.errors import RunError

    def fail(*args, **kwargs):
        raise failure

    monkeypatch.setattr(train_module, "build_model", fail)
    agent = AgentConfig(algorithm=algorithm, total_timesteps=64, n_envs=1)
    with pytest.raises(RunError) as info:
        train(CONFIG, agent, tmp_path / "run")
    assert str(info.value) == expected


def test_a_runtime_error_that_is_not_about_memory_is_not_relabelled(tmp_path, monkeypatch):
    import prlpid_fmi.tuning.agent as train_module

    def fail(*args, **kwargs):
        raise RuntimeError("mat1 and mat2 shapes cannot be multiplied")

    monkeypatch.setattr(train_module, "build_model", fail)
    with pytest.raises(RuntimeError, match="shapes cannot be multiplied"):
        train(CONFIG, AgentConfig(total_timesteps=64, n_envs=1), tmp_path / "run")


def test_the_largest_allowed_seed_with_every_offset_still_seeds_numpy_and_sb3():
    """MAX_SEED's reason, checked against the libraries: SB3's set_random_seed calls numpy's legacy seeding,
    which refuses 2**32; the largest seed plus the largest per-episode offset and per-env index stays below."""
    import numpy as np
    from stable_baselines3.common.utils import set_random_seed

    from prlpid_fmi.schema.types import MAX_SEED
    from prlpid_fmi.deliver.evidence import HOLDOUT_SEED_OFFSET

    set_random_seed(MAX_SEED + HOLDOUT_SEED_OFFSET + 1000)  # must not raise
    with pytest.raises(ValueError):
        np.random.seed(2**32)
