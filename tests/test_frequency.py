"""report.frequency: the measured frequency responses' CSV and figures, checked against python-control computing the
same loop from transfer functions (an independent truth: here the "measured" P and C are a linear plant's and a
hand-written PI's values at the grid's frequencies)."""
import csv
import io
import math

import control
import numpy as np
import pytest

from prlpid_fmi.deliver.rule import Candidate
from prlpid_fmi.report.frequency import (
    CSV_COLUMNS, NYQUIST_RADIUS, LoopResponse, bode_figure, file_stem, frequency_csv, loop_responses, nyquist_figure,
    sensitivity_figure, write_frequency_files)
from prlpid_fmi.robustness.margins import Margins

TS = 0.1
W = np.geomspace(0.05, math.pi / TS, 120)
Z = np.exp(1j * W * TS)
PLANT = control.c2d(control.tf([1.0], [1.0, -1.0]), TS, "zoh")  # paper 4.1: 1/(s - 1), held over Ts


def pi_controller(Kp: float, Ti: float) -> control.TransferFunction:
    """Kp (1 + (Ts/Ti) z/(z - 1)), written out: Kp ((1 + Ts/Ti) z - 1) / (z - 1)."""
    return control.tf([Kp * (1 + TS / Ti), -Kp], [1.0, -1.0], TS)


def margins(C, P=PLANT, Ms=2.0) -> Margins:
    """A margin estimate whose measured P and C are the transfer functions' values on W."""
    return Margins(Ms, 1.0, 2.0, 1.0, 45.0, 1.0, W, P(Z), C(Z), 0.1, True, "", "y")


def candidates():
    fixed = Candidate("fixed PID", {}, margins=[margins(pi_controller(3.0, 1.0))] * 3, breakpoints=[-1.0, 0.0, 1.0])
    table = Candidate("gain schedule", {}, margins=[margins(pi_controller(2.5, 0.8)), margins(pi_controller(2.5, 0.8)),
                                                    margins(pi_controller(9.0, 0.3))],
                      breakpoints=[-1.0, "-0.5 (between breakpoints)", "0, draw 1"])
    return fixed, table


def test_nyquist_and_sensitivity_data_are_python_controls():
    C = pi_controller(3.0, 1.0)
    (r,) = loop_responses([candidates()[0]], ["y"], TS)[:1]
    L_true = control.nyquist_response(C * PLANT, omega=W, warn_encirclements=False).response
    S_true = control.frequency_response(control.feedback(1, C * PLANT), W)
    T_true = control.frequency_response(control.feedback(C * PLANT, 1), W)
    fig = nyquist_figure([r], "y", 2.0, "operating point")
    ax = fig.axes[0]
    (curve,) = [l for l in ax.get_lines() if l.get_gid() == "nyquist" and l.get_linestyle() == "-"]
    drawn = np.asarray(curve.get_xdata(), float) + 1j * np.asarray(curve.get_ydata(), float)
    # true to scale up to where python-control's compression blends in; beyond, the same phase at a radius <= 2.5
    true_scale = np.abs(L_true) < (1 - 0.15) * NYQUIST_RADIUS
    assert true_scale.sum() > 40 and (~true_scale).sum() > 10
    assert np.allclose(drawn[true_scale], L_true[true_scale], rtol=1e-9, atol=1e-12)
    assert np.allclose(np.angle(drawn), np.angle(L_true), atol=1e-9)
    assert np.all(np.abs(drawn) <= NYQUIST_RADIUS * (1 + 1e-9))
    # the Ms circle: |1 + L| = 1/Ms of the limit
    (circle,) = [l for l in ax.get_lines() if l.get_linestyle() == "--" and len(l.get_xdata()) > 10]
    ring = np.asarray(circle.get_xdata()) + 1j * np.asarray(circle.get_ydata())
    assert np.allclose(np.abs(ring + 1), 0.5)
    # the closest approach to -1 is where |S| peaks, at 1/Ms of the true loop
    (dot,) = [l for l in ax.get_lines() if l.get_gid() == "closest to -1"]
    closest = complex(dot.get_xdata()[0], dot.get_ydata()[0])
    assert abs(1 + closest) == pytest.approx(1 / np.max(np.abs(S_true.complex)), rel=1e-9)

    fig = sensitivity_figure([r], "y", 2.0, "operating point")
    ax = fig.axes[0]
    (s_line,) = [l for l in ax.get_lines() if l.get_gid() == "|S|"]
    (t_line,) = [l for l in ax.get_lines() if l.get_gid() == "|T|"]
    assert np.allclose(s_line.get_xdata(), W) and np.allclose(s_line.get_ydata(), S_true.magnitude, rtol=1e-9)
    assert np.allclose(t_line.get_ydata(), T_true.magnitude, rtol=1e-9)
    (limit,) = [l for l in ax.get_lines() if l.get_gid() == "Ms limit"]
    assert list(limit.get_ydata()) == [2.0, 2.0]


