"""The loops' measured frequency responses: a CSV per loop and the figures an engineer reads them in.

The data are the margin experiments' (robustness.margins.loop_margins: P(e^{j w Ts}) measured on the FMU with the
controller in the loop, C(e^{j w Ts}) that controller's feedback part), one per controller and operating point, as
deliver.rule.Candidate carries them; no new experiment. From them, at each measured frequency w [rad/s]::

    L = C P,   S = 1 / (1 + L),   T = L / (1 + L)

(python-control's FRD arithmetic: control.frd, control.feedback). The figures follow python-control's conventions
and use its plotting where it fits: the Nyquist curve of L (control.nyquist_plot, positive frequencies, the -1
point marked "+", the Ms circle |1 + L| = 1/Ms of deploy.max_sensitivity; beyond |L| = NYQUIST_RADIUS the curve
is drawn compressed, dash-dot), |S| and |T| on log-log axes against the Ms limit, and the Bode plot of P and C
(control.bode_plot: magnitude on a log axis, phase in degrees, frequency in rad/s, the Nyquist frequency pi/Ts
marked). Curves are coloured by operating point (the first loop's setpoint, as in report.md's margins table).
"""
from __future__ import annotations

import csv
import io
import math
import re
import warnings
from dataclasses import dataclass

import control
import matplotlib
import numpy as np
from matplotlib import colors as mcolors
from matplotlib.lines import Line2D

from prlpid_fmi.report.plots import new_figure, save_figure

NYQUIST_RADIUS = 2.5  # |L| beyond which control.nyquist_plot compresses the curve (its max_curve_magnitude)
NYQUIST_VIEW = (-3.0, 2.6, -2.8, 2.8)  # Nyquist axes: real from, to; imaginary from, to (equal aspect)
POINT_COLORMAP = "viridis"
CONTROLLER_STYLES = ("-", "--", ":")  # line style per controller in figures that overlay controllers
BETWEEN = "between breakpoints"
CSV_COLUMNS = ("controller", "operating_point", "frequency_rad_s", "P_re", "P_im", "C_re", "C_im", "L_re", "L_im",
               "S_re", "S_im", "T_re", "T_im")

__all__ = ["LoopResponse", "loop_responses", "frequency_csv", "nyquist_figure", "sensitivity_figure", "bode_figure",
           "file_stem", "CSV_COLUMNS"]


@dataclass(frozen=True, eq=False)
class LoopResponse:
    """One loop's measured frequency response with one controller at one operating point.

    controller: the controller's name (deliver.rule.Candidate.name); loop: the loop's output name; point: the
    operating point as report.md's margins table labels it (the first loop's setpoint, or a text such as
    "0.5 (between breakpoints)"); frequencies_rad_s (K,) ascending [rad/s]; plant (K,) complex P(e^{j w Ts})
    [output unit / input unit]; controller_response (K,) complex C(e^{j w Ts}) [input unit / output unit];
    sample_time_s [s]; Ms: the peak of |S| the margin experiment reported.
    """

    controller: str
    loop: str
    point: str
    frequencies_rad_s: np.ndarray
    plant: np.ndarray
    controller_response: np.ndarray
    sample_time_s: float
    Ms: float

    def frd(self, which: str) -> control.FrequencyResponseData:
        """P, C, L, S or T as a python-control FRD (discrete, dt = sample_time_s) on the measured frequencies."""
        w, dt = self.frequencies_rad_s, self.sample_time_s
        if which in ("P", "C"):
            return control.frd(self.plant if which == "P" else self.controller_response, w, dt=dt, name=which)
        L = control.frd(self.controller_response, w, dt=dt, name="L") * control.frd(self.plant, w, dt=dt)
        if which == "L":
            return L
        if which == "S":
            return control.feedback(1, L)
        if which == "T":
            return control.feedback(L, 1)
        raise ValueError(f"which: one of P, C, L, S, T (got {which!r})")

    def values(self, which: str) -> np.ndarray:
        """P, C, L, S or T (K,) complex at frequencies_rad_s (the FRD's data)."""
        return np.asarray(self.frd(which).frdata).reshape(-1)

    @property
    def point_value(self) -> float | None:
        """The operating point as a number (the setpoint), None for a label that is not one (an error table's row)."""
        try:
            return float(self.point.split()[0])
        except (IndexError, ValueError):
            return None

    @property
    def between_breakpoints(self) -> bool:
        return BETWEEN in self.point

    @property
    def on_draw(self) -> bool:
        """Measured on a Monte-Carlo parameter draw of the plant ("<point>, draw <n>"), not the nominal plant."""
        return ", draw " in self.point


def _label(point) -> str:
    return f"{point:.4g}" if isinstance(point, (int, float)) else str(point)


