"""PidTuningEnv against hand-written replays of the paper's equations and against invariants.

Truths used here do not come from the code under test:
- the gym API contract (gymnasium's env checker);
- "the forecast never moves the plant": trajectories with and without the forecast are bit-identical;
- eq. 2 (positional PID), eq. 10-11 (hierarchical reward) and eq. 12-14 (reward forecast) written
  out again below, driving a third, independent FMU instance of the same plant;
- the action -> gain mapping as documented in actions.py, re-derived here;
- closed-loop stability of G(s) = 1/(s - 1) under PI control: s^2 + (Kp - 1) s + Kp/Ti is unstable
  for Kp < 1 and stable for Kp = 18, Ti = 2;
- physics: removing inflow from tank 1 lowers the level of tank 2.
"""
from __future__ import annotations

import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import prlpid_fmi
from prlpid_fmi.config import Disturbance, PriorConfig
from prlpid_fmi.fmu import FmuPlant
from prlpid_fmi.scenario.presets import PRESET_NAMES

ENV_ID = "prlpid_fmi/PidTuning-v0"
ALL_PRESETS = ("first_order", "second_order", "first_order_1p5", "time_varying", "two_tank", "quadrotor")

# Default RewardWeights of the project, written out as literals (eq. 10-11 and its documented defaults,
# and the control-variation weight, docs/architecture.md "Control-variation penalty").
ALPHA, BETA, V_CLIP, E_CLIP = 1.0, 1.0, 0.5, 1.0
BONUS_THRESHOLD, BONUS_NUMERATOR, BONUS_OFFSET = 0.05, 0.1, 0.05
CONTROL_VARIATION_WEIGHT = 0.3


# -- independent re-implementations ------------------------------------------------------------
def hand_reward(error, previous_error, u, u_prev, u_span) -> float:
    """Eq. 10-11 per loop on normalised errors, minus the control-variation term
    w * min(|u - u_prev| / u_span, 1) (u_span = u_max - u_min), averaged over loops."""
    total = 0.0
    for e, e_prev, uk, uk_prev, span in zip(*(np.atleast_1d(x) for x in (error, previous_error, u, u_prev, u_span))):
        V, V_prev = e * e / 2.0, e_prev * e_prev / 2.0
        r = -max(V - V_prev, 0.0) - ALPHA * min(V, V_CLIP) - BETA * min(abs(e), E_CLIP)
        if abs(e) < BONUS_THRESHOLD:
            r += BONUS_NUMERATOR / (abs(e) + BONUS_OFFSET)
        r -= CONTROL_VARIATION_WEIGHT * min(abs(uk - uk_prev) / span, 1.0)
        total += r
    return total / len(np.atleast_1d(error))


def hand_gain(a: float, low: float, high: float, scale: str) -> float:
    """Documented action mapping: a in [-1, 1] -> geometric ("log") or affine ("linear") in [low, high]."""
    frac = (a + 1.0) / 2.0
    if scale == "log":
        return math.exp(math.log(low) + frac * (math.log(high) - math.log(low)))
    return low + frac * (high - low)


def hand_gains(config, action) -> list[tuple[float, float, float]]:
    out = []
    for i, loop in enumerate(config.loops):
        a = [float(x) for x in action[3 * i: 3 * i + 3]]
        out.append((hand_gain(a[0], loop.Kp.low, loop.Kp.high, loop.Kp.scale),
                    hand_gain(a[1], loop.Ti.low, loop.Ti.high, loop.Ti.scale),
                    hand_gain(a[2], loop.Td.low, loop.Td.high, loop.Td.scale)))
    return out


def action_for(loop, Kp: float, Ti: float, Td: float) -> list[float]:
    """Inverse of the documented mapping (log ranges for Kp, Ti; linear for Td)."""
    def inv_log(v, r):
        return 2.0 * math.log(v / r.low) / math.log(r.high / r.low) - 1.0
    return [inv_log(Kp, loop.Kp), inv_log(Ti, loop.Ti), 2.0 * (Td - loop.Td.low) / (loop.Td.high - loop.Td.low) - 1.0]


