"""Library functions word a bad argument in their own terms (the parameter's name); the CLI shows the option."""
from __future__ import annotations

import pytest

from prlpid_fmi.cli import OPTIONS, main
from prlpid_fmi.errors import ArgumentError, RunError
from prlpid_fmi.run.tune import tune


def test_the_message_names_the_parameter_and_the_cli_names_the_option():
    exc = ArgumentError("{scenario_path} s.yaml: only used with {replay} (got {x}; expected {replay})")
    assert isinstance(exc, RunError)
    assert str(exc) == "scenario_path s.yaml: only used with replay (got x; expected replay)"
    assert exc.worded(OPTIONS) == "--scenario s.yaml: only used with --replay (got x; expected --replay)"


def test_tune_refuses_a_bad_budget_in_its_own_words_and_the_cli_in_options(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ArgumentError, match=r"^timesteps: must be at least 1 \(got 0;"):
        tune("first_order", timesteps=0)
    with pytest.raises(ArgumentError, match=r"^seed: out of range \(got -1;"):
        tune("first_order", seed=-1)
    assert main(["tune", "first_order", "--timesteps", "0"]) == 2
    assert capsys.readouterr().err.startswith("prlpid-fmi: error: --timesteps: must be at least 1 (got 0;")
    assert list(tmp_path.iterdir()) == []
