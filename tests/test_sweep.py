"""prlpid-fmi sweep: sweep files (validation, one line per mistake), trials as run directories, restart without
re-running, resume of an unfinished trial, the summary's statistics against a hand computation, the local
process pool (the default) and Ray.

Ray 2.x removed ``ray.init(local_mode=True)`` (it raises "local_mode is no longer supported"), so the Ray test
runs the sweep on a new local Ray instance in this machine (``--ray`` without an address), which is what
local mode stood for: no cluster needed.
"""
from __future__ import annotations

import csv
import json
import math
import os
import textwrap
import types
from pathlib import Path

import pytest

from prlpid_fmi.cli import main
from prlpid_fmi.metrics import overall_metric
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.sweep import bundled_sweep_names, load_sweep, resolve_sweep, run_sweep, trial_status
from prlpid_fmi.sweep.runner import Trial, run_trial
from prlpid_fmi.sweep.summary import aggregate, band, curve_seeds, mean_ci

# the tiniest budget that still trains, tunes a fixed PID and evaluates every controller
TINY = """\
name: tiny
scenario: first_order
seeds: {seeds}
timesteps: 256
set:
  baseline: {{episodes: 1, maxiter: 1, popsize: 2}}
  agent: {{n_envs: 2, n_steps: 64, batch_size: 64, n_epochs: 2, checkpoint_every: 100000}}
  deploy: {{schedule_points: 3}}
vary:
  strategies.forecast_horizon: [0, 3]
"""
VARIANTS = ("forecast_horizon=0", "forecast_horizon=3")
T_975_DF1 = 12.706204736174705  # Student t, 97.5 % quantile, 1 degree of freedom (statistical tables)


def _write(path: Path, text: str) -> Path:
    path.write_text(textwrap.dedent(text))
    return path


def _lines(capsys) -> list[str]:
    return capsys.readouterr().err.strip().splitlines()


# -- sweep files -----------------------------------------------------------------------------------
def test_bad_sweep_file_gives_one_line_per_mistake(tmp_path, capsys):
    f = _write(tmp_path / "bad.yaml", """\
        scenario: first_order
        seeds: [0, -1, 4294967296]
        timesteps: 0
        colour: red
        set:
          strategies.forcast_horizon: 3
        variants:
          "a/b": {agent.algorithm: ppo}
        """)
    assert main(["sweep", str(f), "--out", str(tmp_path / "out")]) == 2
    assert _lines(capsys) == [
        f"prlpid-fmi: error: {f}: seeds[1]: out of range (got -1; expected an integer in [0, 2147483647])",
        f"prlpid-fmi: error: {f}: seeds[2]: out of range (got 4294967296; expected an integer in [0, 2147483647])",
        f"prlpid-fmi: error: {f}: timesteps: out of range (got 0; expected an integer >= 1 (training steps of every "
        "trial), or null for the scenario's budget)",
        f"prlpid-fmi: error: {f}: colour: unknown key (got 'colour'; expected a known key: one of name, scenario, "
        "seeds, timesteps, set, vary, variants)",
        f"prlpid-fmi: error: {f}: set.strategies.forcast_horizon: unknown scenario key (got "
        "'strategies.forcast_horizon'; expected a key of the scenario file, e.g. strategies.forecast_horizon; did you "
        "mean 'strategies.forecast_horizon'?)",
        f"prlpid-fmi: error: {f}: variants.a/b: not usable as a folder name (got 'a/b'; expected letters, digits and "
        "_ . + = , - (first a letter or digit))"]
    assert not (tmp_path / "out").exists()


def test_a_seed_count_beyond_any_study_is_refused_at_once(tmp_path, capsys):
    """seeds: 1e30 once built a list of 10**30 seeds (the process hung and ate the memory)."""
    f = _write(tmp_path / "many.yaml", "scenario: first_order\nseeds: 1e30\nvariants: {a: {agent.seed: 0}}\n")
    assert main(["sweep", str(f), "--out", str(tmp_path / "out")]) == 2
    assert _lines(capsys) == [
        f"prlpid-fmi: error: {f}: seeds: out of range (got 1.0e+30; expected a number of seeds from 1 to 1000, or a "
        "list of seeds from 0 to 2147483647)"]
    assert not (tmp_path / "out").exists()