class HandPID:
    """Eq. 2, one loop, positional: I(k) = I(k-1) + e(k) dt, u = Kp (e + I/Ti + Td (e - e_prev)/dt),
    saturated at [u_min, u_max], with conditional-integration (clamping) anti-windup: when u is
    saturated and Kp*e pushes further into the limit, e*dt is not added to I."""

    def __init__(self, dt, u_min, u_max, integral, last_error):
        self.dt, self.u_min, self.u_max = dt, u_min, u_max
        self.I, self.e_prev = integral, last_error

    def step(self, e, Kp, Ti, Td):
        dt = self.dt
        I_try = self.I + e * dt
        u_try = Kp * (e + I_try / Ti + Td * (e - self.e_prev) / dt)
        u = min(max(u_try, self.u_min), self.u_max)
        if u != u_try and (u_try - u) * (Kp * e) > 0:
            I_try = self.I
        self.I, self.e_prev = I_try, e
        return u


# -- helpers -----------------------------------------------------------------------------------
def run(env, actions, seed):
    """Step through `actions` (resetting after a termination); return the recorded trajectory."""
    obs, info = env.reset(seed=seed)
    rec = {"obs": [obs], "measurement": [info["measurement"]], "control_signal": [], "setpoint": [info["setpoint"]],
           "terminated": []}
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        rec["obs"].append(obs)
        rec["measurement"].append(info["measurement"])
        rec["control_signal"].append(info["control_signal"])
        rec["setpoint"].append(info["setpoint"])
        rec["terminated"].append(terminated)
        if terminated or truncated:
            obs, info = env.reset()
            rec["obs"].append(obs)
            rec["measurement"].append(info["measurement"])
    return {k: np.array(v) for k, v in rec.items()}


def random_actions(env, n, seed=1):
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n, env.action_space.shape[0])).astype(np.float32)


# -- 1. gym API ----------------------------------------------------------------------------------
def test_all_paper_presets_exist():
    assert set(ALL_PRESETS) <= set(PRESET_NAMES)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_check_env_through_gymnasium_make(name):
    env = gymnasium.make(ENV_ID, config=name)
    try:
        n = len(prlpid_fmi.scenario.presets.preset(name).loops)
        coupled = prlpid_fmi.scenario.presets.preset(name).coupled
        assert coupled == (name == "quadrotor") or name not in ALL_PRESETS
        assert env.action_space.shape == (3 * n + (6 if coupled else 0),)
        assert env.observation_space.shape == (4 * n,)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # the checker's advisories (dtype, bounds, determinism) fail too
            check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()


@pytest.mark.parametrize("name", ["first_order", "quadrotor"])
def test_check_env_make_env(name):
    env = prlpid_fmi.make_env(name, forecast_horizon=5, smoothing="sma")
    try:
        assert env.config.forecast_horizon == 5 and env.config.smoothing == "sma"
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(env, skip_render_check=True)
    finally:
        env.close()


def test_gymnasium_make_passes_overrides():
    env = gymnasium.make(ENV_ID, config="two_tank", forecast_horizon=0, episode_steps=7)
    try:
        assert env.unwrapped.forecast is None and env.unwrapped.prior is None
        env.reset(seed=0)
        for k in range(7):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            assert truncated == (k == 6) and not terminated
    finally:
        env.close()


