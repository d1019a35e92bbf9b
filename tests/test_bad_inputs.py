"""Bad scenario files: every mistake is one clear line naming the file, the key path and the value as written,
all mistakes of a file are reported at once, and broken FMU archives are refused at validate.

Each case edits a bundled scenario (or its text, or its FMU archive) in one place; the loader must answer
with exactly one line ``<file>: <key.path>: <problem> (got <value>; expected <what>)``.
"""
from __future__ import annotations

import copy
import math
import random
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import yaml

from prlpid_fmi.errors import ScenarioError
from prlpid_fmi.fmu import bundled_fmu
from prlpid_fmi.scenario.load import load_scenario
from test_scenario import _raw, _set

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
INF, NAN = math.inf, math.nan


def _both(*edits):
    def edit(doc, tmp_path):
        for e in edits:
            e(doc, tmp_path)
    return edit


# (id, base scenario, edit, key path in the message, the value as shown, a word of the problem)
CASES = [
    # numbers that must be finite (only u_limits may be infinite), NaN nowhere
    ("sample-time-inf", "first_order", _set("plant.sample_time", INF), "plant.sample_time", ".inf", "not finite"),
    ("sample-time-nan", "first_order", _set("plant.sample_time", NAN), "plant.sample_time", ".nan", "NaN"),
    ("gain-bound-inf", "first_order", _set("plant.loops.0.gains.Kp", [0.5, INF, "log"]),
     "plant.loops[0].gains.Kp[1]", ".inf", "not finite"),
    ("noise-inf", "first_order", _set("training.measurement_noise_std", INF), "training.measurement_noise_std",
     ".inf", "not finite"),
    ("learning-rate-inf", "first_order", _set("agent.learning_rate", INF), "agent.learning_rate", ".inf",
     "not finite"),
    ("measurement-scale-inf", "first_order", _set("plant.loops.0.measurement_scale", INF),
     "plant.loops[0].measurement_scale", ".inf", "not finite"),
    ("divergence-penalty-inf", "first_order", _set("reward.divergence_penalty", -INF), "reward.divergence_penalty",
     "-.inf", "not finite"),
    ("u-limits-nan", "first_order", _set("plant.loops.0.u_limits", [NAN, 1]), "plant.loops[0].u_limits[0]",
     ".nan", "NaN"),
    ("setpoint-range-inf", "first_order", _set("plant.loops.0.setpoint_range", [0, INF]),
     "plant.loops[0].setpoint_range[1]", ".inf", "not finite"),
    ("parameter-inf", "first_order", _set("plant.parameters.a", INF), "plant.parameters.a", ".inf", "not finite"),
    ("control-scale-inf", "first_order", _set("plant.loops.0.control_scale", INF), "plant.loops[0].control_scale",
     ".inf", "not finite"),
    ("max-sensitivity-inf", "first_order", _set("deploy.max_sensitivity", INF), "deploy.max_sensitivity", ".inf",
     "not finite"),
    ("eval-randomize-inf", "first_order", _set("evaluation.randomize", {"a": [0.5, INF]}),
     "evaluation.randomize.a[1]", ".inf", "not finite"),
    # ranges
    ("negative-noise", "first_order", _set("training.actuator_noise_std", -0.1), "training.actuator_noise_std",
     "-0.1", "out of range"),
    ("divergence-bound-zero", "first_order", _set("plant.loops.0.divergence_bound", 0),
     "plant.loops[0].divergence_bound", "0", "out of range"),
    ("u-limits-equal", "first_order", _set("plant.loops.0.u_limits", [1, 1]), "plant.loops[0].u_limits", "[1, 1]",
     "low >= high"),
    ("gamma-above-1", "first_order", _set("agent.gamma", 1.5), "agent.gamma", "1.5", "out of range"),
    ("net-arch-empty", "first_order", _set("agent.net_arch", []), "agent.net_arch", "[]", "length 0"),
    ("net-arch-zero-layer", "first_order", _set("agent.net_arch", [64, 0]), "agent.net_arch[1]", "0", "out of range"),
    ("negative-seed", "first_order", _set("agent.seed", -1), "agent.seed", "-1", "out of range"),
    # numpy's legacy seeding (SB3's set_random_seed) refuses 2**32 and above with a traceback
    ("seed-2-to-the-32", "first_order", _set("agent.seed", 2**32), "agent.seed", "4294967296",
     "an integer in [0, 2147483647]"),
    ("eval-seed-huge", "first_order", _set("evaluation.seed", 1e30), "evaluation.seed", "1.0e+30", "out of range"),
    ("control-scale-zero", "first_order", _set("plant.loops.0.control_scale", 0), "plant.loops[0].control_scale",
     "0", "out of range"),
    ("control-variation-negative", "first_order", _set("reward.control_variation_weight", -1),
     "reward.control_variation_weight", "-1", "out of range"),
    ("anchor-kp-below-1", "first_order", _set("controller.anchor_bands.Kp", 0.5), "controller.anchor_bands.Kp",
     "0.5", "out of range"),
    ("anchor-td-zero", "first_order", _set("controller.anchor_bands.Td", 0), "controller.anchor_bands.Td", "0",
     "out of range"),
    ("anchor-td-above-1", "first_order", _set("controller.anchor_bands.Td", 1.5), "controller.anchor_bands.Td",
     "1.5", "out of range"),
    ("anchor-coupling-negative", "first_order", _set("controller.anchor_bands.coupling", -0.1),
     "controller.anchor_bands.coupling", "-0.1", "out of range"),
    ("max-sensitivity-1", "first_order", _set("deploy.max_sensitivity", 1.0), "deploy.max_sensitivity", "1.0",
     "out of range"),
    ("randomize-samples-negative", "first_order", _set("evaluation.randomize_samples", -1),
     "evaluation.randomize_samples", "-1", "out of range"),
    ("baseline-popsize-zero", "first_order", _set("baseline.popsize", 0), "baseline.popsize", "0", "out of range"),
    ("eval-episode-fraction", "first_order", _set("evaluation.episode_steps", 0.5), "evaluation.episode_steps",
     "0.5", "not an integer"),
    # types and choices
    ("baseline-episodes-fraction", "first_order", _set("baseline.episodes", 1.5), "baseline.episodes", "1.5",
     "not an integer"),
    ("normalize-string", "first_order", _set("agent.normalize", "yes"), "agent.normalize", "'yes'",
     "not a boolean"),
    ("empty-name", "first_order", _set("name", ""), "name", "''", "empty"),
    ("section-not-mapping", "first_order", _set("reward", 5), "reward", "5", "not a mapping"),
    ("fmi-version-4", "first_order", _set("plant.fmi_version", 4), "plant.fmi_version", "4", "unknown"),
    ("vec-env-misspelled", "first_order", _set("agent.vec_env", "subprocess"), "agent.vec_env", "'subprocess'",
     "did you mean 'subproc'"),
    ("gain-mapping-misspelled", "first_order", _set("controller.gain_mapping", "anchord"),
     "controller.gain_mapping", "'anchord'", "did you mean 'anchored'"),
    ("anchor-band-key-case", "first_order", _set("controller.anchor_bands.kp", 2.0), "controller.anchor_bands.kp",
     "'kp'", "did you mean 'Kp'"),
    ("deploy-unknown-key", "first_order", _set("deploy.margin", 2), "deploy.margin", "'margin'", "unknown key"),
    # randomize
    ("randomize-unknown", "first_order", _set("training.randomize", {"zz": [0, 1]}), "training.randomize.zz",
     "'zz'", "no variable 'zz'"),
    ("randomize-low-gt-high", "first_order", _set("training.randomize", {"a": [2, 1]}), "training.randomize.a",
     "[2, 1]", "low > high"),
    ("randomize-an-output", "two_tank", _set("training.randomize", {"h2": [10, 20]}),
     "training.randomize.h2", "'h2'", "causality mismatch"),
    ("randomize-not-a-pair", "first_order", _set("training.randomize", {"a": [1]}), "training.randomize.a", "[1]",
     "list of length 1"),
    # agent.extra against the algorithm's constructor
    ("extra-unknown", "first_order", _set("agent.extra", {"max_grad_nrm": 0.5}), "agent.extra.max_grad_nrm",
     "'max_grad_nrm'", "did you mean 'max_grad_norm'"),
    ("extra-set-by-agent", "first_order", _set("agent.extra", {"learning_rate": 0.1}), "agent.extra.learning_rate",
     "'learning_rate'", "agent.learning_rate"),
    ("extra-of-another-algorithm", "first_order",
     _both(_set("agent.algorithm", "sac"), _set("agent.extra", {"clip_range_vf": 0.2})),
     "agent.extra.clip_range_vf", "'clip_range_vf'", "stable_baselines3.SAC"),
    ("extra-set-by-the-tool", "first_order", _set("agent.extra", {"policy": "CnnPolicy"}), "agent.extra.policy",
     "'policy'", "prlpid-fmi itself"),
    # schedules, disturbances, loops
    ("setpoints-not-increasing", "first_order",
     _set("training.setpoints", [{"at_step": 0, "value": 0.5}, {"at_step": 0, "value": 1.0}]),
     "training.setpoints[1].at_step", "0", "out of order"),
    ("setpoints-start-late", "first_order", _set("evaluation.setpoints", [{"at_step": 5, "value": 1.0}]),
     "evaluation.setpoints[0].at_step", "5", "start at step 0"),
    ("pulse-without-duration", "two_tank", _set("evaluation.disturbances.0", {"type": "pulse", "target": "q_d",
                                                                              "at_step": 100, "value": 1.0}),
     "evaluation.disturbances[0].duration_steps", "nothing", "a pulse needs a duration"),
    ("disturbance-past-episode", "two_tank", _set("evaluation.disturbances.2.at_step", 800),
     "evaluation.disturbances[2].at_step", "800", "outside the episode"),
    ("alpha-for-no-smoothing", "first_order", _both(_set("strategies.smoothing", "none"),
                                                    _set("strategies.smoothing_alpha", 0.5)),
     "strategies.smoothing_alpha", "0.5", "takes no alpha"),
    ("loops-share-output", "quadrotor", _set("plant.loops.1.output", "phi"), "plant.loops[1].output", "'phi'",
     "share the output"),
    # a setpoint step the divergence bound ends at once: setpoint_range spans 2, the bound is 5 x scale 1
    ("divergence-bound-below-setpoint-span", "first_order", _set("plant.loops.0.divergence_bound", 1.5),
     "plant.loops[0].divergence_bound", "1.5", "2 x measurement_scale"),
    ("setpoint-step-past-divergence-bound", "first_order",
     _set("evaluation.setpoints", [{"at_step": 0, "value": 1.0}, {"at_step": 50, "value": -4.5}]),
     "evaluation.setpoints[1].value", "-4.5", "plant.loops[0].divergence_bound x measurement_scale = 5"),
    ("setpoint-step-past-divergence-bound-loop-2", "quadrotor",  # 6 x 0.5 = 3 rad per loop
     _set("evaluation.setpoints", [{"at_step": 0, "value": [0.0, 0.0, 0.0]},
                                   {"at_step": 10, "value": [2.9, -3.1, 0.0]}]),
     "evaluation.setpoints[1].value", "[2.9, -3.1, 0.0]", "from 0 to -3.1 is larger than plant.loops[1]"),
]