def loop_responses(candidates, loop_names, sample_time_s: float, draws: bool = False) -> list[LoopResponse]:
    """Every measured loop response of the candidates (deliver.rule.Candidate: margins and their operating points),
    loop by loop; estimates without a response (a loop that diverged or sat at a limit) are left out, and so are
    the Monte-Carlo parameter draws' ("<point>, draw <n>") unless `draws`."""
    out = []
    for c in candidates:
        if c is None:
            continue
        for point, m in zip(c.breakpoints, c.margins):
            label = _label(point)
            if not draws and ", draw " in label:
                continue
            for i, loop in enumerate(loop_names):
                x = m.per_loop[i] if m.per_loop else m
                if len(x.frequencies_rad_s) < 2 or not np.all(np.isfinite(x.plant_response)):
                    continue
                out.append(LoopResponse(c.name, loop, label, np.asarray(x.frequencies_rad_s, float),
                                        np.asarray(x.plant_response, complex), np.asarray(x.controller_response, complex),
                                        float(sample_time_s), float(x.Ms)))
    return out


def file_stem(loop: str) -> str:
    """A loop's output name as a file-name part: letters, digits, '-' and '_' kept, anything else '_'."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", loop)


def frequency_csv(responses: list[LoopResponse], loop: str, units: tuple[str, str] = ("", "")) -> str:
    """The CSV text of one loop's responses: '# ' lines saying what the columns are, then CSV_COLUMNS, one row per
    controller, operating point and measured frequency; complex values as real and imaginary parts."""
    y, u = units[0] or "output unit", units[1] or "input unit"
    rows = [r for r in responses if r.loop == loop]
    buf = io.StringIO()
    buf.write(f"# Frequency response of loop {loop}, measured on the FMU at each operating point with each controller "
              "in the loop (robustness.margins.loop_margins).\n"
              "# controller: the controller in the loop; operating_point: the first loop's setpoint (as report.md's "
              "margins table labels it); frequency_rad_s: w [rad/s], z = exp(j w Ts).\n"
              f"# Complex values as real (_re) and imaginary (_im) parts: P = plant [{y} per {u}], C = PID feedback "
              f"part [{u} per {y}], L = C P, S = 1/(1 + L), T = L/(1 + L) [1].\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for r in rows:
        values = [r.plant, r.controller_response, r.values("L"), r.values("S"), r.values("T")]
        for k, freq in enumerate(r.frequencies_rad_s):
            row = [r.controller, r.point, repr(float(freq))]
            for v in values:
                row += [repr(float(v[k].real)), repr(float(v[k].imag))]
            w.writerow(row)
    return buf.getvalue()


# -- figures --------------------------------------------------------------------------------------------------
def _controllers(responses: list[LoopResponse]) -> list[str]:
    return list(dict.fromkeys(r.controller for r in responses))


class _PointColors:
    """Colour per operating point: a colour map over the setpoints (with a colour bar) when every point is a number,
    else one colour per label (with a legend)."""

    def __init__(self, responses: list[LoopResponse]):
        values = [r.point_value for r in responses]
        self.numeric = bool(values) and all(v is not None for v in values)
        if self.numeric:
            lo, hi = min(values), max(values)
            self.norm = mcolors.Normalize(lo - 0.5 if lo == hi else lo, hi + 0.5 if lo == hi else hi)
            self.cmap = matplotlib.colormaps[POINT_COLORMAP]
        else:
            cycle = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
            labels = list(dict.fromkeys(r.point for r in responses))
            self.by_label = {p: cycle[j % len(cycle)] for j, p in enumerate(labels)}

    def __call__(self, r: LoopResponse):
        return self.cmap(self.norm(r.point_value)) if self.numeric else self.by_label[r.point]

    def key(self, fig, axes, label: str) -> None:
        """The colour bar (numeric points) beside the axes; else a legend of the labels on the last axes."""
        if self.numeric:
            bar = fig.colorbar(matplotlib.cm.ScalarMappable(norm=self.norm, cmap=self.cmap), ax=list(np.ravel(axes)),
                               shrink=0.9, pad=0.02)
            bar.set_label(label)
        else:
            ax = np.ravel(axes)[-1]
            for p, color in self.by_label.items():
                ax.plot([], [], color=color, label=p)
            ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7, title="operating point",
                      title_fontsize=7)


def _point_title(loop_names, y_unit: str) -> str:
    return f"operating point: setpoint of {loop_names[0]}" + (f" [{y_unit}]" if y_unit else "")


def _deployed_name(name: str, deployed: str | None) -> str:
    return f"{name} (deployed)" if deployed is not None and name == deployed else name


def nyquist_figure(responses: list[LoopResponse], loop: str, ms_limit: float, point_label: str,
                   deployed: str | None = None, title: str = ""):
    """The Nyquist curve of L = C P for each controller (one panel each) at each operating point (a curve each, its
    closest approach to -1 marked), with the circle |1 + L| = 1/ms_limit (control.nyquist_plot's ms_circles). Curves
    from the measured frequencies (positive ones; the mirror image is omitted); beyond |L| = NYQUIST_RADIUS they are
    compressed (dash-dot, python-control's convention)."""
    rows = [r for r in responses if r.loop == loop]
    names = _controllers(rows)
    fig, axes = new_figure(1, max(len(names), 1), figsize=(0.6 + 4.6 * max(len(names), 1), 5.2), squeeze=False)
    fig.set_layout_engine("constrained")
    axes = axes[0]
    colors = _PointColors(rows)
    x0, x1, y0, y1 = NYQUIST_VIEW
    for ax, name in zip(axes, names):
        first = True
        for r in (r for r in rows if r.controller == name):
            L = r.frd("L")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # encirclements: the measured curve starts above w = 0
                control.nyquist_plot(L, ax=ax, color=colors(r), mirror_style=False, max_curve_magnitude=NYQUIST_RADIUS,
                                     max_curve_offset=0.0, ms_circles=[ms_limit] if first else None, arrows=1,
                                     warn_encirclements=False, warn_nyquist=False, show_legend=False, title="",
                                     start_marker="", gid="nyquist", lw=0.9 if r.between_breakpoints else 1.4)
            first = False
            Lv = r.values("L")
            k = int(np.argmin(np.abs(1 + Lv)))
            if abs(Lv[k]) <= NYQUIST_RADIUS:
                ax.plot(Lv[k].real, Lv[k].imag, "o", color=colors(r), ms=4, gid="closest to -1")
        for t in list(ax.texts):  # the circle's own label: said in the legend instead
            t.remove()
        keys = [Line2D([], [], color="k", ls="--", lw=1, label=f"Ms limit {ms_limit:g}: |1 + L| = 1/{ms_limit:g}"),
                Line2D([], [], ls="none", marker="+", color="r", ms=7, label="critical point -1"),
                Line2D([], [], ls="none", marker="o", color="0.4", ms=4, label="closest to -1 (distance 1/Ms)"),
                Line2D([], [], color="k", ls="-.", lw=1, label=f"|L| > {NYQUIST_RADIUS:g} drawn compressed")]
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("Re L [1]")
        ax.set_ylabel("Im L [1]")
        ax.set_title(_deployed_name(name, deployed), fontsize=10)
        ax.legend(handles=keys, loc="upper right", fontsize=7)
    if not names:
        axes[0].text(0.5, 0.5, f"no frequency response measured for loop {loop}", ha="center", va="center",
                     transform=axes[0].transAxes)
    else:
        colors.key(fig, axes, point_label)
    fig.suptitle(title or f"Nyquist plot of L = C P, loop {loop} (measured on the FMU)", fontsize=11)
    return fig


def sensitivity_figure(responses: list[LoopResponse], loop: str, ms_limit: float, point_label: str,
                       deployed: str | None = None, title: str = ""):
    """|S| (solid) and |T| (dashed) against frequency for each controller (one panel each) at each operating point,
    with the Ms limit on |S| (deploy.max_sensitivity; the scenario sets no limit on |T|) and pi/Ts marked."""
    rows = [r for r in responses if r.loop == loop]
    names = _controllers(rows)
    n = max(len(names), 1)
    fig, axes = new_figure(1, n, figsize=(0.6 + 4.6 * n, 4.4), squeeze=False, sharey=True)
    fig.set_layout_engine("constrained")
    axes = axes[0]
    colors = _PointColors(rows)
    top = ms_limit
    for ax, name in zip(axes, names):
        for r in (r for r in rows if r.controller == name):
            w = r.frequencies_rad_s
            S, T = np.abs(r.values("S")), np.abs(r.values("T"))
            lw = 0.9 if r.between_breakpoints else 1.4
            ax.loglog(w, S, color=colors(r), lw=lw, gid="|S|")
            ax.loglog(w, T, color=colors(r), lw=lw, ls="--", gid="|T|")
            top = max(top, float(np.max(S)), float(np.max(T)))
        ax.axhline(ms_limit, color="tab:red", ls="-.", lw=1.2, label=f"Ms limit {ms_limit:g}", gid="Ms limit")
        ax.axvline(math.pi / rows[0].sample_time_s, color="0.5", ls=":", lw=1, label="Nyquist frequency π/Ts")
        ax.plot([], [], "k-", lw=1.4, label="|S| = |1/(1 + L)|")
        ax.plot([], [], "k--", lw=1.4, label="|T| = |L/(1 + L)| (no limit set)")
        ax.set_xlabel("frequency [rad/s]")
        ax.set_title(_deployed_name(name, deployed), fontsize=10)
        ax.grid(True, which="major", alpha=0.4)
        ax.grid(True, which="minor", alpha=0.15)
        ax.legend(loc="lower right", fontsize=7)
    axes[0].set_ylabel("magnitude [1]")
    if names:
        bottom = min(float(np.min(np.abs(r.values("S")))) for r in rows)
        axes[0].set_ylim(max(bottom, 1e-4) / 1.5, top * 1.6)
        colors.key(fig, axes, point_label)
    fig.suptitle(title or f"Sensitivity |S| and complementary sensitivity |T|, loop {loop}", fontsize=11)
    return fig


def bode_figure(responses: list[LoopResponse], loop: str, units: tuple[str, str], point_label: str,
                deployed: str | None = None, title: str = ""):
    """Bode plot (control.bode_plot) of the plant P (left) and the PID's feedback part C (right) at each operating
    point (colour) with each controller (line style; P as measured with that controller in the loop)."""
    rows = [r for r in responses if r.loop == loop]
    names = _controllers(rows)
    fig, axes = new_figure(2, 2, figsize=(11.5, 6.6), squeeze=False, sharex=True)
    fig.set_layout_engine("constrained")
    colors = _PointColors(rows)
    for which, column in (("P", 0), ("C", 1)):
        for r in rows:
            style = CONTROLLER_STYLES[names.index(r.controller) % len(CONTROLLER_STYLES)]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                control.bode_plot(r.frd(which), ax=axes[:, column:column + 1], color=colors(r), linestyle=style,
                                  lw=0.9 if r.between_breakpoints else 1.4, title="", show_legend=False,
                                  label=f"{which} {r.controller} {r.point}")
    y, u = units[0] or "output unit", units[1] or "input unit"
    axes[0, 0].set_ylabel(f"|P| [{y} per {u}]")
    axes[0, 1].set_ylabel(f"|C| [{u} per {y}]")
    axes[0, 0].set_title("plant P (measured)", fontsize=10)
    axes[0, 1].set_title("PID C (feedback part)", fontsize=10)
    for ax in axes[1]:
        ax.set_ylabel("phase [deg]")
        ax.set_xlabel("frequency [rad/s]")
    for ax in axes.ravel():  # bode_plot marks pi/Ts once per curve, in its colour: once, in grey, instead
        for line in [l for l in ax.get_lines() if l.get_label().startswith("_nyq")]:
            line.remove()
        if rows:
            ax.axvline(math.pi / rows[0].sample_time_s, color="0.4", ls="--", lw=1)
    keys = [Line2D([], [], color="k", ls=style, label=_deployed_name(name, deployed))
            for name, style in zip(names, CONTROLLER_STYLES * len(names))]
    if names:
        axes[0, 1].legend(handles=keys, loc="best", fontsize=7)
        colors.key(fig, axes, point_label)
    fig.suptitle(title or f"Bode plot of the plant and the PID, loop {loop} (Nyquist frequency π/Ts dashed)",
                 fontsize=11)
    return fig


def write_frequency_files(out_dir, responses: list[LoopResponse], loop_names, units_per_loop, ms_limit: float,
                          deployed: str | None = None) -> dict:
    """Per loop, in out_dir (created): <loop>.csv (frequency_csv: every response, the parameter draws' too) and
    nyquist_, sensitivity_, bode_<loop>.png (the nominal plant's). Returns {loop: {kind: file name}} of what was
    written (kind: csv, nyquist, sensitivity, bode); a loop without a measured response gets only its CSV (the header
    and the columns)."""
    from prlpid_fmi.rundir import write_atomic

    out_dir.mkdir(parents=True, exist_ok=True)
    written = {}
    for i, loop in enumerate(loop_names):
        stem, units = file_stem(loop), units_per_loop[i]
        files = {"csv": f"{stem}.csv"}
        write_atomic(out_dir / files["csv"], frequency_csv(responses, loop, units))
        nominal = [r for r in responses if not r.on_draw]
        if any(r.loop == loop for r in nominal):
            label = _point_title(loop_names, units_per_loop[0][0])
            for kind, draw in (("nyquist", lambda: nyquist_figure(nominal, loop, ms_limit, label, deployed)),
                               ("sensitivity", lambda: sensitivity_figure(nominal, loop, ms_limit, label, deployed)),
                               ("bode", lambda: bode_figure(nominal, loop, units, label, deployed))):
                files[kind] = f"{kind}_{stem}.png"
                save_figure(draw(), out_dir / files[kind])
        written[loop] = files
    return written
