"""run.record.RunRecord: run.json's content read and written back, field by field (hand-written documents)."""
import json

from prlpid_fmi.run.record import RunRecord, TrainingStopped


def test_a_run_json_round_trips_with_unknown_keys_kept(tmp_path):
    data = {"command": ["prlpid-fmi", "tune", "x.yaml"], "started": "2026-12-04T10:00:00+00:00",
            "versions": {"numpy": "2.0"}, "seed": 3, "total_timesteps": 512, "algorithm": "PPO",
            "isolation": "process", "isolation_reason": "crashed (SIGSEGV) in fmi2DoStep from t = 3 s",
            "anchor": "fixed PID", "trained_timesteps": 256,
            "training_stopped": {"steps": 256, "episodes": 20, "termination": {"message": "boom", "time_s": 0.0}},
            "a_key_of_a_newer_version": [1, 2]}
    (tmp_path / "run.json").write_text(json.dumps(data))
    record = RunRecord.read(tmp_path)
    assert record.isolation == "process" and record.trained_timesteps == 256
    assert record.training_stopped == TrainingStopped(256, 20, {"message": "boom", "time_s": 0.0})
    assert record.extra == {"a_key_of_a_newer_version": [1, 2]}
    record.write(tmp_path)
    assert json.loads((tmp_path / "run.json").read_text()) == data


def test_unset_fields_are_left_out_and_auto_isolation_is_not_written(tmp_path):
    RunRecord(command=["prlpid-fmi"], started="t0", seed=1).write(tmp_path)
    assert json.loads((tmp_path / "run.json").read_text()) == {"command": ["prlpid-fmi"], "started": "t0",
                                                                  "versions": {}, "seed": 1}
    back = RunRecord.read(tmp_path)
    assert back.isolation == "auto" and back.finished is None and back.trained_timesteps is None


def test_a_missing_or_broken_run_json_reads_as_none(tmp_path):
    assert RunRecord.read(tmp_path) is None
    (tmp_path / "run.json").write_text("{not json")
    assert RunRecord.read(tmp_path) is None
    (tmp_path / "run.json").write_text("[1, 2]")
    assert RunRecord.read(tmp_path) is None
