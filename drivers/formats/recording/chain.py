"""The parts of the recording in progress: one per camera stream, the previous one still taking its centrelines."""

from __future__ import annotations

import logging
import re
from collections.abc import Callable
from pathlib import Path

from flagtrack.drivers.formats.recording.inputs import TrackerUpdates
from flagtrack.drivers.formats.recording.part import RecordingPart

log = logging.getLogger(__name__)


class PartChain:
    """The current part and, after a roll-over to a new camera stream, the previous one while it still
    takes its stream's centrelines (the tracker's lag the packets).

    Parts closed are listed in :attr:`finished`. A part whose writing fails (a full disk) is abandoned
    (its .raw file cut back to its last flush, so it reads back whole) and ``on_failure`` is told the
    part and a one-line message.
    """

    def __init__(self, on_failure: Callable[[RecordingPart, str], None]) -> None:
        self.current: RecordingPart | None = None
        self.draining: RecordingPart | None = None
        self.finished: list[Path] = []
        self._on_failure = on_failure

    def begin(self, part: RecordingPart) -> None:
        """Make ``part`` the current one (its first sidecar written).

        Raises:
            OSError: the sidecar cannot be written (a path under a file ...); ``part`` is not current.
        """
        part.write_sidecar()
        self.current = part

    def stop(self) -> RecordingPart | None:
        """Close the previous part and the current one; returns the current one (None if there was none)."""
        self.close_draining()
        part, self.current = self.current, None
        if part is not None:
            self.close(part)
        return part

    def close(self, part: RecordingPart) -> None:
        """Close ``part`` (final sidecar), or abandon it if that fails."""
        try:
            part.close()
        except (OSError, RuntimeError) as exc:  # a full disk at the last flush
            self.fail(exc, part)
            return
        self.finished.append(part.raw_path)
        log.info(
            "recorder: closed %s (%d packets, %d bytes, %d gaps)",
            part.raw_path,
            part.packets,
            part.bytes,
            len(part.gaps),
        )

    def close_draining(self) -> None:
        """Close the previous part, if one still takes centrelines."""
        if self.draining is not None:
            part, self.draining = self.draining, None
            self.close(part)

    def fail(self, exc: BaseException, part: RecordingPart | None = None) -> None:
        """Writing ``part`` (by default the current one, which is then none) failed: abandon it."""
        if part is None or part is self.current:
            part, self.current = self.current, None
        if part is None:
            return
        path, why = failed_write(exc, part.raw_path)
        message = f"recording stopped: writing {path} failed: {why}; "
        if path == part.raw_path:
            message += f"the file is kept up to its last flush ({part.flushed_at} bytes)"
        else:
            message += f"{part.raw_path.name} is kept up to its last flush ({part.flushed_at} bytes)"

        part.abandon()
        self.finished.append(part.raw_path)
        self._on_failure(part, message)

    def roll_over(self, first_sent_ns: int) -> tuple[RecordingPart, RecordingPart]:
        """A new camera stream, its first packet sent at ``first_sent_ns``: close the current part's .raw
        file and make the next part current; the old part keeps taking centrelines if it records them.
        Returns (old part, new part)."""
        old = self.current
        if old is None:
            raise ValueError("roll_over without a current part")
        new = old.next_part()
        new.first_sent_ns = first_sent_ns
        self.close_draining()
        old.close_raw()
        if old.want_centrelines:
            self.draining = old
        else:
            self.close(old)
        self.begin(new)
        return old, new

    @property
    def takes_centrelines(self) -> bool:
        """Whether a part (the current one, or the previous one still draining) records centrelines."""
        return self.draining is not None or (self.current is not None and self.current.want_centrelines)

    def take_centrelines(self, msg: TrackerUpdates) -> None:
        """Write ``msg`` to the previous part while it is of its stream, else to the current one; the
        previous part is closed once the tracker is on the new stream or at its final message.

        Raises:
            SchemaError: the message does not fit its part's file (not recorded).
        """
        target, draining = self.current, self.draining
        if draining is not None:
            if self._of_previous_stream(msg):
                target = draining
            else:  # the tracker is on the new stream: the old one's centrelines are all in
                self.close_draining()
        try:
            if target is not None:
                target.write_centrelines(msg)
        finally:
            if msg.final and target is draining is not None:
                self.close_draining()

    def _of_previous_stream(self, msg: TrackerUpdates) -> bool:
        """Whether ``msg`` (while a previous part drains) comes from packets older than the current
        part's first (an empty one, such as a final message, goes with the previous part). O(1)."""
        first_ns = self.current.first_sent_ns if self.current is not None else None
        return len(msg.source_ns) == 0 or first_ns is not None and 0 < msg.source_ns[-1] < first_ns


def failed_write(exc: BaseException, default: Path) -> tuple[Path, str]:
    """The file a failed write names (``default`` if it names none) and why, in one line: an
    ``OSError``'s own, or what HDF5's error text (h5py's ``OSError`` or ``RuntimeError``, several
    lines) says of the file and the system's error."""
    filename = exc.filename if isinstance(exc, OSError) else None
    text = (exc.strerror if isinstance(exc, OSError) else None) or str(exc)
    named = re.search(r"filename = '(.+?)', file descriptor", text) or re.search(r"filename = '([^']+)'", text)
    system = re.search(r"error message = '(.+?)', buf", text) or re.search(r"error message = '([^']+)'", text)
    path = Path(filename) if filename else Path(named.group(1)) if named else default
    first_line = text.splitlines()[0] if text else type(exc).__name__
    return path, system.group(1) if system else first_line
