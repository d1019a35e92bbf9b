"""Control pieces, plain numpy: PID law (eq. 2, 26-27), action smoothing (eq. 19-21), reward (eq. 10-11)."""
from prlpid_fmi.control.pid import (
                  ANTI_WINDUP_MODES,
                  COUPLING_NAMES,
                  PID,
                  CoupledPID,
                  PIDState,
                  coupling_matrix,
                  parallel_gains,
)
from prlpid_fmi.control.reward import DEFAULT_WEIGHTS, RewardWeights, hierarchical_reward, hierarchical_reward_per_loop
from prlpid_fmi.control.smoothing import (
                  DEFAULT_ALPHA,
                  DEFAULT_WINDOW,
                  SMOOTHING_METHODS,
                  ExponentialRecursiveAverage,
                  LinearlyWeightedMovingAverage,
                  NoSmoothing,
                  SimpleMovingAverage,
                  make_smoother,
)

__all__ = [
    "ANTI_WINDUP_MODES", "COUPLING_NAMES", "PID", "CoupledPID", "PIDState", "coupling_matrix", "parallel_gains",
    "DEFAULT_WEIGHTS", "RewardWeights", "hierarchical_reward", "hierarchical_reward_per_loop",
    "DEFAULT_ALPHA", "DEFAULT_WINDOW", "SMOOTHING_METHODS", "ExponentialRecursiveAverage",
    "LinearlyWeightedMovingAverage", "NoSmoothing", "SimpleMovingAverage", "make_smoother",
]