# -- 2. the forecast never moves the plant -------------------------------------------------------
@pytest.mark.parametrize("name", ["first_order", "two_tank", "quadrotor"])
def test_plant_trajectory_does_not_depend_on_the_forecast(name):
    n_steps = 150
    runs = {}
    for horizon in (0, 1, 3, 10):
        env = prlpid_fmi.make_env(name, forecast_horizon=horizon)
        assert (env.forecast is None) == (horizon == 0)
        runs[horizon] = run(env, random_actions(env, n_steps), seed=11)
        env.close()
    ref = runs[0]
    assert ref["control_signal"].shape == (n_steps, len(prlpid_fmi.scenario.presets.preset(name).loops))
    # the run is not trivial: the plant moved and the control signal varied
    assert np.ptp(ref["measurement"]) > 0 and np.ptp(ref["control_signal"]) > 0
    for horizon in (1, 3, 10):
        for key in ("measurement", "control_signal", "setpoint", "obs", "terminated"):
            assert np.array_equal(runs[horizon][key], ref[key]), (name, horizon, key)


@pytest.mark.parametrize("name", ["first_order", "two_tank", "quadrotor"])
def test_forecast_call_leaves_plant_and_pid_untouched(name):
    N = 10
    env = prlpid_fmi.make_env(name, forecast_horizon=N)
    env.reset(seed=4)
    for a in random_actions(env, 20, seed=2):
        env.step(a)
    action = random_actions(env, 1, seed=3)[0]
    gains = env.action_map(np.asarray(action, float))
    r, y = env.setpoint.copy(), env.measurement.copy()
    coupling = gains.coupling.tolist() if env.config.coupled else None

    plant_state, plant_time, plant_out = env.plant.get_state(), env.plant.time, env.plant.read_outputs()
    pid_state = env.pid.get_state()
    env.plant.copy_state_to(env.prior)
    assert env.prior.time == plant_time
    reward = env.forecast.mean_reward(r.tolist(), y.tolist(), gains.Kp.tolist(), gains.Ti.tolist(), gains.Td.tolist(),
                                      coupling, env.core.pid_output)

    assert env.plant.get_state() == plant_state  # byte-identical
    assert env.plant.time == plant_time
    assert np.array_equal(env.plant.read_outputs(), plant_out)
    after = env.pid.get_state()
    assert np.array_equal(after.integral, pid_state.integral)
    assert np.array_equal(after.last_error, pid_state.last_error)
    assert np.array_equal(after.derivative, pid_state.derivative)
    assert after.initialized == pid_state.initialized
    # ... while the prior really was rolled N steps ahead
    assert np.isfinite(reward)
    assert len(env.forecast.last_rewards) == N
    assert env.prior.time == pytest.approx(plant_time + N * env.config.sample_time_s, abs=1e-9)
    assert env.prior.get_state() != plant_state
    env.close()


# -- 3. the forecast reward against a hand replay (eq. 2, 10-14) ----------------------------------
REPLAY_CASES = {
    # preset, overrides, setpoint schedule
    "first_order": ({}, ((0, (0.5,)), (30, (-0.3,)))),
    "two_tank": ({"measurement_noise_std": 0.0, "actuator_noise_std": 0.0}, ((0, (10.0,)), (30, (12.0,)))),
}


