"""Start-up: the commands that neither train nor run a policy import no torch (nor stable-baselines3).

Each command runs in a fresh interpreter (`python -c`, the cli's main), which then reports whether torch or
stable_baselines3 was imported: `validate`, `schema`, `inspect`, `probe`, and `export` of an already-deployed
schedule as Structured Text, PLCopen XML and C.
"""
import json
import subprocess
import sys

import pytest

from prlpid_fmi import rundir as rd
from prlpid_fmi.fmu.resolve import resolve_fmu
from prlpid_fmi.loop.gains import gains_from_values
from prlpid_fmi.scenario.presets import preset, scenario_path
from prlpid_fmi.tuning.schedule.csv_file import write_schedule_csv
from prlpid_fmi.tuning.schedule.table import fixed_schedule

KP, KP_TEXT = 2.375, "2.375"  # the deployed Kp, and how the exported code writes it
PROGRAM = """
import json, sys
from prlpid_fmi.cli import main
try:
    code = main(json.loads(sys.argv[1]))
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "heavy": [m for m in ("torch", "stable_baselines3") if m in sys.modules]}))
"""


@pytest.fixture(scope="module")
def deployed_run(tmp_path_factory):
    """A run directory holding only a deployed schedule.csv (a fixed PID on first_order), what `export` reads."""
    run = tmp_path_factory.mktemp("run")
    write_schedule_csv(fixed_schedule(gains_from_values([KP], [1.5], [0.05]), preset("first_order")),
                       run / rd.SCHEDULE)
    return run


def _commands(run, out):
    fmu = str(resolve_fmu("FirstOrderUnstable"))
    return {"validate": ["validate", str(scenario_path("first_order"))],
            "schema": ["schema"],
            "inspect": ["inspect", fmu],
            "probe": ["probe", fmu, "--output", "y"],
            "export st": ["export", str(run), "--format", "st", "-o", str(out / "pid.st")],
            "export plcopen": ["export", str(run), "--format", "plcopen", "-o", str(out / "pid.xml")],
            "export c": ["export", str(run), "--format", "c", "-o", str(out / "pid.c")]}


@pytest.mark.parametrize("name", ["validate", "schema", "inspect", "probe", "export st", "export plcopen",
                                  "export c"])
def test_commands_that_do_not_train_import_no_torch(name, deployed_run, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    argv = _commands(deployed_run, out)[name]
    proc = subprocess.run([sys.executable, "-c", PROGRAM, json.dumps(argv)], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path)  # probe writes its plot into the working directory
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["code"] == 0, proc.stderr
    assert result["heavy"] == [], f"{name} imported {result['heavy']}"
    if name.startswith("export"):  # the command did its job: the code carries the deployed Kp
        written = {p.name: p.read_text() for p in out.iterdir()}
        assert set(written) == {"export st": {"pid.st"}, "export plcopen": {"pid.xml"},
                                "export c": {"pid.c", "pid.h"}}[name]
        assert any(KP_TEXT in text for text in written.values())