def test_validate_checks_a_sweep_file_as_a_sweep(tmp_path, capsys):
    """validate once read a sweep file as a scenario: four lines on `scenario`, `seeds`, ... being unknown."""
    good = _write(tmp_path / "good.yaml", """\
        scenario: first_order
        seeds: [3, 7]
        timesteps: 64
        vary: {strategies.forecast_horizon: [0, 3, 5]}
        """)
    assert main(["validate", str(good)]) == 0
    assert capsys.readouterr().out.strip() == (
        f"{good}: ok: sweep good: 3 variant(s) x 2 seed(s) = 6 trials of "
        f"{load_sweep(good).base}, 64 training steps each")
    assert main(["validate", "fig3_algorithms"]) == 0  # a bundled sweep by name: 4 algorithms x 5 seeds
    assert "ok: sweep fig3_algorithms: 4 variant(s) x 5 seed(s) = 20 trials" in capsys.readouterr().out
    bad = _write(tmp_path / "bad.yaml", "scenario: first_order\nseeds: 1\nset: {plant.loops.0.input: u}\n")
    assert main(["validate", str(bad)]) == 2
    assert _lines(capsys) == [
        f"prlpid-fmi: error: {bad}: set.plant.loops.0.input: not a scenario key path (got 'plant.loops.0.input'; "
        "expected dotted names with optional [index], e.g. strategies.forecast_horizon; did you mean "
        "'plant.loops[0].input'?)"]


def test_sweep_file_syntax_errors_say_what_the_parser_found(tmp_path, capsys):
    """One line each, with the parser's problem (before: only 'not valid YAML at line 2', and a traceback for
    binary data in the scenario reader's place)."""
    flow = _write(tmp_path / "flow.yaml", "scenario: first_order\nvariants: {a: {plant.loops[0].input: u}}\n")
    looped = _write(tmp_path / "looped.yaml", "scenario: first_order\nvariants: &v {a: *v}\n")
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\xff\xfe\x00")
    for f in (flow, looped, binary):
        assert main(["sweep", str(f), "--out", str(tmp_path / "out")]) == 2
    assert _lines(capsys) == [
        f"prlpid-fmi: error: {flow}: (top level): not valid YAML at line 2, column 27: expected ',' or '}}', but got "
        "'[' (got unparsable text; expected a YAML mapping)",
        f"prlpid-fmi: error: {looped}: (top level): not valid YAML at line 2, column 11: this anchor is used inside "
        "itself (an alias to it within it: the data would contain itself) (got unparsable text; expected a YAML "
        "mapping)",
        f"prlpid-fmi: error: {binary}: (top level): not a text file (got binary data; expected UTF-8 YAML)"]
    assert not (tmp_path / "out").exists()


def test_every_failing_variant_is_reported_at_once(tmp_path, capsys):
    f = _write(tmp_path / "bad.yaml", """\
        scenario: first_order
        seeds: 2
        set:
          controller.gain_mapping: absolut
          strategies.smoothing_alpha: 0.3
        vary:
          strategies.forecast_horizon: [0, -1]
          strategies.smoothing: [era, sma]
        variants:
          A: {agent.algorithm: ppx}
          B: {agent.algorithm: ppo, "plant.loops[2].u_limits": [0, 1]}
        """)
    with pytest.raises(PrlPidError) as info:
        load_sweep(f)
    assert str(info.value).splitlines() == [
        f"{f}: set: controller.gain_mapping: unknown gain mapping (got 'absolut'; expected one of anchored, absolute; "
        "did you mean 'absolute'?)",
        f"{f}: variants.A: agent.algorithm: unknown algorithm (got 'ppx'; expected one of ppo, sac, td3; did you mean "
        "'ppo'?)",
        # alpha is fine for era and wrong for sma: only those variants (4 of 8)
        f"{f}: set (in 4 of 8 variants, e.g. A,forecast_horizon=0,smoothing=sma): strategies.smoothing_alpha: smoothing "
        "'sma' takes no alpha (got 0.3; expected null, or smoothing lwma / era)",
        f"{f}: vary: strategies.forecast_horizon: out of range (got -1; expected an integer >= 0)",
        f"{f}: variants.B: plant.loops[2].u_limits: no such item in the base scenario {resolve_base('first_order')} "
        "(got index 2; expected an index below 1, the number of items of plant.loops)"]
    assert main(["sweep", str(f), "--out", str(tmp_path / "out")]) == 2
    assert len(_lines(capsys)) == 5 and not (tmp_path / "out").exists()


