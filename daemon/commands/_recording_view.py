"""What ``flagtrack up`` shows while its recorder records: the file, the time, the size, the rate.

On a terminal, one line redrawn every second (log messages print above it); elsewhere (a pipe, the
journal), a line when a recording begins and one a minute; in both, a line for each file closed
(``recorded recordings/test1.raw: 134.4 MB``), so the end of a run says where the events went.
It reads the recorder service's open part from its own thread: sizes and counts only, never a file.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, TextIO

from flagtrack.daemon.commands._progress import TerminalView, clock

TICK_S = 1.0  # the terminal's line is redrawn this often
PLAIN_EVERY_S = 60.0  # elsewhere, a line this often


def recording_line(path: Path, elapsed_s: float, size_bytes: int, rate_ev_s: float, lost_packets: int) -> str:
    """``recording recordings/test1.raw  0:12  80.3 MB  6.7 Mev/s`` (and ``lost 3 packets``)."""
    rate = f"  {rate_ev_s / 1e6:.1f} Mev/s" if rate_ev_s >= 0 else ""
    lost = f"  lost {lost_packets} packets" if lost_packets else ""
    return f"recording {path}  {clock(elapsed_s)}  {size_bytes / 1e6:.1f} MB{rate}{lost}"


def recorded_line(path: Path) -> str:
    """``recorded recordings/test1.raw: 134.4 MB, 0:20 of camera time``, and the packets its sidecar
    says were lost (or why its size is not known)."""
    try:
        said = f"{path.stat().st_size / 1e6:.1f} MB"
    except OSError as exc:
        return f"recorded {path}: size not known ({exc.strerror})"
    sidecar = path.with_suffix(".json")
    try:
        facts = json.loads(sidecar.read_text())
        span_us = int(facts["t_last_us"]) - int(facts["t_first_us"])
        lost = int(facts.get("missing_packets", 0)) + int(facts.get("dropped_packets", 0))
    except (OSError, ValueError, KeyError, TypeError):  # no sidecar, or one without times: the size alone
        return f"recorded {path}: {said}"
    said += f", {clock(span_us * 1e-6)} of camera time"
    if lost:
        said += f", {lost} packets lost (see {sidecar.name})"
    return f"recorded {path}: {said}"


class RecordingView(TerminalView):
    """Shows the recorder service's recording while a rig runs (call it with the rig's services).

    Args:
        command: the command, for the plain lines (``flagtrack up: recording ...``).
        stream, quiet, terminal: :class:`.TerminalView`'s (on a terminal, one line redrawn in place).
    """

    def __init__(
        self, command: str = "up", stream: TextIO | None = None, *, quiet: bool = False, terminal: bool | None = None
    ) -> None:
        super().__init__(stream, quiet=quiet, terminal=terminal)
        self.command = command
        self._recorder: Any = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._reported: set[Path] = set()
        self._shown: Path | None = None
        self._last_plain = 0.0
        self._last_count: tuple[float, int] | None = None

    def __call__(self, services: Sequence[Any]) -> None:
        """Watch the rig's recorder, if it has one."""
        self._recorder = next((s for s in services if getattr(s, "name", "") == "recorder"), None)
        if self._recorder is None or self.quiet:
            return
        self._log_above_bar()
        self._thread = threading.Thread(target=self._watch, name="recording-view", daemon=True)
        self._thread.start()

    def __enter__(self) -> RecordingView:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def close(self) -> None:
        """Stop watching; a line for each file closed and not yet said (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        self._close_terminal()
        if self._recorder is not None and not self.quiet:
            self._say_finished()

    def tick(self, now_s: float) -> None:
        """Draw the state of the recording at monotonic time ``now_s`` (the watch thread's step)."""
        part = self._recorder.current
        if part is None or not part.opened:  # not recording (any more): no line left standing
            self._close_bar()
            self._shown = None
            self._say_finished()
            return
        self._say_finished()  # (a part closed for a new camera stream: said above the new part's line)
        if part.raw_path != self._shown:  # a new recording (or part): its rate starts afresh
            self._shown, self._last_count = part.raw_path, None
            self._last_plain = -PLAIN_EVERY_S
        rate = -1.0
        if self._last_count is not None and now_s > self._last_count[0]:
            rate = (part.events - self._last_count[1]) / (now_s - self._last_count[0])
        self._last_count = (now_s, part.events)
        line = recording_line(
            part.raw_path, time.time() - part.started_wall, part.bytes, rate, part.dropped + part.missing_packets
        )
        if self.terminal:
            self._draw(line)
        elif now_s - self._last_plain >= PLAIN_EVERY_S:
            self._last_plain = now_s
            self._write(f"flagtrack {self.command}: {line}")

    def _watch(self) -> None:
        while not self._stop.wait(TICK_S):
            self.tick(time.monotonic())

    def _say_finished(self) -> None:
        for path in list(self._recorder.finished):
            if path not in self._reported:
                self._reported.add(path)
                self._write(f"flagtrack {self.command}: {recorded_line(path)}")

    def _draw(self, line: str) -> None:
        if self._bar is None:
            from tqdm import tqdm

            self._bar = tqdm(file=self.stream, bar_format="{desc}", dynamic_ncols=True, leave=False)
        self._bar.set_description_str(line, refresh=True)
