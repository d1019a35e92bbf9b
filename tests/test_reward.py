"""Hierarchical reward (eq. 10-11) against hand-computed values and invariants."""
import dataclasses
import math

import numpy as np
import pytest

from prlpid_fmi.control import RewardWeights, hierarchical_reward, hierarchical_reward_per_loop
from prlpid_fmi.control.reward import mean_loop_reward

W = RewardWeights()


def test_defaults():
    assert dataclasses.astuple(W) == (1.0, 1.0, 0.5, 1.0, 0.05, 0.1, 0.05, 0.3)  # last: control variation
    with pytest.raises(dataclasses.FrozenInstanceError):
        W.alpha = 2.0


@pytest.mark.parametrize("error, previous, expected", [
    # in the bonus band, steady: V = 0.0002, bonus = 0.1/0.07
    (0.02, 0.02, -0.0002 - 0.02 + 0.1 / 0.07),
    # in the band, negative error: V = 0.0008, bonus = 0.1/0.09
    (-0.04, -0.04, -0.0008 - 0.04 + 0.1 / 0.09),
    # band edge is exclusive: |e| = 0.05 gets no bonus; V = 0.00125
    (0.05, 0.05, -0.05125),
    # steady outside the band: V = 0.125
    (0.5, 0.5, -0.625),
    # growing error: dV = 0.125 - 0.045 = 0.08
    (0.5, 0.3, -0.08 - 0.125 - 0.5),
    # shrinking error: dV < 0 -> no penalty; V = 0.045
    (0.3, 0.5, -0.345),
    # both clips active: min(V=2, 0.5) = 0.5, min(|e|=2, 1) = 1
    (2.0, 2.0, -1.5),
    # clips active and growing: dV = 4.5 - 2 = 2.5 (not clipped)
    (-3.0, -2.0, -4.0),
    # entering the band from outside: dV < 0, V = 0.00005, bonus = 0.1/0.06
    (0.01, 0.5, -0.00005 - 0.01 + 0.1 / 0.06),
])
def test_hand_computed(error, previous, expected):
    assert hierarchical_reward(error, previous, W) == pytest.approx(expected, abs=1e-12)
    assert hierarchical_reward(np.array([error]), np.array([previous]), W) == pytest.approx(expected, abs=1e-12)


def test_custom_weights():
    # alpha=2, beta=0.5, wide clips, e=0.5, prev=0.3: -0.08 - 2*0.125 - 0.5*0.5 = -0.58
    w = RewardWeights(alpha=2.0, beta=0.5, v_clip=10.0, e_clip=10.0)
    assert hierarchical_reward(0.5, 0.3, w) == pytest.approx(-0.58)
    # bigger bonus band, e = 0.1: V = 0.005, bonus = 0.2/(0.1 + 0.1) = 1 -> -0.005 - 0.1 + 1
    w = RewardWeights(bonus_threshold=0.2, bonus_numerator=0.2, bonus_offset=0.1)
    assert hierarchical_reward(0.1, 0.1, w) == pytest.approx(0.895)


def test_multi_loop_is_the_mean_of_per_loop_rewards():
    error, previous = np.array([0.5, 0.02, 2.0]), np.array([0.3, 0.02, 2.0])
    per_loop = hierarchical_reward_per_loop(error, previous, W)
    expected = [-0.705, -0.0002 - 0.02 + 0.1 / 0.07, -1.5]
    np.testing.assert_allclose(per_loop, expected, atol=1e-12)
    assert per_loop.shape == (3,)
    assert hierarchical_reward(error, previous, W) == pytest.approx(sum(expected) / 3, abs=1e-12)


def test_default_weights_used_when_omitted():
    assert hierarchical_reward(0.5, 0.5) == pytest.approx(-0.625)


def test_reward_decreases_as_error_grows_outside_the_band():
    errors = np.linspace(0.05, 5.0, 400)
    rewards = np.array([hierarchical_reward(e, e, W) for e in errors])
    assert np.all(np.diff(rewards) <= 0)
    below_clip = errors < 1.0
    assert np.all(np.diff(rewards[below_clip]) < 0)  # strictly, until both clip bounds are reached
    assert rewards[-1] == pytest.approx(-1.5)


def test_sign_symmetry_and_bonus_band_beats_outside():
    for e in (0.01, 0.3, 1.7):
        assert hierarchical_reward(-e, -e, W) == hierarchical_reward(e, e, W)
    assert hierarchical_reward(0.049, 0.049, W) > 0.9 > hierarchical_reward(0.051, 0.051, W)