def resolve_base(name: str) -> Path:
    from prlpid_fmi.scenario.presets import scenario_path

    return scenario_path(name)


def test_variants_merge_into_the_base_scenario(tmp_path):
    """set, then the named variant, then the vary combination; a mapping merges into the base's mapping."""
    f = _write(tmp_path / "s.yaml", """\
        scenario: two_tank
        seeds: 1
        set:
          plant.parameters: {h1_0: 12.0}
          "plant.loops[0].setpoint_range": [6, 14]
        variants:
          slow: {agent: {learning_rate: 0.0001}}
          fast: {agent.learning_rate: 0.001}
        vary:
          agent.algorithm: [ppo, sac]
        """)
    sweep = load_sweep(f)
    base = load_scenario(resolve_base("two_tank"))
    assert [v.name for v in sweep.variants] == ["slow,algorithm=ppo", "slow,algorithm=sac", "fast,algorithm=ppo",
                                                "fast,algorithm=sac"]
    for v in sweep.variants:
        t, a = v.scenario.tuning, v.scenario.agent
        assert t.plant_parameters == {**base.tuning.plant_parameters, "h1_0": 12.0}  # the base's others kept
        assert len(t.plant_parameters) > 1
        assert t.loops[0].setpoint_range == (6.0, 14.0) and t.loops[0].u_max == 50.0
        assert a.learning_rate == (1e-4 if v.name.startswith("slow") else 1e-3)
        assert a.seed == 0 and a.total_timesteps == 500_000  # the base's: every trial sets its own seed
        assert a.algorithm == v.name.rsplit("=", 1)[1]
        assert v.scenario.evaluation.intervals == ((0, 200), (200, 400), (400, 600), (600, 800))


def test_bundled_sweeps_are_the_paper_studies():
    names = bundled_sweep_names()
    experiments = {"first_order", "second_order", "first_order_1p5", "time_varying", "two_tank", "quadrotor"}
    assert {f"experiment_{e}" for e in experiments} | {"fig3_algorithms", "fig4_5_forecast_horizon", "fig6_smoothing",
                                                      "fig7_generalisation", "table2_ablation_two_tank",
                                                      "smoke"} == set(names)
    for name in names:
        sweep = load_sweep(resolve_sweep(name))
        if name == "smoke":
            continue
        assert sweep.seeds == (0, 1, 2, 3, 4) and sweep.timesteps is None, name
        assert {v.scenario.agent.total_timesteps for v in sweep.variants} == {500_000}, name  # the paper's budget
        text = resolve_sweep(name).read_text()
        assert "gain_mapping" in text.split("name:")[0], name  # the comment says which map and why
        if name.startswith("experiment_"):
            assert {v.scenario.tuning.gain_mapping for v in sweep.variants} == {"absolute", "anchored"}
            # the paper variant runs eq. 2's positional gain change, the tool's own the bumpless default
            assert {(v.scenario.tuning.gain_mapping, v.scenario.tuning.gain_change) for v in sweep.variants} == {
                ("absolute", "positional"), ("anchored", "bumpless")}, name
        else:  # studies of the paper's own method, with its PID law
            assert {v.scenario.tuning.gain_mapping for v in sweep.variants} == {"absolute"}, name
            assert {v.scenario.tuning.gain_change for v in sweep.variants} == {"positional"}, name

    def knobs(name):
        return [(v.scenario.agent.algorithm, v.scenario.tuning.forecast_horizon, v.scenario.tuning.smoothing)
                for v in load_sweep(resolve_sweep(name)).variants]

    assert knobs("fig3_algorithms") == [("ppo", 3, "era"), ("ppo", 0, "none"), ("td3", 0, "none"), ("sac", 0, "none")]
    assert [k[1] for k in knobs("fig4_5_forecast_horizon")] == [0, 1, 3, 5, 10]
    assert [k[2] for k in knobs("fig6_smoothing")] == ["none", "sma", "lwma", "era"]
    ablation = {("ppo", 0, "none"), ("ppo", 3, "none"), ("ppo", 0, "era"), ("ppo", 3, "era")}
    assert set(knobs("fig7_generalisation")) == ablation == set(knobs("table2_ablation_two_tank"))