@pytest.mark.parametrize("horizon", [3, 7])
@pytest.mark.parametrize("name", list(REPLAY_CASES))
def test_forecast_reward_equals_hand_replay(name, horizon):
    overrides, schedule = REPLAY_CASES[name]
    # the paper's law (b = c = 1, no filter, positional gain change: eq. 2, what HandPID computes)
    env = prlpid_fmi.make_env(name, forecast_horizon=horizon, smoothing="none", setpoint_schedule=schedule,
                              setpoint_weight=1.0, derivative_weight=1.0, measurement_filter=0.0,
                              gain_change="positional", **overrides)
    c = env.config
    assert c.n_loops == 1 and not c.disturbances
    loop = c.loops[0]
    dt, scale, bound = c.sample_time_s, loop.measurement_scale, loop.divergence_bound
    third = FmuPlant(env.plant.path, [loop.input], [loop.output], dt, dict(c.plant_parameters))
    assert third.path == env.plant.path and third is not env.plant and third is not env.prior

    actions = random_actions(env, 60, seed=7)
    _, info = env.reset(seed=5)
    y = float(info["measurement"][0])
    u_span = loop.u_max - loop.u_min  # control_scale is not set in these scenarios
    # the PID output of the sample before: at the start, the plant's input start value, clipped
    u_before = min(max(float(c.plant_parameters.get(loop.input, 0.0)), loop.u_min), loop.u_max)
    n_replayed, n_bonus, n_saturated, n_moved = 0, 0, 0, 0
    for k, action in enumerate(actions):
        blob, pid_state = env.plant.get_state(), env.pid.get_state()
        r = schedule[0][1][0] if k < schedule[1][0] else schedule[1][1][0]
        _, reward, terminated, _, info = env.step(action)
        Kp, Ti, Td = hand_gains(c, action)[0]
        assert info["gains"]["Kp"][0] == pytest.approx(Kp, rel=1e-13)
        assert info["gains"]["Ti"][0] == pytest.approx(Ti, rel=1e-13)
        assert info["gains"]["Td"][0] == pytest.approx(Td, abs=1e-13)
        assert info["setpoint"][0] == r

        # replay eq. 12-14 on an independent instance from the plant's state before the step
        third.set_state(blob)
        e0 = r - y
        integral = float(pid_state.integral[0])
        u0 = min(max(float(c.plant_parameters.get(loop.input, 0.0)), loop.u_min), loop.u_max)
        if k == 0 and u0 != 0.0:  # bumpless start: the integral term Kp/Ti * I equals the trim input u0
            integral = u0 / (Kp / Ti)
        pid = HandPID(dt, loop.u_min, loop.u_max, integral,
                      float(pid_state.last_error[0]) if pid_state.initialized else e0)
        y_hat, prev_norm_error, rewards = y, e0 / scale, []
        u_prev, u_first = u_before, None
        for _ in range(horizon):
            u = pid.step(r - y_hat, Kp, Ti, Td)
            u_first = u if u_first is None else u_first  # what the real plant gets this sample
            n_saturated += u in (loop.u_min, loop.u_max)
            y_hat = float(third.step([u])[0])
            norm_error = (r - y_hat) / scale
            if not abs(norm_error) <= bound:
                rewards.append(c.divergence_penalty)
                break
            rewards.append(hand_reward(norm_error, prev_norm_error, u, u_prev, u_span))
            n_bonus += abs(norm_error) < BONUS_THRESHOLD
            n_moved += 0.0 < abs(u - u_prev) < u_span
            prev_norm_error, u_prev = norm_error, u
        expected = sum(rewards) / len(rewards)
        assert info["forecast_reward"] == pytest.approx(expected, abs=1e-12, rel=0), k
        if not terminated:
            assert reward == info["forecast_reward"]
            # the one-step reward, also by hand, on the real plant's new measurement
            y_new = float(info["measurement"][0])
            assert info["step_reward"] == pytest.approx(
                hand_reward((r - y_new) / scale, e0 / scale, u_first, u_before, u_span), abs=1e-12)
        u_before = u_first
        n_replayed += 1
        if terminated:
            break
        y = float(info["measurement"][0])
    assert n_replayed >= 40
    assert n_bonus > 0  # the bonus branch of eq. 11 was exercised
    assert n_saturated > 0  # ... and so were the saturation and the clamping rule
    assert n_moved > 0  # ... and the unclipped control-variation term
    third.close()
    env.close()


# -- 4. duplicate prior, N = 1: forecast == one-step reward; a mismatched prior differs ------------
@pytest.mark.parametrize("name", ALL_PRESETS)
def test_duplicate_prior_one_step_forecast_equals_step_reward(name):
    env = prlpid_fmi.make_env(name, forecast_horizon=1, measurement_noise_std=0.0, actuator_noise_std=0.0,
                              disturbances=(), load_disturbance=0.0)  # the prior sees no disturbance
    assert env.prior is not None and env.prior is not env.plant
    env.reset(seed=8)
    n = 0
    for a in random_actions(env, 80, seed=9):
        _, reward, terminated, _, info = env.step(a)
        if terminated:
            break
        assert info["forecast_reward"] == info["step_reward"] == reward
        n += 1
    assert n >= 40
    env.close()


