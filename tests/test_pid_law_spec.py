"""Every implementation of the PID law against one specification: the cases of tests/pid_law_cases.py.

The truth is the literal expected u of each case (hand-checked arithmetic; `exact_u` recomputes it
in exact rational arithmetic without prlpid_fmi). Compared: exactly (`==`) when all of a case's
numbers are dyadic, so that no implementation rounds; otherwise to 1e-12 relative (1e-12 absolute
near zero).

1. Python: prlpid_fmi.control.PID with the case's structure (b, c, Tf per loop, the filter order) and
   rate limits R, driven open loop with the case's r, y and per-sample gains (preset_output at y(0)
   with u_start before the first step, always, as LoopCore does). Every case.
2. The exported C controller (formats.render(..., "c") of export.controller.from_schedule), compiled
   once per module with gcc into one driver for all cases, driven open loop through stdin. The case
   becomes a gain table: one row for constant gains, or, when the gains change with the setpoint of
   loop 1, a row per setpoint value (the table is then looked up exactly at its breakpoints); the
   table carries the case's b, c, Tf, filter order and rate limits, which the export turns into
   constants; the block is reset with the case's u_start (its first sample presets from it).
   Skipped, with the reason: Ti = inf (from_schedule refuses non-finite gains) and a given Tt (the
   exports always use the default rule); `test_the_export_skip_reasons_still_hold` fails once either
   reason goes away.
3. The exported Structured Text (the same table rendered as "st"), run by tests/st_interpreter.py;
   parsed once per module, each statement body text once (blark takes seconds per block; see
   the st_blocks fixture).
4. The C reward forecast (plant_sources/common/forecast.c through NativeForecast) and, beside it,
   the FMI-path forecast (FmiForecast, which steps the Python PID). The forecast rolls a prior FMU
   out from a measurement with constant setpoint and gains, so it cannot take an arbitrary y
   sequence; but with tests/plants/StaticValve built with Kv = 1 (q = opening, no dynamics) as the
   prior, the predicted measurements are the PID's outputs: y(k+1) = u(k). Every case marked
   `static_gain` is such a closed loop (its y are the previous u), and both forecasts must predict
   its u(0..n-1) from y(0). Only those cases (single loop, constant r and gains) are checked this
   way; the others are skipped with the reason. FMI 2.0 build only (forecast.c is the same code
   under every FMI version, and tests/test_native.py compares native and FMI paths bit for
   bit for both versions). The PID is preset (at y(0), from u_start) before the forecast is called,
   as LoopCore does; the forecast itself rolls out from the state it is given.

Cases with gain_change "bumpless" run the rescale of a gain change (PID(gain_change="bumpless"), the exports'
table with that law); cases with an `imposed` output run PID.track_values at those samples, and the exports'
manual or tracking input (C: <name>_step_modes, ST: Manual/ManualValue or Track/TrackValue).

`test_each_mutation_of_the_law_is_caught` shows the cases can fail: each deliberately wrong law of
pid_law_cases.MUTATIONS (a derivative kick on the first sample, clamping that never holds the sum,
...) changes the expected numbers of at least one case, so an implementation with that error fails.
"""
from __future__ import annotations

import dataclasses
import math
import shutil
import subprocess
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from pid_law_cases import CASES, INF, MUTATIONS, exact_u

