"""Action smoothing (eq. 19-21) against hand-computed sequences."""
import numpy as np
import pytest

from prlpid_fmi.control import DEFAULT_ALPHA, DEFAULT_WINDOW, SMOOTHING_METHODS, make_smoother

RAW = [1.0, 3.0, 2.0, 6.0, 4.0, 8.0, 5.0]


def smooth_1d(smoother, raw=RAW):
    return [smoother(np.array([a]))[0] for a in raw]


def test_defaults_are_the_papers():
    assert DEFAULT_WINDOW == 5
    assert DEFAULT_ALPHA == {"lwma": 0.2, "era": 0.3}
    assert SMOOTHING_METHODS == ("none", "sma", "lwma", "era")


def test_none_returns_a_copy_of_the_raw_action():
    s = make_smoother("none", n_params=2)
    raw = np.array([0.3, -0.7])
    out = s(raw)
    np.testing.assert_array_equal(out, raw)
    out[0] = 99.0
    assert raw[0] == 0.3


def test_sma_window_3():
    # means of what is available, then of the last 3:
    # 1, (1+3)/2, (1+3+2)/3, (3+2+6)/3, (2+6+4)/3, (6+4+8)/3, (4+8+5)/3
    expected = [1.0, 2.0, 2.0, 11 / 3, 4.0, 6.0, 17 / 3]
    np.testing.assert_allclose(smooth_1d(make_smoother("sma", n_params=1, window=3)), expected)


def test_sma_default_window_5():
    # t4: (1+3+2+6+4)/5 = 3.2, t5: (3+2+6+4+8)/5 = 4.6, t6: (2+6+4+8+5)/5 = 5
    expected = [1.0, 2.0, 2.0, 3.0, 3.2, 4.6, 5.0]
    np.testing.assert_allclose(smooth_1d(make_smoother("sma", n_params=1)), expected)


def test_lwma_window_3_newest_weighted_most():
    # eq. 20 weights for M=3, alpha=0.2: w_k = 0.2 + 0.8(k+1)/3 = 7/15, 11/15, 15/15.
    # Newest action gets 15/15, the one before 11/15, the oldest 7/15 (in fifteenths: 15, 11, 7).
    # t0: 1
    # t1: (15*3 + 11*1)/26          = 56/26
    # t2: (15*2 + 11*3 + 7*1)/33    = 70/33
    # t3: (15*6 + 11*2 + 7*3)/33    = 133/33
    # t4: (15*4 + 11*6 + 7*2)/33    = 140/33
    # t5: (15*8 + 11*4 + 7*6)/33    = 206/33
    # t6: (15*5 + 11*8 + 7*4)/33    = 191/33
    expected = [1.0, 56 / 26, 70 / 33, 133 / 33, 140 / 33, 206 / 33, 191 / 33]
    np.testing.assert_allclose(smooth_1d(make_smoother("lwma", n_params=1, window=3)), expected)


def test_lwma_defaults_window_5_alpha_02():
    # weights newest..oldest: 1.0, 0.84, 0.68, 0.52, 0.36 (sum 3.4)
    # t1: (3*1 + 1*0.84)/1.84                              = 3.84/1.84
    # t4: 4*1 + 6*.84 + 2*.68 + 3*.52 + 1*.36  = 12.32     -> 12.32/3.4
    # t5: 8*1 + 4*.84 + 6*.68 + 2*.52 + 3*.36  = 17.56     -> 17.56/3.4
    # t6: 5*1 + 8*.84 + 4*.68 + 6*.52 + 2*.36  = 18.28     -> 18.28/3.4
    out = smooth_1d(make_smoother("lwma", n_params=1))
    np.testing.assert_allclose([out[1], out[4], out[5], out[6]], [3.84 / 1.84, 12.32 / 3.4, 17.56 / 3.4, 18.28 / 3.4])


def test_lwma_alpha_one_is_sma():
    lwma = smooth_1d(make_smoother("lwma", n_params=1, window=3, alpha=1.0))
    np.testing.assert_allclose(lwma, [1.0, 2.0, 2.0, 11 / 3, 4.0, 6.0, 17 / 3])


