"""The Python API takes a scenario file path wherever it takes a preset name."""
import gymnasium as gym
import numpy as np

import prlpid_fmi
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.scenario.load import load_scenario


def test_make_env_and_gym_make_take_a_scenario_path():
    path = scenario_path("two_tank")
    expected = load_scenario(path).tuning
    for env in (prlpid_fmi.make_env(str(path)), gym.make("prlpid_fmi/PidTuning-v0", scenario=str(path))):
        config = env.unwrapped.config
        assert config.loops == expected.loops and config.sample_time_s == expected.sample_time_s
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs.astype(env.observation_space.dtype))
        obs, reward, *_ = env.step(env.action_space.sample())
        assert np.isfinite(reward)
        env.close()
