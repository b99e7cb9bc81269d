"""A sweep's progress on the command line: a line per finished point and, on a terminal, a bar.

Drawn from the :class:`~flagtrack.daemon.schema.SupervisorState` messages the supervisor publishes
(``run_rig(on_supervisor_state=view)`` hands each one to the view in the supervisor's thread), so
what a command prints is what a viewer on the bus receives. On a terminal: the lines scroll above a
tqdm bar (points done of the plan, elapsed time, ETA, the point being measured), and log messages
print above the bar too; elsewhere (a pipe, a file): plain lines, each with the elapsed time and
the ETA; ``quiet``: nothing.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from types import TracebackType
from typing import Any, TextIO

from flagtrack.daemon.schema import SupervisorState
from flagtrack.daemon.services.runner import is_terminal

REFRESH_S = 0.5  # the bar is redrawn at most this often (and at once when a point finishes)


def clock(seconds: float) -> str:
    """``1:05`` or ``2:01:05`` for a duration in seconds; ``?`` when not known (negative)."""
    if not seconds >= 0:
        return "?"
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


def _number(value: float, fmt: str, width: int) -> str:
    """``value`` formatted, or ``-`` (right-aligned to ``width``) when not known (negative)."""
    return format(value, fmt) if value >= 0 else "-".rjust(width)


def point_line(state: SupervisorState) -> str:
    """The line of the last finished point of ``state``, e.g.
    ``point  3/17  4.50 m/s up    flapping  A/L 0.231  f  12.4 Hz  lost 0.0 %  stale 0.0 %  e/L RMS 0.43 %  [0:42, ETA 1:38]``.

    Labels, units and digits are those of ``daemon/sweep/quantities.py`` (as README.txt shows them):
    ``lost`` is the % of the point's updates the tracker flagged lost (``-`` when the record has none),
    ``stale`` the % whose shape rests on no recent events (shown when known),
    ``e/L RMS`` the RMS error against the point sensor in % of L, shown when the point has one;
    ``SUSPECT`` ends the line of a point whose numbers may not be the flag's, with the chain's
    ``reach`` when that is why (the run log's line says why in words).
    """
    from flagtrack.daemon.core.chain_reach import TOLERANCE as REACH_TOLERANCE
    from flagtrack.daemon.sweep.quantities import show

    width = len(str(state.points_total))
    head = f"point {state.last_index:>{width}}/{state.points_total}  {state.last_speed_mps:5.2f} m/s {state.last_branch:<4}"
    times = f"[{clock(state.elapsed_s)}, ETA {clock(state.eta_s)}]"
    if state.last_status in ("failed", "lossy"):
        return f"{head}  {state.last_status.upper()} (the run log says why)  {times}"
    lost = show("lost_fraction", state.lost_fraction if state.lost_fraction >= 0 else None)
    if state.stale_fraction >= 0:
        lost += f"  {show('stale_fraction', state.stale_fraction)}"
    error = state.sensor_error_rms_over_l
    sensor = f"  {show('sensor_error_rms_over_l', error)}" if error >= 0 else ""
    suspect = "  SUSPECT" if state.last_suspect else ""
    if suspect and state.chain_reach >= 0 and abs(state.chain_reach - 1.0) > REACH_TOLERANCE:
        suspect += f" ({show('chain_reach', state.chain_reach)})"
    return (
        f"{head}  {state.last_state:<8}  A/L {_number(state.amplitude_over_l, '5.3f', 5)}  "
        f"f {_number(state.frequency_hz, '5.1f', 5)} Hz  {lost}{sensor}{suspect}  {times}"
    )


def bar_text(state: SupervisorState) -> str:
    """The text after the bar: elapsed, ETA, the point being measured and the flag's state."""
    now = (
        f"point {state.point_index}: {state.speed_mps:.2f} m/s {state.branch}, flag {state.flag_state}"
        if state.point_index
        else f"{state.mode}, flag {state.flag_state}"
    )
    return f"{clock(state.elapsed_s)} elapsed, ETA {clock(state.eta_s)} | {now}"


class TerminalView:
    """Lines on a stream and, on a terminal, a tqdm bar kept below them (log lines print above it).

    Args:
        stream: where to draw (default ``sys.stderr``).
        quiet: draw nothing.
        terminal: draw a bar (default: when ``stream`` is a terminal); otherwise plain lines.
    """

    def __init__(self, stream: TextIO | None = None, *, quiet: bool = False, terminal: bool | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.terminal = is_terminal(self.stream) if terminal is None else terminal
        self._bar: Any = None
        self._redirect: contextlib.ExitStack | None = None

    def _log_above_bar(self) -> None:
        """From now on, on a terminal, log lines (a warning from a service) print above the bar."""
        if self.terminal and not self.quiet and self._redirect is None:
            from tqdm.contrib.logging import logging_redirect_tqdm

            self._redirect = contextlib.ExitStack()
            self._redirect.enter_context(logging_redirect_tqdm())

    def _close_bar(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def _close_terminal(self) -> None:
        """Leave the bar as it last was and stop redirecting the log (idempotent)."""
        self._close_bar()
        if self._redirect is not None:
            self._redirect.close()
            self._redirect = None

    def _write(self, line: str) -> None:
        if self._bar is not None:
            self._bar.write(line, file=self.stream)
        else:
            print(line, file=self.stream, flush=True)


class SweepProgressView(TerminalView):
    """Draws the progress of a sweep from the supervisor's states (call it with each one); the
    arguments are :class:`TerminalView`'s."""

    def __init__(self, stream: TextIO | None = None, *, quiet: bool = False, terminal: bool | None = None) -> None:
        super().__init__(stream, quiet=quiet, terminal=terminal)
        self._lock = threading.Lock()
        self._started = False
        self._finished = 0
        self._records = 0
        self._last_draw = 0.0

    def __enter__(self) -> SweepProgressView:
        self._log_above_bar()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __call__(self, state: SupervisorState) -> None:
        """Take one state: a line when a point has been recorded since the last one (a redone point
        gets a line for each record), the bar redrawn."""
        if self.quiet or state.points_total <= 0:
            return
        with self._lock:
            if not self._started:
                self._start(state)
            if state.point_records > 0:  # a line per point record (a redone point has two)
                new_point = state.point_records > self._records and bool(state.last_point)
                self._records = max(self._records, state.point_records)
            else:  # a supervisor that does not count its records
                new_point = state.points_done > self._finished and bool(state.last_point)
            self._finished = max(self._finished, state.points_done)
            if new_point:
                self._write(point_line(state))
            if self._bar is not None:
                now = time.monotonic()
                self._bar.n = state.points_done
                self._bar.set_description_str(bar_text(state), refresh=False)
                if new_point or now - self._last_draw >= REFRESH_S:
                    self._bar.refresh()
                    self._last_draw = now

    def close(self) -> None:
        """Leave the bar as it last was and stop redirecting the log (idempotent)."""
        with self._lock:
            self._close_terminal()

    def _start(self, state: SupervisorState) -> None:
        self._started = True
        self._finished = state.points_done
        self._records = state.point_records  # (a view that joins mid-sweep draws no line for the past)
        if self.terminal:
            from tqdm import tqdm

            self._bar = tqdm(
                total=state.points_total,
                initial=state.points_done,
                file=self.stream,
                bar_format="sweep {n_fmt}/{total_fmt} |{bar}| {desc}",
                dynamic_ncols=True,
                leave=True,
            )
            return
        before = f", {state.points_done} done before" if state.points_done else ""
        self._write(f"sweep: {state.points_total} points{before}, ETA {clock(state.eta_s)}")