def _write(path: Path, doc) -> Path:
    path.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc, sort_keys=False))
    return path


def _one_line(path: Path, key: str, shown: str, word: str) -> str:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert "\n" not in msg, msg
    assert msg.startswith(f"{path}: {key}: "), msg
    assert f"(got {shown}" in msg and "; expected " in msg, msg
    assert word in msg, msg
    return msg


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_value_gives_one_line(case, tmp_path):
    _, base, edit, key, shown, word = case
    doc = copy.deepcopy(_raw(base))
    edit(doc, tmp_path)
    _one_line(_write(tmp_path / "bad.yaml", doc), key, shown, word)


def test_cases_are_distinct():
    assert len({c[0] for c in CASES}) == len(CASES) >= 40


# --------------------------------------------------------------------------------------------
# repeated keys (PyYAML keeps the second silently)

DUPLICATES = [
    ("plant-key", "  sample_time: 0.1                 # s\n",
     "  sample_time: 0.1\n  sample_time: 5.0\n", "plant.sample_time", "'sample_time'", "lines 5 and 6"),
    ("section", "agent: {algorithm: ppo, total_timesteps: 500000, seed: 0}\n",
     "agent: {algorithm: ppo}\nagent: {algorithm: sac}\n", "agent", "'agent'", "lines 17 and 18"),
    ("loop-key", "      output: y\n", "      output: y\n      output: y\n", "plant.loops[0].output", "'output'",
     "lines 9 and 10"),
    ("flow-mapping", "gains: {Kp: [0.5, 30, log],", "gains: {Kp: [0.5, 30, log], Kp: [1, 2],", "plant.loops[0].gains.Kp",
     "'Kp'", "lines 14 and 14"),
]