def test_mismatched_prior_changes_the_forecast():
    env = prlpid_fmi.make_env("first_order", forecast_horizon=1, prior=PriorConfig(parameters={"a": 2.0}),
                              setpoint_schedule=((0, (0.5,)),))
    env.reset(seed=8)
    differ, n = 0, 0
    for a in random_actions(env, 60, seed=9):
        _, reward, terminated, _, info = env.step(a)
        if terminated:
            break
        n += 1
        assert reward == info["forecast_reward"]
        differ += abs(info["forecast_reward"] - info["step_reward"]) > 1e-9
        # the mismatch lives in the prior only
        assert env.prior.get(["a"])[0] == 2.0
        assert env.plant.get(["a"])[0] == 1.0
    assert n >= 40
    assert differ >= n - 2  # the state x is nonzero after the first step, so a = 2 predicts differently
    env.close()


# -- 5. disturbances ------------------------------------------------------------------------------
def test_fmu_disturbance_sets_and_restores_the_input():
    dist = Disturbance(kind="fmu", target="q_d", start_step=10, value=-20.0, end_step=20)
    env = prlpid_fmi.make_env("two_tank", disturbances=(dist,))
    base = prlpid_fmi.make_env("two_tank")
    actions = random_actions(env, 30, seed=12)
    for e in (env, base):
        e.reset(seed=13)
    for k, a in enumerate(actions):
        _, _, _, _, info = env.step(a)
        _, _, _, _, info_base = base.step(a)
        expected = -20.0 if 10 <= k < 20 else 0.0
        assert env.plant.get(["q_d"])[0] == expected, k
        assert base.plant.get(["q_d"])[0] == 0.0
        if k == 10:
            # the prior model does not know the disturbance: its copy of q_d is the nominal 0
            assert env.prior.get(["q_d"])[0] == 0.0
            # less inflow into tank 1 -> lower tank 2 (same seed: same noise in both runs)
            assert info["measurement"][0] < info_base["measurement"][0]
        if k < 10:
            assert np.array_equal(info["measurement"], info_base["measurement"]), k
            assert np.array_equal(info["control_signal"], info_base["control_signal"]), k
    # a reset in the middle of the disturbance restores the input
    env.reset(seed=13)
    for k, a in enumerate(actions[:15]):
        env.step(a)
    assert env.plant.get(["q_d"])[0] == -20.0
    env.reset()
    assert env.plant.get(["q_d"])[0] == 0.0
    for k, a in enumerate(actions[:11]):
        env.step(a)
        assert env.plant.get(["q_d"])[0] == (-20.0 if k == 10 else 0.0)
    env.close()
    base.close()


STABLE_FIRST_ORDER = action_for(prlpid_fmi.scenario.presets.preset("first_order").loops[0], Kp=3.0, Ti=2.0, Td=0.0)