def test_growth_penalty_grows_with_the_step_increase():
    # fixed e, smaller previous |e| -> larger dV -> lower reward
    rewards = [hierarchical_reward(1.0, p, W) for p in (1.0, 0.8, 0.5, 0.0)]
    assert rewards == sorted(rewards, reverse=True) and rewards[0] > rewards[-1]


def test_nan_error_gives_nan():
    assert math.isnan(hierarchical_reward(float("nan"), 0.1, W))
    assert math.isnan(hierarchical_reward(0.1, float("nan"), W))


def test_invalid_weights_and_shapes():
    with pytest.raises(ValueError, match="v_clip"):
        RewardWeights(v_clip=0.0)
    with pytest.raises(ValueError, match="alpha"):
        RewardWeights(alpha=-1.0)
    with pytest.raises(ValueError, match="length"):
        hierarchical_reward(np.zeros(2), np.zeros(3), W)


CV = RewardWeights(control_variation_weight=0.5)


@pytest.mark.parametrize("error, previous, u, u_prev, u_scale, expected", [
    # steady |e| = 0.2 (V = 0.02, no growth): -0.02 - 0.2; |du|/scale = 2/10 = 0.2 -> -0.5*0.2
    (0.2, 0.2, 3.0, 1.0, 10.0, -0.22 - 0.1),
    # the move counts in either direction
    (0.2, 0.2, 1.0, 3.0, 10.0, -0.22 - 0.1),
    # clipped at 1: |du|/scale = 20/10 -> -0.5*1
    (0.2, 0.2, 15.0, -5.0, 10.0, -0.22 - 0.5),
    # exactly at the clip
    (0.2, 0.2, 10.0, 0.0, 10.0, -0.22 - 0.5),
    # no move, no penalty; in the bonus band: V = 0.0002, bonus 0.1/0.07
    (0.02, 0.02, 4.0, 4.0, 10.0, -0.0002 - 0.02 + 0.1 / 0.07),
])
def test_control_variation_hand_computed(error, previous, u, u_prev, u_scale, expected):
    assert hierarchical_reward(error, previous, CV, u, u_prev, u_scale) == pytest.approx(expected, abs=1e-12)
    assert hierarchical_reward_per_loop(error, previous, CV, u, u_prev, u_scale)[0] == pytest.approx(expected, abs=1e-12)


def test_control_variation_per_loop_scale_and_mean():
    # loop 1: -0.22 - 0.5*0.2; loop 2: steady e = 0.5 (-0.625) - 0.5*min(3/2, 1)
    r = hierarchical_reward([0.2, 0.5], [0.2, 0.5], CV, [3.0, 1.0], [1.0, -2.0], [10.0, 2.0])
    assert r == pytest.approx((-0.32 + -1.125) / 2, abs=1e-12)
    assert mean_loop_reward([0.2, 0.5], [0.2, 0.5], CV, [3.0, 1.0], [1.0, -2.0], [10.0, 2.0]) == r


def test_control_variation_is_zero_without_u_or_weight():
    assert hierarchical_reward(0.5, 0.3, CV) == hierarchical_reward(0.5, 0.3, W)
    off = RewardWeights(control_variation_weight=0.0)  # the paper's eq. 10
    assert hierarchical_reward(0.5, 0.3, off, 5.0, -5.0, 1.0) == hierarchical_reward(0.5, 0.3, W)


def test_control_variation_on_by_default():
    # steady |e| = 0.2: -0.02 - 0.2; |du| / scale = 2 / 10 -> -0.3 * 0.2 with the default weight
    assert hierarchical_reward(0.2, 0.2, W, 3.0, 1.0, 10.0) == pytest.approx(-0.22 - 0.06, abs=1e-12)
    assert math.isnan(hierarchical_reward(0.5, 0.3, CV, float("nan"), 0.0, 1.0))  # min(NaN, 1) is NaN


def test_control_variation_needs_all_three_and_a_positive_scale():
    with pytest.raises(ValueError, match="together"):
        hierarchical_reward(0.5, 0.3, CV, u=1.0)
    with pytest.raises(ValueError, match="u_scale"):
        hierarchical_reward(0.5, 0.3, CV, 1.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="values each"):
        hierarchical_reward([0.5, 0.1], [0.3, 0.1], CV, [1.0], [0.0], [1.0])
    with pytest.raises(ValueError, match="control_variation_weight"):
        RewardWeights(control_variation_weight=-0.1)