@pytest.mark.parametrize("case", DUPLICATES, ids=[c[0] for c in DUPLICATES])
def test_repeated_key_is_refused_with_both_lines(case, tmp_path):
    _, old, new, key, shown, lines = case
    text = (SCENARIOS / "first_order.yaml").read_text()
    assert text.count(old) == 1
    msg = _one_line(_write(tmp_path / "dup.yaml", text.replace(old, new)), key, shown, "duplicate key")
    assert lines in msg


# --------------------------------------------------------------------------------------------
# FMU archives, checked before anything is extracted

def _rezip(tmp_path: Path, transform, name: str = "plant.fmu", fmi_version: int = 2) -> Path:
    """A copy of the bundled FirstOrderUnstable FMU (FMI 2.0, or 3.0) with its members passed through
    transform(name, data) -> [(name, data), ...]."""
    src = bundled_fmu("FirstOrderUnstable", fmi_version)
    out = tmp_path / name
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as zout:
        for info in zin.infolist():
            for member, data in transform(info.filename, zin.read(info)):
                zout.writestr(zipfile.ZipInfo(member), data)
    return out


def _add(member: str, data: bytes = b"x"):
    def transform(name, data_in):
        return [(name, data_in)] + ([(member, data)] if name == "modelDescription.xml" else [])
    return transform


