"""Tuning: the fixed-PID search and its detuning, the agent's training (stable-baselines3), and gain schedules read
from a trained policy."""
