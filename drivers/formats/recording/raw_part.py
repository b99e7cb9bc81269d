"""The ``.raw`` file of one recording part: a RAW header and time-base preamble, then packet bytes."""

from __future__ import annotations

import os
from pathlib import Path
from typing import BinaryIO

from flagtrack.daemon import __version__
from flagtrack.drivers.formats.packets import stream_preamble
from flagtrack.drivers.formats.raw_header import raw_header


class RawPartFile:
    """A ``.raw`` file written packet by packet, readable whole up to its last :meth:`flush`.

    Created by :meth:`open` (the first packet's encoding, geometry and time offset); bytes are
    appended by :meth:`write`; :attr:`flushed_at` is the size at the last flush, what :meth:`abandon`
    cuts the file back to after a failed write.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.flushed_at = 0
        self._file: BinaryIO | None = None

    @property
    def opened(self) -> bool:
        """Whether the file was created."""
        return self._file is not None

    def open(
        self, encoding: str, width: int, height: int, camera_id: str, t_offset_us: int, simulated: bool = False
    ) -> None:
        """Create the file with its header and the time-base preamble of ``t_offset_us`` (``simulated``:
        the header says flagtrack simulated the camera).

        Raises:
            FormatError: no header or preamble for this encoding, offset or camera id; nothing is created.
        """
        start = raw_header(
            encoding,
            width,
            height,
            {"camera_id": camera_id, "recorder": f"flagtrack-{__version__}"},
            simulated=simulated,
        ) + stream_preamble(encoding, t_offset_us)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close() or abandon()
        self._file.write(start)
        self.flush()

    def write(self, data: bytes | memoryview) -> None:
        """Append ``data`` (buffered: on disk at the next :meth:`flush`)."""
        assert self._file is not None, "RawPartFile.write before open"
        self._file.write(data)

    def flush(self) -> None:
        """Hand the written bytes to the OS (a crash after this keeps them)."""
        if self._file is not None and not self._file.closed:
            self._file.flush()
            self.flushed_at = self._file.tell()

    def fsync(self) -> None:
        """Force the flushed bytes to disk."""
        if self._file is not None and not self._file.closed:
            os.fsync(self._file.fileno())

    def close(self) -> None:
        """Flush, fsync and close. Idempotent."""
        if self._file is not None and not self._file.closed:
            self.flush()
            self.fsync()
            self._file.close()

    def abandon(self) -> None:
        """After a failed write (a full disk): close, and cut the file back to its last flush so it
        reads back whole up to there.

        Raises:
            OSError: closing or cutting back failed too (the file is closed all the same).
        """
        if self._file is None:
            return
        try:
            if not self._file.closed:
                self._file.close()
        finally:
            os.truncate(self.path, self.flushed_at)