def _drop(prefix: str):
    return lambda name, data: [] if name.startswith(prefix) else [(name, data)]


def _replace(member: str, data: bytes):
    return lambda name, data_in: [(name, data if name == member else data_in)]


def _corrupt(tmp_path: Path) -> Path:
    """Flip a byte inside the stored binary: the archive's CRC check fails."""
    path = _rezip(tmp_path, lambda n, d: [(n, d)])
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("binaries/linux64/FirstOrderUnstable.so")
    raw = bytearray(path.read_bytes())
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    raw[start + 100] ^= 0xFF
    path.write_bytes(bytes(raw))
    return path


def _truncated(tmp_path: Path) -> Path:
    path = tmp_path / "plant.fmu"
    data = bundled_fmu("FirstOrderUnstable", 2).read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


MD = "modelDescription.xml"
ARCHIVES = [
    ("absolute-member", lambda t: _rezip(t, _add("/tmp/evil.txt")), "unsafe member name '/tmp/evil.txt'"),
    ("dotdot-member", lambda t: _rezip(t, _add("resources/../../evil.txt")), "'..'"),
    ("backslash-member", lambda t: _rezip(t, _add("resources\\data.txt")), "a backslash"),
    ("no-model-description", lambda t: _rezip(t, _drop(MD)), "no modelDescription.xml"),
    ("garbage-model-description", lambda t: _rezip(t, _replace(MD, b"<fmiModelDescription")),
     "unreadable modelDescription.xml"),
    ("unsupported-fmi-version", lambda t: _rezip(t, lambda n, d: [(n, d.replace(b'fmiVersion="2.0"',
                                                                               b'fmiVersion="4.0"'))]),
     "Unsupported FMI version: 4.0"),
    ("no-binary-but-sources", lambda t: _rezip(t, _drop("binaries/")), "fmpy compile plant.fmu"),
    ("no-binary-no-sources", lambda t: _rezip(t, lambda n, d: [] if n.split("/")[0] in ("binaries", "sources")
                                              else [(n, d)]), "binaries for: no platform"),
    ("empty-platform-folder", lambda t: _rezip(t, lambda n, d: (
        [] if n.split("/")[0] in ("binaries", "sources") else [(n, d)]) + (
        [("binaries/linux64/", b""), ("binaries/win64/FirstOrderUnstable.dll", b"MZ")] if n == MD else [])),
     "binaries for: win64)"),  # an empty binaries/linux64/ folder is no binary for linux64 (SimulationX 3.7)
    ("corrupt-member", _corrupt, "corrupt archive member 'binaries/linux64/FirstOrderUnstable.so'"),
    ("truncated-archive", _truncated, "not a ZIP archive"),
    ("extracted-folder", lambda t: (t / "plant.fmu").mkdir(), "a folder, not an FMU file"),
]


