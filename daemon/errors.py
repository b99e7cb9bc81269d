"""Domain exceptions. Each carries what a user needs to find the problem (file, offset, key, device).

The CLI turns any :class:`FlagtrackError` into one clear line on stderr and a non-zero exit.
"""

from __future__ import annotations


class FlagtrackError(Exception):
    """Base class of every error flagtrack reports to a user."""


class ConfigError(FlagtrackError):
    """A configuration value is missing, of the wrong type or out of range.

    Args:
        message: what is wrong.
        key: dotted key of the offending value (``tracker.alpha``), or the option that gave it
            (``--root``), if known.
        path: configuration file, if the value came from one.
    """

    def __init__(self, message: str, *, key: str | None = None, path: str | None = None) -> None:
        self.message = message
        self.key = key
        self.path = path
        named = key and (key if key.startswith("-") else f"key '{key}'")  # (an option: ``--root``)
        where = ", ".join(part for part in (path and f"file {path}", named) if part)
        super().__init__(f"{where}: {message}" if where else message)


class FormatError(FlagtrackError):
    """An event or data file cannot be decoded.

    Args:
        message: what is wrong.
        path: the file (or packet source) being decoded.
        offset: byte offset of the fault in that file, if known.
    """

    def __init__(self, message: str, *, path: str | None = None, offset: int | None = None) -> None:
        self.path = path
        self.offset = offset
        where = ", ".join(part for part in (path and f"{path}", offset is not None and f"byte {offset}") if part)
        super().__init__(f"{where}: {message}" if where else message)


class DriverError(FlagtrackError):
    """A device (camera, wind tunnel, sensor) failed or did not answer.

    Args:
        message: what is wrong.
        device: device name or port (``/dev/ttyUSB0``, ``camera 'main'``).
    """

    def __init__(self, message: str, *, device: str | None = None) -> None:
        self.device = device
        super().__init__(f"{device}: {message}" if device else message)


class PortInUseError(DriverError):
    """A serial port another process holds (opened exclusively): the message names the holder."""


class SchemaError(FlagtrackError):
    """A bus message is malformed or of an unknown version.

    Args:
        message: what is wrong.
        key: the key expression the message arrived on, if known.
    """

    def __init__(self, message: str, *, key: str | None = None) -> None:
        self.key = key
        super().__init__(f"message on '{key}': {message}" if key else message)