def test_trial_status(tmp_path):
    d = tmp_path / "t"
    assert trial_status(d) == "new"
    d.mkdir()
    assert trial_status(d) == "new"
    (d / "scenario.yaml").write_text("x")
    assert trial_status(d) == "stale"  # started, never wrote run.json: starts over
    (d / "run.json").write_text(json.dumps({"started": "2026"}))
    assert trial_status(d) == "unfinished"
    (d / "run.json").write_text(json.dumps({"started": "2026", "finished": "2026"}))
    assert trial_status(d) == "finished"


def test_statistics_against_hand_computation():
    n, mean, half = mean_ci([1.0, 3.0])
    assert (n, mean) == (2, 2.0) and half == pytest.approx(T_975_DF1 * 1.0)  # s = sqrt(2), s / sqrt(2) = 1
    n, mean, half = mean_ci([2.0, 4.0, 6.0, math.inf])  # t(0.975, 2) = 4.302652729911275; s = 2
    assert (n, mean) == (3, 4.0) and half == pytest.approx(4.302652729911275 * 2 / math.sqrt(3))
    assert mean_ci([5.0])[0:2] == (1, 5.0) and math.isnan(mean_ci([5.0])[2])
    # NaN = not defined (no segment there): not a seed's value; inf = failed (never settles): counted, not averaged
    rows = [{"variant": "v", "controller": "policy", "interval": "overall", "metric": "SettlingTime", "value": v,
             "ended_early": False} for v in (math.nan, math.inf, 2.0, 4.0)]
    (stat,) = aggregate(rows, ["v"])
    assert (stat["n"], stat["n_finite"], stat["mean"]) == (3, 2, 3.0)
    assert stat["ci95_half_width"] == pytest.approx(T_975_DF1 * 1.0)
    grid, m, s = band([([0.0, 10.0], [0.0, 10.0]), ([0.0, 5.0, 12.0], [2.0, 7.0, 14.0])], points=3)
    assert list(grid) == [0.0, 5.0, 10.0]  # the steps both curves cover
    assert list(m) == [1.0, 6.0, 11.0] and list(s) == [1.0, 1.0, 1.0]
    # a variant's band comes from its finished trials once one has finished (an interrupted sweep: an unfinished
    # trial would cut the finished curves to its few steps); before that, from every seed
    sweep = types.SimpleNamespace(seeds=(0, 1, 2, 3, 4))
    assert curve_seeds(sweep, "SAC", {"SAC": [0], "TD3": [0, 1]}) == (0,)
    assert curve_seeds(sweep, "SAC", {"TD3": [0, 1]}) == (0, 1, 2, 3, 4)


# -- running ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    """The tiny sweep (2 variants x 2 seeds) run once with the defaults: local processes, one per core."""
    base = tmp_path_factory.mktemp("sweep")
    f = _write(base / "tiny.yaml", TINY.format(seeds=2))
    out = base / "out"
    assert main(["-q", "sweep", str(f), "--out", str(out)]) == 0
    return f, out