@pytest.mark.parametrize("case", ARCHIVES, ids=[c[0] for c in ARCHIVES])
def test_broken_fmu_archive_gives_one_line(case, tmp_path):
    _, make, word = case
    make(tmp_path)
    doc = _raw("first_order")
    doc["plant"]["fmu"] = "plant.fmu"
    _one_line(_write(tmp_path / "bad.yaml", doc), "plant.fmu", "'plant.fmu'", word)


def test_broken_prior_archive_names_prior_fmu(tmp_path):
    _rezip(tmp_path, _add("../evil.txt"), "prior.fmu")
    doc = _raw("first_order")
    doc["prior"] = {"fmu": "prior.fmu", "state_map": {"x0": "y"}}
    _one_line(_write(tmp_path / "bad.yaml", doc), "prior.fmu", "'prior.fmu'", "unsafe member name")


def test_another_prior_fmu_needs_a_state_map(tmp_path):
    _rezip(tmp_path, lambda n, d: [(n, d)], "prior.fmu")
    doc = _raw("first_order")
    doc["prior"] = {"fmu": "prior.fmu", "parameters": {"a": 1.2}}
    _one_line(_write(tmp_path / "bad.yaml", doc), "prior.state_map", "nothing (default {})", "needs a state map")
    doc["prior"]["state_map"] = {"x0": "y"}
    prior = load_scenario(_write(tmp_path / "ok.yaml", doc)).tuning.prior
    assert Path(prior.fmu) == (tmp_path / "prior.fmu").resolve() and prior.state_map == {"x0": "y"}
    doc["prior"]["state_map"] = {"x9": "y"}
    _one_line(_write(tmp_path / "bad.yaml", doc), "prior.state_map.x9", "'x9'", "no variable 'x9'")


def test_a_sound_rebuilt_archive_is_accepted(tmp_path):
    """The archive checks refuse what is broken, not what is merely repacked."""
    _rezip(tmp_path, lambda n, d: [(n, d)])
    doc = _raw("first_order")
    doc["plant"]["fmu"] = "plant.fmu"
    s = load_scenario(_write(tmp_path / "ok.yaml", doc))
    assert Path(s.tuning.fmu) == (tmp_path / "plant.fmu").resolve()


