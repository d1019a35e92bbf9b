"""Progress of long work on stderr (training, the fixed-PID search: an honest total and an ETA; the steps
after training: when each starts and how long it took).

Work made of steps of different kinds (the fixed-PID search: a stabilising search, frequency-response
experiments, the load design with its polish, the setpoint weight, the Ms check on the FMU) is shown step
by step (`Steps`): each step with its own count and ETA where its size is known, a start and a duration
where it is not. One total over all of them would lie: its units do not cost the same, and steps such as
the Ms check have no size known in advance.

Every Steps and `stage` also records its duration, shown or not (`stage_seconds`: what `tune` writes to run.json
as "stage_seconds", and benchmarks/bench_speed.py tabulates).

On a terminal: one line redrawn in place (a bar). Otherwise (`nohup ... > log`): a plain line when the
work starts, about every 30 s, and when it ends, so a log shows where a long run is. The count never
passes the total: PPO collects whole rollouts, so SB3's own bar ends at 51,200/50,000.
"""
from __future__ import annotations

import contextlib
import sys
import time
from typing import Callable, TextIO

TTY_INTERVAL_S = 0.2
LOG_INTERVAL_S = 30.0
BAR_WIDTH = 24
_STAGE_SECONDS: dict[str, float] = {}  # stage name -> seconds, since the last stage_seconds(clear=True)


def _record(label: str, seconds: float) -> None:
    """Add a stage's duration under its name: the label up to its first " (" (the explanation); "" records nothing."""
    name = label.split(" (")[0].strip()
    if name:
        _STAGE_SECONDS[name] = _STAGE_SECONDS.get(name, 0.0) + max(float(seconds), 0.0)


def stage_seconds(clear: bool = False) -> dict[str, float]:
    """{stage name: seconds} of the Steps and `stage`s that ended in this process (since the last clear), in the
    order they first ended; clear: start afresh after reading (a new run)."""
    out = dict(_STAGE_SECONDS)
    if clear:
        _STAGE_SECONDS.clear()
    return out