def _read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_every_trial_is_a_run_directory(local_sweep):
    f, out = local_sweep
    info = json.loads((out / "sweep.json").read_text())
    (inv,) = info["invocations"]
    assert inv["backend"] == "local" and inv["workers"] == min(os.cpu_count(), 4) and inv["trials_run"] == 4
    assert inv["failed"] == {}
    for variant, horizon in zip(VARIANTS, (0, 3)):
        for seed in (0, 1):
            run = out / variant / f"seed{seed}"
            run_info = json.loads((run / "run.json").read_text())
            assert "finished" in run_info and run_info["seed"] == seed and run_info["total_timesteps"] == 256
            scenario = load_scenario(run / "scenario.yaml")
            assert (scenario.tuning.forecast_horizon, scenario.agent.seed) == (horizon, seed)
            for name in ("metrics.json", "model.zip", "fixed_pid.json", "report.md", "schedule.csv"):
                assert (run / name).is_file(), (run, name)
            assert list((run / "monitor").glob("*.monitor.csv"))


def test_summary_is_the_mean_and_t_interval_of_the_trials(local_sweep):
    """summary.csv against the trials' own metrics.json, with t(0.975, 1) from a table."""
    f, out = local_sweep
    rows = {(r["variant"], r["controller"], r["interval"], r["metric"]): r for r in _read_csv(out / "summary.csv")}
    for variant in VARIANTS:
        ms = [json.loads((out / variant / f"seed{s}" / "metrics.json").read_text()) for s in (0, 1)]
        for controller, pick in {
            "policy": lambda m: m["policy"],
            "schedule": lambda m: m["schedule_replay"]["metrics"],
            "fixed_pid": lambda m: m["fixed_pid"]["metrics"],
            "deployed": lambda m: (m["schedule_replay"] if m["deployed"] == "gain schedule"
                                   else m["fixed_pid_assessment"])["metrics"],
        }.items():
            for metric in ("ISE", "IAE", "Overshoot", "SettlingTime"):
                for interval, get in (("overall", lambda m: m["overall"]), ("0-200", lambda m: m["intervals"][0])):
                    x1, x2 = (overall_metric(get(pick(m)), metric) for m in ms)
                    r = rows[(variant, controller, interval, metric)]
                    assert (int(r["n"]), int(r["n_finite"])) == (2, 2)
                    assert float(r["mean"]) == pytest.approx((x1 + x2) / 2, rel=1e-12)
                    assert float(r["ci95_half_width"]) == pytest.approx(T_975_DF1 * abs(x1 - x2) / 2, rel=1e-9)
    md = (out / "summary.md").read_text()
    assert "| forecast_horizon=3 | `strategies.forecast_horizon: 3` | 2 |" in md
    for png in ("learning_curves.png", "metrics.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_restart_runs_nothing_again_and_resumes_an_unfinished_trial(local_sweep, capsys):
    f, out = local_sweep
    runs = [out / v / f"seed{s}" for v in VARIANTS for s in (0, 1)]
    stamps = {p: p.stat().st_mtime_ns for r in runs for p in (r / "run.json", r / "metrics.json", r / "model.zip")}
    metrics_before = (runs[3] / "metrics.json").read_text()
    # the last trial stopped after training (run.json has no "finished"): only it runs again
    info = json.loads((runs[3] / "run.json").read_text())
    del info["finished"]
    (runs[3] / "run.json").write_text(json.dumps(info))
    stamps[runs[3] / "run.json"] = (runs[3] / "run.json").stat().st_mtime_ns

    assert main(["sweep", str(f), "--out", str(out), "--workers", "1"]) == 0
    err = capsys.readouterr().err
    assert "3 finished earlier, 1 to run on 1 local process(es)" in err
    assert "[1/1] forecast_horizon=3/seed1: resumed in" in err
    changed = {p for p, t in stamps.items() if p.stat().st_mtime_ns != t}
    assert changed == {runs[3] / "run.json", runs[3] / "metrics.json"}  # model.zip: no training left to do
    resumed = json.loads((runs[3] / "run.json").read_text())
    assert "resumed" in resumed and "finished" in resumed
    assert json.loads((runs[3] / "metrics.json").read_text()) == json.loads(metrics_before)  # same policy, same numbers
    assert [i["trials_run"] for i in json.loads((out / "sweep.json").read_text())["invocations"]] == [4, 1]

    # a sweep file changed since: refused before anything runs, naming what differs
    _write(f, TINY.format(seeds=2).replace("timesteps: 256", "timesteps: 300"))
    assert main(["sweep", str(f), "--out", str(out)]) == 2
    lines = _lines(capsys)
    assert len(lines) == 4 and all("agent.total_timesteps: differs from the sweep's variant" in l for l in lines)
    assert lines[0] == (f"prlpid-fmi: error: {runs[0] / 'scenario.yaml'}: agent.total_timesteps: differs from the "
                        "sweep's variant forecast_horizon=0 (got 256; expected 300: the sweep file changed since this "
                        "trial ran; use another --out)")
    _write(f, TINY.format(seeds=2))


def test_sweep_arguments(tmp_path, capsys):
    f = _write(tmp_path / "tiny.yaml", TINY.format(seeds=1))
    assert main(["sweep", str(f), "--workers", "0"]) == 2
    assert _lines(capsys) == ["prlpid-fmi: error: --workers: must be at least 1 (got 0; expected a number of "
                              "processes >= 1)"]
    assert main(["sweep", str(f), "--workers", "2", "--ray"]) == 2
    assert "--workers: not used with --ray" in _lines(capsys)[0]
    assert main(["sweep", "no_such_sweep"]) == 2
    assert _lines(capsys)[0].startswith("prlpid-fmi: error: no_such_sweep: no such sweep file or bundled sweep "
                                        "(got 'no_such_sweep'; expected a path to a .yaml file or one of: "
                                        "experiment_first_order, ")


def test_a_failed_trial_is_a_result_not_a_crash(tmp_path):
    """run_trial (what each worker runs) reports a trial that cannot run as one line and leaves no folder."""
    trial = Trial("v", 0, str(tmp_path / "gone.yaml"), str(tmp_path / "v" / "seed0"), 256)
    result = run_trial(trial)
    assert result["status"] == "failed" and result["error"] == (
        f"{tmp_path / 'gone.yaml'}: scenario file not found (got '{tmp_path / 'gone.yaml'}'; expected a path to a "
        ".yaml file)")
    assert not (tmp_path / "v").exists()


def test_an_unreachable_ray_address_is_one_line_before_anything_is_written(tmp_path, capsys):
    pytest.importorskip("ray", reason="Ray is not installed (pip install \"prlpid-fmi[ray]\")")
    import socket

    with socket.socket() as s:  # a port nobody listens on: bound, never listening
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        f = _write(tmp_path / "tiny.yaml", TINY.format(seeds=1))
        assert main(["sweep", str(f), "--out", str(tmp_path / "out"), "--ray", f"127.0.0.1:{port}"]) == 2
    assert _lines(capsys) == [f"prlpid-fmi: error: --ray 127.0.0.1:{port}: cannot reach a Ray cluster there (got "
                              "Connection refused; expected the address of a running Ray cluster: host:6379, "
                              "ray://host:10001 or auto)"]
    assert not (tmp_path / "out").exists()


def test_ray_runs_the_same_trials(local_sweep, tmp_path):
    """On a new local Ray instance, seed 0 of both variants gives the very numbers the local processes gave."""
    pytest.importorskip("ray", reason="Ray is not installed (pip install \"prlpid-fmi[ray]\")")
    f = _write(tmp_path / "tiny.yaml", TINY.format(seeds="[0]"))
    result = run_sweep(f, out=tmp_path / "out", ray=True)
    assert result.failed == []
    (inv,) = json.loads((tmp_path / "out" / "sweep.json").read_text())["invocations"]
    assert inv["backend"] == "ray" and inv["trials_run"] == 2
    local = [r for r in _read_csv(local_sweep[1] / "trials.csv") if r["seed"] == "0"]
    assert _read_csv(tmp_path / "out" / "trials.csv") == local and len(local) == 2 * 4 * 2 * 6


def test_ctrl_c_writes_the_summary_of_the_finished_trials(local_sweep, tmp_path, monkeypatch, capsys):
    import shutil

    import prlpid_fmi.sweep.runner as runner

    def ctrl_c(trials, workers):  # the pool's behaviour on Ctrl-C: the running trials stop, it re-raises
        raise KeyboardInterrupt
        yield

    f, finished = local_sweep
    out = tmp_path / "out"
    shutil.copytree(finished, out)
    shutil.rmtree(out / VARIANTS[1] / "seed1")  # one trial left to run
    monkeypatch.setattr(runner, "run_local", ctrl_c)
    assert main(["sweep", str(f), "--out", str(out), "--workers", "1"]) == 130
    err = capsys.readouterr().err
    assert "sweep tiny: interrupted after " in err and "the same command continues the sweep" in err
    summary = (out / "summary.md").read_text()
    assert "Finished trials: 3 of 4." in summary and "| 0 (interrupted) |" in summary


def test_sigterm_stops_the_workers_and_writes_the_summary(tmp_path):
    # a job manager or `timeout` stops a sweep with SIGTERM: before, the workers were orphaned and ran on
    import signal
    import subprocess
    import sys

    f, out = _write(tmp_path / "tiny.yaml", TINY.format(seeds=1)), tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "prlpid_fmi", "sweep", str(f), "--out", str(out), "--workers", "1"],
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    lines = []
    for line in proc.stderr:
        lines.append(line)
        if line.startswith("[1/2]"):
            break
    children = [int(p) for p in Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()]
    assert children  # the worker (and multiprocessing's resource tracker)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=120) == 128 + signal.SIGTERM  # (killed by the signal: -15)
    rest = proc.communicate(timeout=60)[1]
    assert "sweep tiny: interrupted after" in rest and "interrupted by SIGTERM" in rest and "Traceback" not in rest
    assert [pid for pid in children if _still_running(pid)] == []
    summary = (out / "summary.md").read_text()
    assert "Finished trials: 1 of 2." in summary and "| 1 (interrupted) |" in summary


