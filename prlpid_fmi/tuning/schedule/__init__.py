"""Gain schedules: the table, extraction from a policy (settled holds and trajectories), replay as a plain PID, and
the CSV file."""