def test_infinite_actuator_limits_are_allowed(tmp_path):
    doc = _raw("first_order")
    doc["plant"]["loops"][0]["u_limits"] = [-INF, INF]
    s = load_scenario(_write(tmp_path / "ok.yaml", doc))
    assert (s.tuning.loops[0].u_min, s.tuning.loops[0].u_max) == (-INF, INF)


def test_setpoint_steps_up_to_the_divergence_bound_are_allowed(tmp_path):
    """A step of exactly divergence_bound x measurement_scale is allowed (only a larger one ends the episode)."""
    doc = _raw("first_order")
    doc["plant"]["loops"][0]["divergence_bound"] = 2.0  # = the span of setpoint_range [-1, 1]
    doc["evaluation"]["setpoints"] = [{"at_step": 0, "value": 1.0}, {"at_step": 50, "value": -1.0},
                                      {"at_step": 100, "value": 1.0}]
    s = load_scenario(_write(tmp_path / "ok.yaml", doc))
    assert s.tuning.loops[0].divergence_bound == 2.0


# --------------------------------------------------------------------------------------------
# every mistake of a file at once

FOUR = """\
name: four
plant:
  fmu: FirstOrderUnstable
  sample_time: .inf
  loops:
    - {input: u, output: yy}
strategies: {smoothing_windw: 3}
agent: {extra: {max_grad_nrm: 0.5}}
"""
FOUR_KEYS = ["plant.sample_time", "plant.loops[0].output", "strategies.smoothing_windw", "agent.extra.max_grad_nrm"]


def test_four_mistakes_give_four_lines_in_file_order(tmp_path):
    path = _write(tmp_path / "four.yaml", FOUR)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    lines = info.value.lines
    assert lines == str(info.value).splitlines()
    assert [line.split(": ")[1] for line in lines] == FOUR_KEYS
    assert all(line.startswith(f"{path}: ") and "(got " in line and "; expected " in line for line in lines)


def test_each_mistake_alone_is_one_of_the_four(tmp_path):
    """Fixing all but one mistake leaves exactly that one line: the four are independent, not cascades."""
    fixes = {"plant.sample_time": ("sample_time: .inf", "sample_time: 0.1"),
             "plant.loops[0].output": ("output: yy", "output: y"),
             "strategies.smoothing_windw": ("smoothing_windw", "smoothing_window"),
             "agent.extra.max_grad_nrm": ("max_grad_nrm", "max_grad_norm")}
    for keep in FOUR_KEYS:
        text = FOUR
        for key, (bad, good) in fixes.items():
            if key != keep:
                text = text.replace(bad, good)
        with pytest.raises(ScenarioError) as info:
            load_scenario(_write(tmp_path / "one.yaml", text))
        assert [line.split(": ")[1] for line in str(info.value).splitlines()] == [keep]


# --------------------------------------------------------------------------------------------
# through the command line, in a real process

def _validate(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prlpid_fmi.cli", "validate", str(path)], capture_output=True,
                          text=True)


