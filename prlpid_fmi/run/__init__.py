"""The workflows on a run directory: tune a scenario as named stages, re-evaluate a run, export its controller."""
