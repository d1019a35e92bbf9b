"""prlpid-fmi: tune PID controllers for FMU plants with predictive reinforcement learning (PRL-PID)."""

__version__ = "0.1.0"