def format_duration(seconds: float) -> str:
    """'42 s', '3 min 05 s', '1 h 02 min'."""
    s = int(round(max(seconds, 0.0)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


class Progress:
    """Count `done` of `total` units of work and show it on `stream` (default stderr).

    total may be given later, with the first `update`. `start` is work already done before this
    session (a resumed training): it counts toward done, not toward the rate.
    """

    def __init__(self, label: str, unit: str, total: int | None = None, start: int = 0,
                 stream: TextIO | None = None, interval_s: float | None = None,
                 clock: Callable[[], float] = time.monotonic):
        self.label, self.unit, self.total = label, unit, total
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval_s = interval_s if interval_s is not None else (TTY_INTERVAL_S if self.tty else LOG_INTERVAL_S)
        self.clock = clock
        self.start = self.done = start
        self.t0 = clock()
        self._last_shown: float | None = None
        self._closed = False
        if total is not None:
            self._show(self.t0)

    def update(self, done: int, total: int | None = None) -> None:
        """Set the amount done (clamped to [0, total]); shown at most every interval_s."""
        if total is not None and self.total is None:
            self.total = int(total)
        self.done = max(0, int(done)) if self.total is None else min(max(0, int(done)), self.total)
        now = self.clock()
        if self._last_shown is None or now - self._last_shown >= self.interval_s:
            self._show(now)

    def close(self) -> None:
        """Show the final count and the elapsed time (once)."""
        if self._closed or self.total is None:
            return
        self._closed = True
        elapsed = self.clock() - self.t0
        if self.tty:
            self.stream.write("\r" + self._bar_line(elapsed) + "\n")
        else:
            early = "" if self.done >= self.total else f" (stopped before {self.total:,}: done early)"
            self.stream.write(f"prlpid-fmi: {self.label}: {self.done:,} {self.unit} in "
                              f"{format_duration(elapsed)}{early}\n")
        self.stream.flush()

    # -- rendering ---------------------------------------------------------------------------------
    def _rate_eta(self, elapsed: float) -> tuple[str, str]:
        rate = (self.done - self.start) / elapsed if elapsed > 0 else 0.0
        if rate <= 0:
            return "", ""
        eta = format_duration((self.total - self.done) / rate) if self.total is not None else ""
        return f"{rate:,.1f} {self.unit}/s" if rate < 10 else f"{rate:,.0f} {self.unit}/s", eta

    def _bar_line(self, elapsed: float) -> str:
        frac = self.done / self.total if self.total else 1.0
        filled = int(round(frac * BAR_WIDTH))
        rate, eta = self._rate_eta(elapsed)
        tail = f"  {rate}" if rate else ""
        if eta and self.done < self.total:
            tail += f"  ETA {eta}"
        elif self.done >= self.total:
            tail += f"  {format_duration(elapsed)}"
        return (f"{self.label} [{'#' * filled}{'.' * (BAR_WIDTH - filled)}] {self.done:,}/{self.total:,} "
                f"{self.unit} {100 * frac:3.0f} %{tail}").ljust(79)

    def _show(self, now: float) -> None:
        if self.total is None or self._closed:
            return
        self._last_shown = now
        elapsed = now - self.t0
        if self.tty:
            self.stream.write("\r" + self._bar_line(elapsed))
        else:
            rate, eta = self._rate_eta(elapsed)
            pct = 100 * self.done / self.total if self.total else 100.0
            extra = "".join(f", {s}" for s in (rate, f"ETA {eta}" if eta else "") if s)
            self.stream.write(f"prlpid-fmi: {self.label}: {self.done:,}/{self.total:,} {self.unit} "
                              f"({pct:.0f} %){extra}\n")
        self.stream.flush()


class Steps:
    """Work in named steps (see the module docstring), all under one `label`; silent if not enabled.

    step(name, total, unit): ends the current step and starts the next, counted (`update`) when total is
    given, else announced with its duration at the end. close(): ends the last step and shows the whole
    duration.
    """

    def __init__(self, label: str, enabled: bool = True, stream: TextIO | None = None,
                 clock: Callable[[], float] = time.monotonic):
        self.label, self.enabled, self.clock = label, enabled, clock
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = clock()
        self._counted: Progress | None = None
        self._plain: tuple[str, float] | None = None
        self._closed = False

    def step(self, name: str, total: int | None = None, unit: str = "evaluations") -> "Steps":
        self._end_step()
        if not self.enabled:
            return self
        if total is not None and total > 0:
            self._counted = Progress(f"{self.label}: {name}", unit, total=int(total), stream=self.stream,
                                     clock=self.clock)
        else:
            self._plain = (name, self.clock())
            self.stream.write(f"prlpid-fmi: {self.label}: {name} ...\n")
            self.stream.flush()
        return self

    def update(self, done: int) -> None:
        if self._counted is not None:
            self._counted.update(done)

    def close(self) -> None:
        self._end_step()
        if not self._closed:
            _record(self.label, self.clock() - self.t0)
        self._closed = True
        if self.enabled:
            self.stream.write(f"prlpid-fmi: {self.label}: done in {format_duration(self.clock() - self.t0)}\n")
            self.stream.flush()
        self.enabled = False

    def _end_step(self) -> None:
        if self._counted is not None:
            self._counted.close()
            self._counted = None
        if self._plain is not None:
            name, t0 = self._plain
            self.stream.write(f"prlpid-fmi: {self.label}: {name}: done in {format_duration(self.clock() - t0)}\n")
            self.stream.flush()
            self._plain = None


def counted(fn, steps: Steps, start: int = 0):
    """`fn` reporting its number of calls so far (after `start` counted before) to `steps` (the count of the
    current step) on every call."""
    calls = [start]

    def wrapped(*args):
        calls[0] += 1
        steps.update(calls[0])
        return fn(*args)
    return wrapped


def batch_counted(fn, steps: Steps):
    """`fn(x)` of a whole population x (n, S) (scipy's vectorized form) reporting the number of vectors evaluated so
    far to `steps` after every call."""
    def wrapped(x, *args):
        out = fn(x, *args)
        wrapped.calls += int(x.shape[1]) if getattr(x, "ndim", 1) == 2 else 1
        steps.update(wrapped.calls)
        return out
    wrapped.calls = 0  # vectors evaluated so far (scipy's nfev counts one per vectorized call)
    return wrapped


QUIET = Steps("", enabled=False)  # a Steps that shows nothing (the default of functions that report steps)


@contextlib.contextmanager
def stage(label: str, enabled: bool = True, stream: TextIO | None = None,
          clock: Callable[[], float] = time.monotonic):
    """Announce a step of unknown length (`label` ...) and its duration when it ends; silent if not enabled."""
    out = stream if stream is not None else sys.stderr
    t0 = clock()
    if enabled:
        out.write(f"prlpid-fmi: {label} ...\n")
        out.flush()
    yield
    _record(label, clock() - t0)
    if enabled:
        out.write(f"prlpid-fmi: {label}: done in {format_duration(clock() - t0)}\n")
        out.flush()


def training_progress(stream: TextIO | None = None):
    """An SB3 callback that shows training steps done of the target (resumed steps included) on stderr."""
    from stable_baselines3.common.callbacks import BaseCallback

    class TrainingProgress(BaseCallback):
        def _on_training_start(self) -> None:
            # learn() has already added the resumed steps to its local total_timesteps
            self.progress = Progress("training", "steps", total=int(self.locals["total_timesteps"]),
                                     start=int(self.model.num_timesteps), stream=stream)

        def _on_step(self) -> bool:
            self.progress.update(self.num_timesteps)
            return True

        def _on_training_end(self) -> None:
            self.progress.close()

    return TrainingProgress()