def test_actuator_disturbance_adds_to_the_control_signal():
    value, start, end = 0.7, 5, 12
    schedule = ((0, (0.5,)),)
    dist = Disturbance(kind="actuator", target="y", start_step=start, value=value, end_step=end)
    env = prlpid_fmi.make_env("first_order", disturbances=(dist,), setpoint_schedule=schedule)
    base = prlpid_fmi.make_env("first_order", setpoint_schedule=schedule)
    for e in (env, base):
        e.reset(seed=0)
    for k in range(20):
        _, _, terminated, _, info = env.step(STABLE_FIRST_ORDER)
        _, _, _, _, info_base = base.step(STABLE_FIRST_ORDER)
        assert not terminated
        u, u_base = info["control_signal"][0], info_base["control_signal"][0]
        assert abs(u) < 10.0  # not saturated
        if k < start:
            assert u == u_base
        elif k == start:
            assert u - u_base == pytest.approx(value, abs=1e-12)
        else:
            assert u != u_base  # the loop reacted
        # u = PID output (before saturation) + the offset inside [start, end)
        offset = value if start <= k < end else 0.0
        assert u == pytest.approx(env.pid.unsaturated_u[0] + offset, abs=1e-12)
    env.close()
    base.close()
    # the offset is added before the saturation: a huge one pins u at u_max, never beyond
    dist = Disturbance(kind="actuator", target="y", start_step=start, value=100.0, end_step=start + 2)
    env = prlpid_fmi.make_env("first_order", disturbances=(dist,), setpoint_schedule=schedule)
    env.reset(seed=0)
    for k in range(start + 4):
        _, _, _, _, info = env.step(STABLE_FIRST_ORDER)
        if start <= k < start + 2:
            assert info["control_signal"][0] == env.config.loops[0].u_max
        else:
            assert abs(info["control_signal"][0]) < env.config.loops[0].u_max
    env.close()


def test_measurement_disturbance_offsets_the_measurement():
    value, start, end = 0.3, 5, 12
    schedule = ((0, (0.5,)),)
    dist = Disturbance(kind="measurement", target="y", start_step=start, value=value, end_step=end)
    env = prlpid_fmi.make_env("first_order", disturbances=(dist,), setpoint_schedule=schedule)
    base = prlpid_fmi.make_env("first_order", setpoint_schedule=schedule)
    for e in (env, base):
        e.reset(seed=0)
    for k in range(20):
        _, _, terminated, _, info = env.step(STABLE_FIRST_ORDER)
        _, _, _, _, info_base = base.step(STABLE_FIRST_ORDER)
        assert not terminated
        # info["measurement"] of step k is the sample y(k+1), which the PID uses in step k+1
        offset = value if start <= k + 1 < end else 0.0
        assert info["measurement"][0] == pytest.approx(env.plant.read_outputs()[0] + offset, abs=1e-12)
        if k + 1 == start:
            assert info["measurement"][0] - info_base["measurement"][0] == pytest.approx(value, abs=1e-12)
        if k < start:
            assert info["control_signal"][0] == info_base["control_signal"][0]
        else:
            assert info["control_signal"][0] != info_base["control_signal"][0]
    env.close()
    base.close()
    # from step 0 on: the reset measurement is offset too
    env = prlpid_fmi.make_env("first_order", disturbances=(Disturbance("measurement", "y", 0, value),))
    _, info = env.reset(seed=0)
    assert info["measurement"][0] == env.plant.read_outputs()[0] + value
    env.close()


# -- 6. divergence and truncation -----------------------------------------------------------------
def test_minimal_gains_diverge_and_terminate_with_the_penalty():
    penalty = -123.5
    env = prlpid_fmi.make_env("first_order", divergence_penalty=penalty, setpoint_schedule=((0, (0.5,)),))
    loop = env.config.loops[0]
    assert hand_gains(env.config, [-1.0, -1.0, -1.0])[0] == (loop.Kp.low, loop.Ti.low, loop.Td.low) == (0.5, 0.2, 0.0)
    # PI on 1/(s - 1): s^2 + (Kp - 1) s + Kp/Ti = s^2 - 0.5 s + 2.5 -> growing oscillation
    env.reset(seed=0)
    for k in range(env.config.episode_steps):
        _, reward, terminated, truncated, info = env.step(np.array([-1.0, -1.0, -1.0], np.float32))
        y_true = env.plant.read_outputs()[0]
        assert terminated == (abs(0.5 - y_true) > loop.divergence_bound), k
        if terminated:
            break
        assert reward != penalty and not truncated
    assert terminated and not truncated
    assert k + 1 < env.config.episode_steps
    assert reward == penalty
    assert info["step_reward"] is None
    env.close()


