"""Sweeps: one scenario's variants (any scenario keys) over several seeds, each trial an ordinary run directory,
run in local processes or on Ray, summarised as mean and 95 % confidence interval per variant.

spec.py reads and validates sweep files, runner.py runs the trials, summary.py writes the tables and figures.
"""
from prlpid_fmi.sweep.runner import SweepRun, Trial, run_sweep, trial_status
from prlpid_fmi.sweep.spec import Sweep, Variant, bundled_sweep_names, load_sweep, resolve_sweep

__all__ = ["Sweep", "Variant", "SweepRun", "Trial", "bundled_sweep_names", "load_sweep", "resolve_sweep", "run_sweep",
           "trial_status"]