WORKER_SIGNALS = """\
import os, signal, sys, time
from prlpid_fmi.errors import Interrupted
from prlpid_fmi.sweep import runner

runner._local_worker()
if sys.argv[1] == "in-trial":
    runner._WORKER["in_trial"] = True
    try:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    except Interrupted:
        print("unwinding", flush=True)
    os.kill(os.getpid(), signal.SIGTERM)  # a second one while the trial unwinds: ignored
    time.sleep(0.2)
    print("unwound", flush=True)
else:  # between trials: e.g. the executor sending a finished trial's result, which catches BaseException
    try:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    except BaseException:
        pass
    print("still running", flush=True)
"""


def test_a_worker_stopped_between_trials_exits_at_once(tmp_path):
    """Before: SIGTERM raised Interrupted wherever it landed; landing in the executor's own code (sending trial 1's
    result back) it was caught there, the handler had switched SIGTERM off, and the worker ran trial 2 to its end
    after the sweep had stopped (seen as a flaky SIGTERM test; an hour of both cores for a SAC trial)."""
    import subprocess
    import sys

    script = _write(tmp_path / "worker.py", WORKER_SIGNALS)
    between = subprocess.run([sys.executable, str(script), "between"], capture_output=True, text=True, timeout=60)
    assert (between.returncode, between.stdout) == (143, "")
    during = subprocess.run([sys.executable, str(script), "in-trial"], capture_output=True, text=True, timeout=60)
    assert (during.returncode, during.stdout) == (0, "unwinding\nunwound\n")


def _still_running(pid: int, wait_s: float = 15.0) -> bool:
    """Whether process `pid` is still running (not gone, not a zombie) after up to wait_s seconds: the
    resource tracker ends a moment after the sweep's process, when its pipe closes."""
    import time

    status = Path(f"/proc/{pid}/status")
    end = time.monotonic() + wait_s
    while time.monotonic() < end:
        try:
            if "\nState:\tZ" in status.read_text():
                return False
        except FileNotFoundError:
            return False
        time.sleep(0.2)
    return True