def test_cli_reports_all_mistakes_exit_2(tmp_path):
    path = _write(tmp_path / "four.yaml", FOUR)
    proc = _validate(path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 4
    for line, key in zip(lines, FOUR_KEYS):
        assert line.startswith(f"prlpid-fmi: error: {path}: {key}: "), line


@pytest.mark.parametrize("case", [c for c in CASES if c[0] in ("learning-rate-inf", "extra-unknown",
                                                               "randomize-an-output")],
                         ids=lambda c: c[0])
def test_cli_bad_value(case, tmp_path):
    _, base, edit, key, shown, word = case
    doc = copy.deepcopy(_raw(base))
    edit(doc, tmp_path)
    path = _write(tmp_path / "bad.yaml", doc)
    proc = _validate(path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    [line] = proc.stderr.strip().splitlines()
    assert line.startswith(f"prlpid-fmi: error: {path}: {key}: ") and f"(got {shown}; " in line and word in line


def test_cli_broken_archive_and_repeated_key(tmp_path):
    _rezip(tmp_path, _add("resources\\data.txt"))
    text = (SCENARIOS / "first_order.yaml").read_text().replace("fmu: FirstOrderUnstable", "fmu: plant.fmu")
    text = text.replace("  sample_time: 0.1                 # s\n", "  sample_time: 0.1\n  sample_time: 5.0\n")
    path = _write(tmp_path / "bad.yaml", text)
    proc = _validate(path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 2
    assert f"{path}: plant.fmu: unsafe member name" in lines[0]
    assert f"{path}: plant.sample_time: duplicate key at lines 5 and 6" in lines[1]
    assert zipfile.is_zipfile(tmp_path / "plant.fmu")  # validate reads the archive, never changes it


# --------------------------------------------------------------------------------------------
# any value anywhere: a ScenarioError with well-formed lines, never another exception

_ODD_VALUES = [None, -1, 0, 0.5, 1e9, "x", "", [], [1], [1, 2, 3], {}, {"q": 1}, True, INF, -INF, NAN, "3e-4",
               [None], {"a": None}]
_LINE = re.compile(r"^(?P<file>.+?): (?P<key>\S+): .+ \(got .+; expected .+\)$")


def _paths(node, path=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, path + (i,))
    if path:
        yield path


def test_random_values_anywhere_give_only_well_formed_lines(tmp_path):
    base = _raw("template")
    paths = list(_paths(base))
    rng = random.Random(7)
    path = tmp_path / "odd.yaml"
    refused = 0
    for _ in range(120):
        doc = copy.deepcopy(base)
        for _ in range(rng.randint(1, 3)):
            where = rng.choice(paths)
            node = doc
            try:
                for k in where[:-1]:
                    node = node[k]
                node[where[-1]] = copy.deepcopy(rng.choice(_ODD_VALUES))
            except (KeyError, IndexError, TypeError):
                pass  # an earlier edit replaced a parent
        _write(path, doc)
        try:
            load_scenario(path)
        except ScenarioError as exc:
            refused += 1
            for line in str(exc).splitlines():
                match = _LINE.match(line)
                assert match and match["file"] == str(path), line
    assert refused >= 100  # almost every such edit is a mistake


def test_an_fmi3_array_input_is_refused_by_name_at_inspect_and_validate(tmp_path):
    """An FMI 3 array variable (a <Dimension>) cannot be a loop's input: inspect says why the FMU cannot be a
    plant, and validate names the variable (before, inspect said "yes" and the first step failed in the FMU)."""
    from prlpid_fmi.fmu import describe_fmu

    scalar = b'causality="input" start="0.0" />'
    array = b'causality="input" start="0.0 0.0"><Dimension start="2" /></Float64>'

    def to_array(name, data):
        if name == MD:
            assert data.count(scalar) == 1
            data = data.replace(scalar, array)
        return [(name, data)]

    fmu = _rezip(tmp_path, to_array, fmi_version=3)
    d = describe_fmu(fmu)
    assert d.variable("u").dimensions == 1 and d.variable("y").dimensions == 0
    assert d.plant_problems() == ["no scalar real inputs (only arrays: u)"]
    doc = _raw("first_order")
    doc["plant"]["fmu"] = str(fmu)
    doc["strategies"]["forecast_horizon"] = 0
    with pytest.raises(ScenarioError) as info:
        load_scenario(_write(tmp_path / "array.yaml", doc))
    assert "plant.loops[0].input: 'u' is an array variable (FMI 3 dimensions) (got 'u'; expected a scalar real" \
        in str(info.value)
