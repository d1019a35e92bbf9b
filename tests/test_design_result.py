"""tuning.design_result: the fixed PID's records read back from fixed_pid.json as the same typed objects, and a file
written before a record's fields existed still reads."""
import json
import math

import numpy as np

from prlpid_fmi.rundir import write_json
from prlpid_fmi.tuning.design_result import (CandidateRecord, DesignResult, Followed, Following, ModelPath,
                                             ModelSearch, Relaxation, Trade)

ON_MODELS = {"evaluations": 450, "model_load_cost": 0.51, "model_overshoot": 4.2, "feasible_on_models": True,
             "kept": True, "load_cost": 0.52, "ISE": 3.0, "Overshoot": 4.4, "b": 0.35}
FIXED_PID = {
    "action": [0.1, -0.2, 0.3], "gains": {"Kp": [4.0], "Ti": [1.0], "Td": [0.1]}, "cost": 0.52, "evaluations": 900,
    "structure": {"setpoint_weight": [0.35], "derivative_weight": [0.0], "measurement_filter_s": [0.0]},
    "design": {
        "objective": "load", "load_cost": 0.52, "load_optimum": 0.5, "load_step": 0.1,
        "traded_for_overshoot": {"load_cost": 0.52, "ISE": 3.0, "Overshoot": 4.4, "feasible": True,
                                 "nearest_load_tolerance": False, "evaluations": 450, "on_models": ON_MODELS},
        "followed_setpoints": {"source": "search", "objective": "setpoint", "load_optimal_diverged": False,
                               "load_cost": 0.9, "ISE": 2.0, "Overshoot": 1.0, "feasible": True, "evaluations": 30,
                               "on_models": None},
        "setpoint_refined": {**ON_MODELS, "ISE_before": 4.0, "classical_bound": True, "settles_range": True},
        "design_model": {"requested": "identified", "path": "identified", "note": "",
                         "models": [{"order": 1, "delay": 0}], "predicted_load_cost": 0.51, "fmu_load_cost": 0.52,
                         "fmu_chatter": 0.0, "validation_error": 0.019, "tolerance": 0.1, "agrees": True,
                         "setpoint_search": "identified"},
        "candidates": [{"relaxed": [{"limit": "max_noise_gain", "requested": 0.02, "used": 0.04}],
                        "following": {"steps": 4, "unsettled": 0, "slow": 1, "diverged": False, "overshoot": 3.0,
                                      "ise": 1.0},
                        "load_cost": 0.52, "ISE": 3.0, "Overshoot": 4.4, "ms_met": True,
                        "gains": {"Kp": [4.0], "Ti": [1.0], "Td": [0.1]}, "kept": True}],
        "following": {"steps": 4, "unsettled": 0, "slow": 1, "diverged": False, "overshoot": 3.0, "ise": 1.0},
        "relaxed": [], "requirements": [], "bound": "overshoot"}}


def test_every_record_reads_back_typed_and_writes_the_same_json(tmp_path):
    result = DesignResult.from_json(json.loads(json.dumps(FIXED_PID)))
    d = result.report.details
    assert isinstance(d.traded_for_overshoot, Trade) and isinstance(d.traded_for_overshoot.on_models, ModelSearch)
    assert d.traded_for_overshoot.on_models.b == 0.35 and d.traded_for_overshoot.feasible
    assert isinstance(d.followed_setpoints, Followed) and d.followed_setpoints.objective == "setpoint"
    assert d.followed_setpoints.on_models is None
    assert isinstance(d.setpoint_refined, ModelSearch) and d.setpoint_refined.ISE_before == 4.0
    assert isinstance(d.design_model, ModelPath) and d.design_model.validation_error == 0.019
    (candidate,) = d.candidates
    assert isinstance(candidate, CandidateRecord) and candidate.kept
    assert candidate.relaxed == (Relaxation("max_noise_gain", 0.02, 0.04),)
    assert candidate.following == Following(4, 0, 1, False, 3.0, 1.0)
    np.testing.assert_array_equal(candidate.gains.Kp, [4.0])
    written = json.loads(write_json(tmp_path / "fixed_pid.json", result.as_json()).read_text())
    again = DesignResult.from_json(written)
    assert again.report == result.report
    assert json.loads(write_json(tmp_path / "again.json", again.as_json()).read_text()) == written
    # every value of the file comes back; fields the file did not have are written as null
    for name, record in FIXED_PID["design"]["traded_for_overshoot"].items():
        assert written["design"]["traded_for_overshoot"][name] == ({**ON_MODELS, **{
            k: None for k in written["design"]["traded_for_overshoot"]["on_models"] if k not in ON_MODELS}}
            if name == "on_models" else record)


def test_a_file_from_before_the_records_reads_with_their_defaults():
    older = {"gains": {"Kp": [4.0], "Ti": [1.0], "Td": [0.0]},
             "design": {"objective": "load", "load_cost": 1.0, "load_optimum": 1.0,
                        "traded_for_overshoot": {"load_cost": 0.94, "ISE": math.inf, "Overshoot": math.inf,
                                                 "feasible": False, "unknown_key": 1},
                        "design_model": {"requested": "fmu"}}}
    d = DesignResult.from_json(older).report.details
    assert d.traded_for_overshoot == Trade(load_cost=0.94, ISE=math.inf, Overshoot=math.inf, feasible=False)
    assert d.followed_setpoints is None and d.setpoint_refined is None and d.candidates == ()
    assert d.design_model == ModelPath(requested="fmu") and d.design_model.path == "fmu"