def test_the_bode_plot_draws_the_measured_plant_and_the_controller():
    responses = loop_responses(candidates(), ["y"], TS)
    fig = bode_figure(responses, "y", ("cm", "cm3/s"), "operating point")
    mag_p, mag_c = fig.axes[0], fig.axes[1]
    assert "cm per cm3/s" in mag_p.get_ylabel() and "cm3/s per cm" in mag_c.get_ylabel()
    curves = [l for l in mag_p.get_lines() if len(l.get_xdata()) == len(W)]
    assert curves and all(np.allclose(l.get_ydata(), np.abs(PLANT(Z))) for l in curves)
    c_curves = [np.asarray(l.get_ydata()) for l in mag_c.get_lines() if len(l.get_xdata()) == len(W)]
    assert any(np.allclose(y, np.abs(pi_controller(3.0, 1.0)(Z))) for y in c_curves)
    assert any(np.allclose(y, np.abs(pi_controller(2.5, 0.8)(Z))) for y in c_curves)


def test_loop_responses_leave_out_draws_and_empty_estimates():
    fixed, table = candidates()
    empty = Margins(math.inf, math.nan, math.nan, math.nan, math.nan, math.nan, np.array([]), np.array([]),
                    np.array([]), 0.1, False, "diverged", "y")
    fixed.margins, fixed.breakpoints = fixed.margins + [empty], fixed.breakpoints + [2.0]
    found = loop_responses([fixed, None, table], ["y"], TS)
    assert [(r.controller, r.point) for r in found] == [
        ("fixed PID", "-1"), ("fixed PID", "0"), ("fixed PID", "1"), ("gain schedule", "-1"),
        ("gain schedule", "-0.5 (between breakpoints)")]
    assert found[-1].between_breakpoints and found[-1].point_value == -0.5
    assert len(loop_responses([table], ["y"], TS, draws=True)) == 3


def _rows(text: str):
    lines = text.splitlines()
    comments = [l for l in lines if l.startswith("#")]
    return comments, list(csv.DictReader(io.StringIO("\n".join(l for l in lines if not l.startswith("#")))))


def test_the_csv_columns_hold_p_c_l_s_t_per_point():
    responses = loop_responses(candidates(), ["h2"], TS)
    comments, rows = _rows(frequency_csv(responses, "h2", ("cm", "cm3/s")))
    assert comments and all(l.startswith("# ") for l in comments)
    assert "[cm per cm3/s]" in " ".join(comments) and "real (_re) and imaginary (_im)" in " ".join(comments)
    assert tuple(rows[0].keys()) == CSV_COLUMNS
    assert len(rows) == len(W) * len(responses)
    assert [r["operating_point"] for r in rows[:: len(W)]] == ["-1", "0", "1", "-1", "-0.5 (between breakpoints)"]
    C = pi_controller(2.5, 0.8)
    last = rows[-len(W):]
    assert {r["controller"] for r in last} == {"gain schedule"}

    def values(name):
        return np.array([complex(float(r[f"{name}_re"]), float(r[f"{name}_im"])) for r in last])

    assert np.allclose([float(r["frequency_rad_s"]) for r in last], W, rtol=1e-15)
    assert np.allclose(values("P"), PLANT(Z), rtol=1e-12)
    assert np.allclose(values("C"), C(Z), rtol=1e-12)
    assert np.allclose(values("L"), (C * PLANT)(Z), rtol=1e-9)
    assert np.allclose(values("S"), control.feedback(1, C * PLANT)(Z), rtol=1e-9)
    assert np.allclose(values("T"), control.feedback(C * PLANT, 1)(Z), rtol=1e-9)


def test_files_per_loop(tmp_path):
    responses = loop_responses(candidates(), ["y"], TS, draws=True)
    written = write_frequency_files(tmp_path / "frequency", responses, ["y", "q.out[1]"], [("", ""), ("", "")], 2.0,
                                    "fixed PID")
    assert written["y"] == {"csv": "y.csv", "nyquist": "nyquist_y.png", "sensitivity": "sensitivity_y.png",
                            "bode": "bode_y.png"}
    for name in written["y"].values():
        assert (tmp_path / "frequency" / name).stat().st_size > 1000
    # a loop with no measured response: its CSV, the columns only
    assert written["q.out[1]"] == {"csv": "q_out_1_.csv"} and file_stem("q.out[1]") == "q_out_1_"
    _, rows = _rows((tmp_path / "frequency" / "y.csv").read_text())
    assert "0, draw 1" in {r["operating_point"] for r in rows}  # the CSV keeps the draws, the figures do not
    comments, rows = _rows((tmp_path / "frequency" / "q_out_1_.csv").read_text())
    assert rows == [] and (tmp_path / "frequency" / "q_out_1_.csv").read_text().splitlines()[3] == ",".join(CSV_COLUMNS)
