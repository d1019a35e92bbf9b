"""Scenario files: the YAML of one tuning problem loaded into typed configs (load), the bundled presets and
make_env (presets), and drafting a scenario for an FMU (draft: `prlpid-fmi init`)."""
from prlpid_fmi.scenario.draft import init_scenario
from prlpid_fmi.scenario.load import (EvaluationConfig, Scenario, load_scenario, scenario_to_dict, scenario_to_yaml,
                                      validate_scenario)
from prlpid_fmi.scenario.presets import bundled_scenario_names, make_env, preset, resolve_scenario, scenario_path

__all__ = ["EvaluationConfig", "Scenario", "load_scenario", "validate_scenario", "scenario_to_dict", "scenario_to_yaml",
           "init_scenario", "bundled_scenario_names", "make_env", "preset", "resolve_scenario", "scenario_path"]