IDS = [case.name for case in CASES]
BY_NAME = {case.name: case for case in CASES}
REL = 1e-12
# tests/test_formats.py's flags: every warning is an error (a one-row table once tripped -Warray-bounds in the
# interpolation branch of lookup(), which the template now leaves out for one row)
GCC = ["gcc", "-std=c99", "-O2", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-ffp-contract=off"]
STATIC_VALVE = Path(__file__).parent / "plants" / "StaticValve"


# -- comparing with the spec ---------------------------------------------------------------------

def _numbers(case) -> list:
    values = [case.dt] + ([case.N] if case.N is not None else [])
    for loop in case.loops:
        values += [*loop.r, *loop.y, *loop.u, loop.u_min, loop.u_max, loop.u_start, loop.b, loop.c, loop.Tf, loop.R]
        values += [g for gains in loop.gains for g in gains] + ([loop.Tt] if loop.Tt is not None else [])
    return [v for v in values if math.isfinite(v)]


def _exact(case) -> bool:
    """All numbers dyadic with small denominators (<= 2^32): the floating-point arithmetic is exact."""
    return all(Fraction(v).denominator <= 2 ** 32 for v in _numbers(case))


def _check(where: str, case, got) -> None:
    """got[loop][k] against the case's expected u; lists every disagreement (case, loop, step, expected, got)."""
    exact = _exact(case)
    bad = []
    for i, loop in enumerate(case.loops):
        values = list(got[i])
        if len(values) != case.steps:
            bad.append(f"loop {i + 1}: {len(values)} outputs for {case.steps} samples")
        for k, (g, x) in enumerate(zip(values, loop.u)):
            if not (g == x if exact else math.isclose(g, x, rel_tol=REL, abs_tol=REL)):
                bad.append(f"loop {i + 1}, step {k}: expected {x!r}, got {float(g)!r}")
    how = "exactly" if exact else f"to {REL} relative"
    assert not bad, f"{where} disagrees with the spec case {case.name!r} ({how}):\n  " + "\n  ".join(bad)


def _per_sample(case, k: int):
    """(r, y, Kp, Ti, Td) of sample k, one list entry per loop."""
    r = [loop.r[k] for loop in case.loops]
    y = [loop.y[k] for loop in case.loops]
    Kp, Ti, Td = ([loop.gains[k][j] for loop in case.loops] for j in range(3))
    return r, y, Kp, Ti, Td


# -- the spec itself -----------------------------------------------------------------------------

@pytest.mark.parametrize("name", IDS)
def test_expected_numbers_follow_the_exact_law(name):
    """The literal u are the exact law, correctly rounded; closed-loop cases are what they claim."""
    case = BY_NAME[name]
    exact = exact_u(case)
    for i, loop in enumerate(case.loops):
        assert list(loop.u) == [float(v) for v in exact[i]], f"loop {i + 1}"
    if case.static_gain is not None:
        g = case.static_gain
        (loop,) = case.loops
        assert len(set(loop.r)) == 1 and case.constant_gains
        assert all(loop.y[k + 1] == g * loop.u[k] for k in range(case.steps - 1))


def test_the_cases_cover_what_they_claim():
    by = BY_NAME

    def hits_limit(case):
        return any(u in (loop.u_min, loop.u_max) for loop in case.loops for u in loop.u)

    for name in ("p_only", "pi_clamping", "pid_back_calculation", "pi_back_calculation_given_tt",
                 "pd_without_integral", "bumpless_start", "gain_change", "two_loops"):
        assert hits_limit(by[name]), name
    assert {c.anti_windup for c in CASES} == {"clamping", "back_calculation", "none"}
    assert any(c.N is not None for c in CASES) and any(c.n_loops == 2 for c in CASES)
    assert any(INF in g for c in CASES for l in c.loops for g in l.gains)
    assert not by["gain_change"].constant_gains
    start = by["bumpless_start"].loops[0]
    assert start.u_start != 0 and start.r[0] == start.y[0] and start.u[0] == start.u_start
    assert by["pi_back_calculation_given_tt"].loops[0].Tt is not None
    assert any(math.isinf(l.u_max) for c in CASES for l in c.loops)  # unbounded output
    assert not _exact(by["two_loops"]) and sum(_exact(c) for c in CASES) == len(CASES) - 1
    # the cases of paper eq. 2 (written before the 2-DOF law) are kept; the 2-DOF ones each vary the structure
    assert [c.name for c in CASES if c.eq2] == IDS[:10]
    assert by["setpoint_weight"].loops[0].b == 0.5 and by["setpoint_weight"].loops[0].y[0] == 0.0  # step from rest
    dm = by["derivative_on_measurement"].loops[0]
    assert dm.c == 0.0 and dm.r[1] != dm.r[2] and dm.y[1] == dm.y[2] and dm.gains[2][2] > 0  # a step, y still
    for name, order in (("measurement_filter_first_order", 1), ("measurement_filter_second_order", 2)):
        case = by[name]
        assert case.filter_order == order and case.loops[0].Tf > 0 and case.loops[0].y[0] != 0  # starts at y(0) != 0
    start = by["bumpless_setpoint_weight"].loops[0]
    assert start.b != 1 and start.r[0] == start.y[0] != 0 and start.u[0] == start.u_start
    two = by["two_loops_structure"].loops
    assert two[0].Tf > 0 and two[1].Tf == 0 and two[0].b != two[1].b and two[0].c != two[1].c
    # the preset at y(0): a setpoint step at t = 0 from a steady start acts through b; a zero start is preset too
    step = by["preset_setpoint_step"]
    (loop,) = step.loops
    assert loop.b != 1 and loop.r[0] != loop.y[0] and loop.u_start != 0 and loop.y[0] == step.static_gain * loop.u_start
    assert loop.u[0] == loop.u_start + loop.gains[0][0] * loop.b * (loop.r[0] - loop.y[0]) \
        + loop.gains[0][0] / loop.gains[0][1] * (loop.r[0] - loop.y[0]) * step.dt
    (loop,) = by["preset_zero_start"].loops
    assert loop.u_start == 0 and loop.b != 1 and loop.r[0] == loop.y[0] != 0 and loop.u[0] == 0
    # the rate limit binds inside the limits (the band, not u_min/u_max, saturates), under both anti-windups
    for name, mode in (("rate_limit_clamping", "clamping"), ("rate_limit_back_calculation", "back_calculation")):
        case = by[name]
        (loop,) = case.loops
        assert case.anti_windup == mode and loop.R < INF and case.static_gain is not None
        steps = [abs(u - v) for u, v in zip(loop.u, (loop.u_start,) + loop.u[:-1])]
        assert max(steps) == loop.R * case.dt and all(s <= loop.R * case.dt for s in steps)
        assert all(loop.u_min < u < loop.u_max for u in loop.u)
    assert by["rate_limit_back_calculation"].loops[0].u_start != 0  # the band starts around u_start
    # the bumpless gain change: a change with b != 1 and D != 0 at the sample before (P and D terms absorbed), one
    # while saturated, a sign change of Kp, one to and from Ki = 0; manual and tracking (beyond a limit), both laws
    (loop,) = by["bumpless_gain_step"].loops
    assert loop.b != 1 and loop.gains[1] != loop.gains[2] and loop.y[1] != loop.y[0]
    (loop,) = by["bumpless_saturated"].loops
    k = loop.gains.index(loop.gains[-1])
    assert loop.u[k - 1] == loop.u[k] == loop.u_max and loop.u[-1] < loop.u_max
    (loop,) = by["bumpless_sign_change"].loops
    assert loop.gains[0][0] > 0 > loop.gains[-1][0]
    assert [g[1] for g in by["bumpless_without_integral"].loops[0].gains].count(INF) == 2
    assert {l.imposed_by for c in CASES for l in c.loops if l.imposed is not None} == {"manual", "track"}
    (loop,) = by["track_to_auto"].loops
    assert max(v for v in loop.imposed if v is not None) > loop.u_max and loop.R < INF
    assert {c.gain_change for c in CASES} == {"positional", "bumpless"}


CAUGHT_BY = {"derivative_kick": "pid_first_sample", "integrate_while_saturated": "pi_clamping",
             "hold_sum_whenever_saturated": "two_loops", "no_tracking": "pid_back_calculation",
             "tracking_time_is_ti": "pi_back_calculation_given_tt", "tracking_time_sqrt_without_td": "bumpless_start",
             "unfiltered": "pid_derivative_filter", "cold_start": "bumpless_start", "first_gains_held": "gain_change",
             "sum_without_current_error": "pi_clamping", "proportional_on_error": "setpoint_weight",
             "derivative_on_error": "derivative_on_measurement", "unfiltered_measurement": "measurement_filter_first_order",
             "integral_on_filtered": "measurement_filter_first_order", "one_filter_section": "measurement_filter_second_order",
             "filter_from_zero": "measurement_filter_first_order", "kick_at_start": "bumpless_setpoint_weight",
             "preset_at_setpoint": "preset_setpoint_step", "preset_only_with_u_start": "preset_zero_start",
             "no_rate_limit": "rate_limit_clamping", "anti_windup_ignores_rate": "rate_limit_back_calculation",
             "no_rescale": "bumpless_gain_step", "rescale_without_p": "bumpless_gain_step",
             "rescale_without_d": "bumpless_gain_step", "rescale_to_clipped_output": "bumpless_saturated",
             "imposed_without_balance": "manual_to_auto", "imposed_not_clipped": "track_to_auto"}


@pytest.mark.parametrize("mutation", MUTATIONS)
def test_each_mutation_of_the_law_is_caught(mutation):
    """A wrong law gives other numbers for the named case (so an implementation of it fails that case)."""
    case = BY_NAME[CAUGHT_BY[mutation]]
    wrong = exact_u(case, mutation)
    assert [[float(v) for v in us] for us in wrong] != [list(loop.u) for loop in case.loops]


# -- 1. Python ------------------------------------------------------------------------------------

def _python_pid(case):
    from prlpid_fmi.control import PID

    Tts = [loop.Tt for loop in case.loops]
    assert all(t is None for t in Tts) or all(t is not None for t in Tts)
    return PID(case.dt, case.n_loops, [l.u_min for l in case.loops], [l.u_max for l in case.loops],
               case.anti_windup, Tt=None if Tts[0] is None else Tts, derivative_filter_N=case.N,
               setpoint_weight=[l.b for l in case.loops], derivative_weight=[l.c for l in case.loops],
               measurement_filter_s=[l.Tf for l in case.loops], measurement_filter_order=case.filter_order,
               u_rate_limit=[l.R for l in case.loops], gain_change=case.gain_change)


def _imposed(case, k: int) -> list | None:
    """Per loop the output imposed at sample k (None: the law), or None when no loop has one."""
    values = [None if loop.imposed is None else loop.imposed[k] for loop in case.loops]
    return None if all(v is None for v in values) else values


@pytest.mark.parametrize("name", IDS)
def test_python_pid(name):
    case = BY_NAME[name]
    pid = _python_pid(case)
    _, y, Kp, Ti, _ = _per_sample(case, 0)
    pid.preset_output([loop.u_start for loop in case.loops], y, Kp, Ti)  # LoopCore's rule: always, at y(0)
    out = []
    for k in range(case.steps):
        imposed = _imposed(case, k)
        if imposed is None:
            out.append(pid.step(*_per_sample(case, k)).tolist())
        else:
            out.append(pid.track_values(*_per_sample(case, k), imposed))
    _check("the Python PID (control/pid.py)", case, np.array(out).T)


# -- the exports: a case as a gain table -----------------------------------------------------------

def _export_skip_reason(case) -> str | None:
    if any(g[1] == INF for loop in case.loops for g in loop.gains):
        return "the exports cannot express Ti = inf (from_schedule refuses non-finite gains)"
    if any(loop.Tt is not None for loop in case.loops):
        return "the exports have no Tt setting (always Tt = sqrt(Ti*Td), or Ti when Td = 0)"
    rows = {}
    for k in range(case.steps):
        key = case.loops[0].r[k]
        gains = tuple(loop.gains[k] for loop in case.loops)
        if rows.setdefault(key, gains) != gains:
            return "its gains change while the setpoint of loop 1 stays: no setpoint-scheduled table produces them"
    return None


def _schedule(case):
    """The case as a GainSchedule on setpoint[y1]: one row per setpoint value (one row for constant gains)."""
    from prlpid_fmi.tuning.schedule.table import GainSchedule

    n = case.n_loops
    if case.constant_gains:
        rows = {case.loops[0].r[0]: tuple(loop.gains[0] for loop in case.loops)}
    else:
        rows = {case.loops[0].r[k]: tuple(loop.gains[k] for loop in case.loops) for k in range(case.steps)}
    breakpoints = sorted(rows)
    table = lambda j: np.array([[rows[b][i][j] for i in range(n)] for b in breakpoints], float)
    return GainSchedule(
        variable="setpoint[y1]", unit="", breakpoints=np.array(breakpoints, float), Kp=table(0), Ti=table(1),
        Td=table(2), coupling=None, sample_time_s=case.dt, loop_names=tuple(f"y{i + 1}" for i in range(n)),
        loop_inputs=tuple(f"u{i + 1}" for i in range(n)), output_units=("",) * n, input_units=("",) * n,
        anti_windup=case.anti_windup, u_min=np.array([l.u_min for l in case.loops], float),
        u_max=np.array([l.u_max for l in case.loops], float), derivative_filter_N=case.N,
        setpoint_weight=np.array([l.b for l in case.loops], float),
        derivative_weight=np.array([l.c for l in case.loops], float),
        measurement_filter_s=np.array([l.Tf for l in case.loops], float), measurement_filter_order=case.filter_order,
        u_rate_limit=np.array([l.R for l in case.loops], float), gain_change=case.gain_change)


def _controller(case):
    from prlpid_fmi.export.controller import from_schedule

    return from_schedule(_schedule(case), case.name, source=f"tests/pid_law_cases.py {case.name}")


EXPORTED = [case for case in CASES if _export_skip_reason(case) is None]


def _skip_export(case):
    reason = _export_skip_reason(case)
    if reason is not None:
        pytest.skip(f"{case.name}: {reason}")


def test_the_export_skip_reasons_still_hold():
    """Remove a skip reason (above) when this fails: the export then can express those cases."""
    from prlpid_fmi.errors import PrlPidError
    from prlpid_fmi.export.controller import DeployedController, from_schedule

    case = BY_NAME["pi_clamping"]
    schedule = _schedule(case)
    schedule.Ti[:] = INF
    with pytest.raises(PrlPidError, match="finite"):
        from_schedule(schedule, "ti_inf")
    fields = {f.lower() for f in DeployedController.__dataclass_fields__}
    assert not fields & {"tt", "tracking_time", "tracking_time_s"}
    assert len(EXPORTED) >= 13


# -- 2. the exported C ----------------------------------------------------------------------------

DRIVER_CASE = r"""
static int run_@n@(void)
{
    @n@_state s;
    double r[@P@_N_LOOPS], y[@P@_N_LOOPS], u[@P@_N_LOOPS], u0[@P@_N_LOOPS], value[@P@_N_LOOPS];
    int n, k, i, mode[@P@_N_LOOPS], manual[@P@_N_LOOPS], track[@P@_N_LOOPS];
    if (scanf("%d", &n) != 1) return 1;
    for (i = 0; i < @P@_N_LOOPS; i++) if (scanf("%lf", &u0[i]) != 1) return 1;
    @n@_reset(&s, u0);
    for (k = 0; k < n; k++) {
        for (i = 0; i < @P@_N_LOOPS; i++) if (scanf("%lf", &r[i]) != 1) return 1;
        for (i = 0; i < @P@_N_LOOPS; i++) if (scanf("%lf", &y[i]) != 1) return 1;
        for (i = 0; i < @P@_N_LOOPS; i++) {  /* 0: automatic, 1: manual, 2: tracking; then the value */
            if (scanf("%d %lf", &mode[i], &value[i]) != 2) return 1;
            manual[i] = mode[i] == 1;
            track[i] = mode[i] == 2;
        }
        @n@_step_modes(&s, r, y, manual, value, track, value, u);
        for (i = 0; i < @P@_N_LOOPS; i++) printf("%a ", u[i]);
        printf("\n");
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def c_driver(tmp_path_factory):
    """One executable holding every exported case; argv[1] names the case, stdin carries its inputs."""
    from prlpid_fmi.export.formats import render

    if shutil.which("gcc") is None:
        pytest.fail("gcc is needed to compile the exported C")
    out = tmp_path_factory.mktemp("pid_law_c")
    sources, includes, runs, dispatch = [], [], [], []
    for case in EXPORTED:
        for filename, text in render(_controller(case), "c", basename=case.name).items():
            (out / filename).write_text(text)
        sources.append(out / f"{case.name}.c")
        includes.append(f'#include "{case.name}.h"')
        runs.append(DRIVER_CASE.replace("@P@", case.name.upper()).replace("@n@", case.name))
        dispatch.append(f'    if (strcmp(argv[1], "{case.name}") == 0) return run_{case.name}();')
    driver = out / "driver.c"
    driver.write_text("#include <stdio.h>\n#include <string.h>\n" + "\n".join(includes) + "\n" + "".join(runs)
                      + "\nint main(int argc, char **argv)\n{\n    if (argc != 2) return 2;\n"
                      + "\n".join(dispatch) + "\n    return 2;\n}\n")
    exe = out / "driver"
    proc = subprocess.run(GCC + [str(driver), *map(str, sources), "-o", str(exe)], capture_output=True, text=True,
                          check=False)
    assert proc.returncode == 0, proc.stderr
    return exe


@pytest.mark.parametrize("name", IDS)
def test_exported_c(name, c_driver):
    case = BY_NAME[name]
    _skip_export(case)
    lines = [str(case.steps), " ".join(repr(loop.u_start) for loop in case.loops)]
    for k in range(case.steps):
        r, y, *_ = _per_sample(case, k)
        modes = [(0, 0.0) if loop.imposed is None or loop.imposed[k] is None
                 else (1 if loop.imposed_by == "manual" else 2, loop.imposed[k]) for loop in case.loops]
        lines.append(" ".join(repr(v) for v in r + y) + " " + " ".join(f"{m} {v!r}" for m, v in modes))
    proc = subprocess.run([str(c_driver), case.name], input="\n".join(lines) + "\n",
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    rows = [[float.fromhex(v) for v in line.split()] for line in proc.stdout.splitlines()]
    _check("the exported C (templates/controller.c.j2)", case, np.array(rows).T)


# -- 3. the exported Structured Text ----------------------------------------------------------------

BODY_START = "(* 0. Reset"  # the first statement comment of templates/st_body.j2


@pytest.fixture(scope="module")
def st_blocks():
    """Every exported case's ST block, ready to run; blark's Earley parser takes ~2 s per block, so a
    statement body is parsed once per distinct body text: the blocks whose body text is identical
    (same anti-windup mode and filter; the numbers are constants in the declarations) get the
    declarations of their own text and the statements of the first such block."""
    from st_interpreter import FunctionBlockInstance

    from prlpid_fmi.export.formats import render

    blocks, bodies = {}, {}
    for case in EXPORTED:
        (text,) = render(_controller(case), "st").values()
        start, end = text.index(BODY_START), text.rindex("END_FUNCTION_BLOCK")
        body = text[start:end]
        if body not in bodies:
            fb = bodies[body] = FunctionBlockInstance(text)
        else:
            fb = FunctionBlockInstance(text[:start] + text[end:])  # the declarations of this text, no statements
            fb.block = dataclasses.replace(fb.block, body=bodies[body].block.body)
        blocks[case.name] = fb
    assert len(bodies) < len(blocks)  # the sharing saves time
    return blocks


@pytest.mark.parametrize("name", IDS)
def test_exported_structured_text(name, st_blocks):
    case = BY_NAME[name]
    _skip_export(case)
    fb = st_blocks[name]
    n = case.n_loops
    fb["Reset"], fb["UStart"] = True, [loop.u_start for loop in case.loops]
    fb["Setpoint"], fb["Measurement"] = [0.0] * n, [0.0] * n
    fb.call()
    fb["Reset"] = False
    out = []
    for k in range(case.steps):
        r, y, *_ = _per_sample(case, k)
        fb["Setpoint"], fb["Measurement"] = r, y
        imposed = [None if loop.imposed is None else loop.imposed[k] for loop in case.loops]
        for flag, value, by in (("Manual", "ManualValue", "manual"), ("Track", "TrackValue", "track")):
            on = [v is not None and loop.imposed_by == by for v, loop in zip(imposed, case.loops)]
            fb[flag] = on
            fb[value] = [v if o else 0.0 for v, o in zip(imposed, on)]
        fb.call()
        out.append(fb["U"])
    _check("the exported Structured Text (templates/st_body.j2)", case, np.array(out).T)


# -- 4. the reward forecast, native C and FMI path ------------------------------------------------------

@pytest.fixture(scope="module")
def static_valve(tmp_path_factory):
    from prlpid_fmi.fmu import build_fmu

    return build_fmu("StaticValve", fmi_version=2, out_dir=tmp_path_factory.mktemp("pid_law_fmu"),
                     source_dir=STATIC_VALVE)


@pytest.mark.parametrize("path", ["native", "fmi"])
@pytest.mark.parametrize("name", IDS)
def test_forecast_predicts_the_closed_loop(name, path, static_valve):
    """The forecast's predicted measurements on the prior q = Kv*opening (Kv = g) are g*u(0..n-1)."""
    from prlpid_fmi.control import RewardWeights
    from prlpid_fmi.fmu import FmuPlant
    from prlpid_fmi.loop.forecast import make_forecast
    from prlpid_fmi.loop.forecast.fmi import FmiForecast
    from prlpid_fmi.loop.forecast.native import NativeForecast

    case = BY_NAME[name]
    if case.static_gain is None:
        pytest.skip(f"{name}: not a closed loop through a static plant (open-loop inputs, changing setpoint "
                    "or gains, or more loops than the one-input valve): the forecast cannot be fed its y")
    (loop,) = case.loops
    g = case.static_gain
    pid = _python_pid(case)
    Kp, Ti, Td = loop.gains[0]
    pid.preset_output([loop.u_start], [loop.y[0]], [Kp], [Ti])  # as LoopCore, before the forecast
    parameters = {"Kv": g}
    with FmuPlant(static_valve, ["opening"], ["q"], case.dt, parameters, "plant") as plant, \
            FmuPlant(static_valve, ["opening"], ["q"], case.dt, parameters, "prior") as prior:
        forecast = make_forecast(plant, prior, pid, horizon=case.steps, scale=[1.0], bound=[1e9], penalty=-1e9,
                                 weights=RewardWeights(), u_scale=[1.0], path=path)
        assert isinstance(forecast, NativeForecast if path == "native" else FmiForecast)
        forecast.mean_reward([loop.r[0]], [loop.y[0]], [Kp], [Ti], [Td], None, [0.0])
        predicted = forecast.last_measurements
    where = ("the C forecast (plant_sources/common/forecast.c)" if path == "native"
             else "the FMI-path forecast (loop/forecast/fmi.py, Python PID)")
    _check(where, case, [[y[0] / g for y in predicted]])