def test_era_default_alpha_03():
    # a0 = 1; a_t = 0.3*raw_t + 0.7*a_{t-1}
    # 0.9 + 0.7 = 1.6; 0.6 + 1.12 = 1.72; 1.8 + 1.204 = 3.004; 1.2 + 2.1028 = 3.3028;
    # 2.4 + 2.31196 = 4.71196; 1.5 + 3.298372 = 4.798372
    expected = [1.0, 1.6, 1.72, 3.004, 3.3028, 4.71196, 4.798372]
    np.testing.assert_allclose(smooth_1d(make_smoother("era", n_params=1)), expected)


@pytest.mark.parametrize("method, kwargs, expected", [
    # raw rows (1, 10), (3, 0), (2, 10)
    ("sma", dict(window=2), [[1, 10], [2, 5], [2.5, 5]]),
    # M=2, alpha=0.2: w_0 = 0.6 (older), w_1 = 1.0 (newest), sum 1.6
    # t1: ((3,0) + 0.6*(1,10))/1.6 = (2.25, 3.75); t2: ((2,10) + 0.6*(3,0))/1.6 = (2.375, 6.25)
    ("lwma", dict(window=2), [[1, 10], [2.25, 3.75], [2.375, 6.25]]),
    # alpha = 0.5: (2, 5), (2, 7.5)
    ("era", dict(alpha=0.5), [[1, 10], [2, 5], [2, 7.5]]),
    ("none", {}, [[1, 10], [3, 0], [2, 10]]),
])
def test_two_parameters_smoothed_independently(method, kwargs, expected):
    s = make_smoother(method, n_params=2, **kwargs)
    out = [s(np.array(row)) for row in ([1.0, 10.0], [3.0, 0.0], [2.0, 10.0])]
    np.testing.assert_allclose(out, expected)


@pytest.mark.parametrize("method", SMOOTHING_METHODS)
def test_reset_restarts_history(method):
    s = make_smoother(method, n_params=1, window=3)
    smooth_1d(s)
    s.reset()
    assert s(np.array([-4.0]))[0] == -4.0  # first action after reset passes unchanged
    second = s(np.array([2.0]))[0]
    fresh = make_smoother(method, n_params=1, window=3)
    fresh(np.array([-4.0]))
    assert second == fresh(np.array([2.0]))[0]


@pytest.mark.parametrize("method", SMOOTHING_METHODS)
def test_output_and_input_are_not_aliased(method):
    s = make_smoother(method, n_params=2, window=3)
    raw = np.array([1.0, 2.0])
    out = s(raw)
    raw[:] = 100.0
    out[:] = -100.0
    np.testing.assert_allclose(s(np.array([1.0, 2.0])), [1.0, 2.0])  # constant input stays constant


@pytest.mark.parametrize("method", SMOOTHING_METHODS)
def test_constant_input_is_a_fixed_point_and_output_stays_in_range(method):
    s = make_smoother(method, n_params=1, window=4)
    np.testing.assert_allclose(smooth_1d(s, [0.25] * 9), [0.25] * 9)
    s.reset()
    out = smooth_1d(s)
    assert min(RAW) <= min(out) and max(out) <= max(RAW)


@pytest.mark.parametrize("kwargs, match", [
    (dict(method="median"), "one of"),
    (dict(method="sma", window=0), "window"),
    (dict(method="lwma", window=2.5), "window"),
    (dict(method="lwma", alpha=1.5), r"\[0, 1\]"),
    (dict(method="lwma", alpha=-0.1), r"\[0, 1\]"),
    (dict(method="era", alpha=0.0), r"\(0, 1\]"),
    (dict(method="era", alpha=float("nan")), r"\(0, 1\]"),
    (dict(method="sma", alpha=0.3), "takes no alpha"),
    (dict(method="none", alpha=0.3), "takes no alpha"),
    (dict(method="era", n_params=0), "n_params"),
])
def test_invalid_arguments(kwargs, match):
    kwargs = {"n_params": 1, **kwargs}
    with pytest.raises(ValueError, match=match):
        make_smoother(**kwargs)


def test_wrong_action_shape():
    s = make_smoother("era", n_params=3)
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        s(np.zeros(2))
