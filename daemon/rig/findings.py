"""What checking a rig found short of an error: notes on what this host does not have yet.

A rig file can be right while the host is not ready for it: the calibration it names is made on the
first day (``flagtrack calibrate -o``), the tunnel's controller is not plugged in, the camera's SDK is
not installed. ``flagtrack config check`` lists these as notes and exits 0; every command that runs
the rig (``up``, ``sweep``, a service alone) checks strictly (``Findings()``), where the first note is the
one-line error it always was. With ``files`` off (a config written for another host), nothing of
this host is looked at: no file, folder, port or SDK.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from flagtrack.daemon.errors import ConfigError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Note:
    """One thing the host lacks for the rig (``pending``), or a warning, and what to do about it."""

    key: str
    text: str
    pending: bool = True

    def __str__(self) -> str:
        return f"key '{self.key}': {self.text}"


@dataclass
class Findings:
    """The notes of one check.

    Attributes:
        strict: a note is raised as a :class:`ConfigError` (the commands that run the rig).
        files: look at this host's files, folders, ports and SDKs (off: a config for another host).
        notes: what was noted, in order.
    """

    strict: bool = True
    files: bool = True
    notes: list[Note] = field(default_factory=list)

    def note(self, text: str, *, key: str, path: str | None, error: str | None = None) -> None:
        """Note what the host lacks; strict: raise ``error`` (default ``text``) naming ``key`` and ``path``."""
        if self.strict:
            raise ConfigError(error or text, key=key, path=path)
        self._add(Note(key, text))

    def later(self, text: str, *, key: str) -> None:
        """Note what the host lacks where the step that needs it says so itself (a camera's SDK, when
        the camera opens): strict, nothing is done here."""
        if not self.strict:
            self._add(Note(key, text))

    def warn(self, text: str, *, key: str) -> None:
        """A warning: noted, never raised (strict: logged, the commands that run the rig say it too)."""
        if self.strict:
            log.warning("key '%s': %s", key, text)
        self._add(Note(key, text, pending=False))

    def _add(self, note: Note) -> None:
        if note not in self.notes:  # once (a file two services need)
            self.notes.append(note)
