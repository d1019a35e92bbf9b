"""Scenario files: the YAML of one tuning problem loaded into typed configs, the bundled presets, and drafting a scenario for an FMU (init)."""
