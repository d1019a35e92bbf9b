"""Reward forecast (paper eq. 12-14): roll the prior model N steps ahead with the current gains, through FMI calls (fmi.py) or one C call (native.py)."""
