"""Robustness of a PID on the FMU: the closed-loop frequency response (identification) and the margins Ms, gain and
phase margin from it."""