@pytest.mark.parametrize("episode_steps", [200, 37])
def test_stabilising_gains_run_until_truncation(episode_steps):
    env = prlpid_fmi.make_env("first_order", episode_steps=episode_steps)
    action = action_for(env.config.loops[0], Kp=18.0, Ti=2.0, Td=0.0)
    Kp, Ti, Td = hand_gains(env.config, action)[0]
    assert (Kp, Ti, Td) == pytest.approx((18.0, 2.0, 0.0))
    _, info = env.reset(seed=1)
    for k in range(episode_steps):
        _, reward, terminated, truncated, info = env.step(action)
        assert not terminated
        assert truncated == (k + 1 == episode_steps), k
        assert reward != env.config.divergence_penalty
    # and it did stabilise the loop
    assert abs(info["setpoint"][0] - info["measurement"][0]) < 0.05
    env.close()


# -- 7. setpoint schedule -------------------------------------------------------------------------
def test_setpoint_schedule():
    env = prlpid_fmi.make_env("first_order", setpoint_schedule=((0, (0.5,)), (50, (1.0,))), setpoint_hold_steps=20)
    action = action_for(env.config.loops[0], Kp=18.0, Ti=2.0, Td=0.0)
    obs, info = env.reset(seed=3)
    assert info["setpoint"][0] == 0.5 and obs[0] == np.float32(0.5)
    for k in range(120):
        obs, _, terminated, _, info = env.step(action)
        assert not terminated
        assert info["setpoint"][0] == (0.5 if k < 50 else 1.0), k
        # the observation announces the setpoint of the next step
        assert obs[0] == np.float32(0.5 if k + 1 < 50 else 1.0), k
    env.close()


def test_random_setpoints_are_held_and_in_range():
    env = prlpid_fmi.make_env("first_order", setpoint_hold_steps=25, forecast_horizon=0)
    action = action_for(env.config.loops[0], Kp=18.0, Ti=2.0, Td=0.0)
    _, info = env.reset(seed=3)
    first = info["setpoint"][0]
    setpoints = []
    for _ in range(100):
        _, _, _, _, info = env.step(action)
        setpoints.append(info["setpoint"][0])  # the setpoint step k was computed for
    assert setpoints[0] == first
    blocks = np.array(setpoints).reshape(4, 25)
    assert np.all(blocks == blocks[:, :1])  # constant within each hold
    assert len(set(blocks[:, 0])) == 4  # and redrawn at every hold boundary
    assert np.all((blocks >= -1.0) & (blocks <= 1.0))
    env.close()


# -- observation (Table 1 features) -------------------------------------------------------------
@pytest.mark.parametrize("name", ["two_tank", "quadrotor"])
def test_observation_is_setpoint_measurement_error_and_error_rate(name):
    """obs after step k, per loop: (r, y, e, (e - e_prev)/Ts) / measurement_scale, clipped to +-10, where
    r, y are the values step k+1 will use and e_prev = r_k - y_k was the error step k acted on."""
    env = prlpid_fmi.make_env(name)
    c = env.config
    scale = np.array([l.measurement_scale for l in c.loops])
    obs, info = env.reset(seed=6)
    r, y = info["setpoint"], info["measurement"]
    n_clipped = 0
    for k, a in enumerate(random_actions(env, 40, seed=6)):
        obs, _, terminated, _, info = env.step(a)
        assert not terminated
        r_next = env.setpoint.copy()  # the next step's (random) setpoint; checked against info next step
        assert np.array_equal(info["setpoint"], r)
        y_next = info["measurement"]
        e = r_next - y_next
        features = np.stack([r_next, y_next, e, (e - (r - y)) / c.sample_time_s], axis=1) / scale[:, None]
        n_clipped += np.sum(np.abs(features) > 10.0)
        np.testing.assert_allclose(obs, np.clip(features, -10.0, 10.0).ravel(), rtol=1e-6, atol=1e-6)
        assert obs.dtype == np.float32
        r, y = r_next, y_next
    env.close()
