"""The calibration's own error: a recording that does not let a calibration be made."""

from __future__ import annotations

from flagtrack.daemon.errors import FlagtrackError


class CalibrationError(FlagtrackError):
    """No blinking, no board, a board of another size, too few corners for the mapping.

    Args:
        message: what is wrong and what to try.
        path: the recording, if known.
    """

    def __init__(self, message: str, *, path: str | None = None) -> None:
        self.path = path
        super().__init__(f"{path}: {message}" if path else message)
