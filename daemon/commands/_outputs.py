"""Outputs a command refuses before any work: a folder, a missing folder, one of its own inputs, or
a file that holds something else than what it writes."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from flagtrack.daemon.errors import ConfigError


def check_output(
    output: Path,
    option: str,
    inputs: Iterable[Path | None] = (),
    *,
    replaceable: Callable[[Path], bool | None] | None = None,
    holds: str = "",
    makes_folder: bool = False,
) -> None:
    """Refuse ``output`` (given as ``option``) in one line when it cannot be written or would destroy
    something: a folder, in a folder that does not exist (unless the command ``makes_folder``), one
    of ``inputs`` itself, or (where ``replaceable`` says so of the non-empty file there) a file that
    is not ``holds``, or one it cannot tell (None: unreadable, damaged)."""
    if output.is_dir():
        raise ConfigError(f"{option} {output}: is a directory (give the file to write)")
    if not makes_folder and not output.parent.is_dir():
        raise ConfigError(f"{option} {output}: folder {output.parent} does not exist")
    if output.parent.is_dir() and not os.access(output.parent, os.W_OK | os.X_OK):
        raise ConfigError(f"{option} {output}: folder {output.parent} is not writable")
    if not output.exists():
        return
    for source in inputs:
        if source is not None and source.exists() and output.resolve() == source.resolve():
            raise ConfigError(f"{option} {output}: is the input {source} itself (it would be overwritten)")
    if replaceable is None or not output.stat().st_size:
        return
    kind = replaceable(output)
    if kind is None:
        raise ConfigError(
            f"{option} {output}: cannot be read (damaged, in use or no permission): delete it or give a new file"
        )
    if not kind:
        raise ConfigError(f"{option} {output}: holds something else than {holds}: give a new file (it is left as is)")


def yaml_file_where(holds: Callable[[Any], bool]) -> Callable[[Path], bool]:
    """Whether a file is small YAML (a config, not a recording) whose content ``holds`` says yes to."""

    def check(path: Path) -> bool:
        import yaml

        try:
            if path.stat().st_size > 1 << 20:
                return False
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, yaml.YAMLError):
            return False
        return holds(data)

    return check


def only_yaml_sections(*sections: str) -> Callable[[Path], bool]:
    """Whether a file is YAML whose top level holds no keys but ``sections`` (an earlier output of the
    command, not a rig config)."""
    return yaml_file_where(lambda data: data is None or (isinstance(data, dict) and set(data) <= set(sections)))


def starts_with(*signatures: bytes) -> Callable[[Path], bool | None]:
    """Whether a file begins with one of ``signatures`` (its format's magic bytes); None: unreadable."""

    def check(path: Path) -> bool | None:
        try:
            with path.open("rb") as file:
                head = file.read(max(map(len, signatures)))
        except OSError:
            return None
        return head.startswith(signatures)

    return check


RRD = starts_with(b"RRF")
"""A Rerun ``.rrd`` file (an earlier view)."""

PICTURES = {".png": b"\x89PNG\r\n\x1a\n", ".pdf": b"%PDF", ".svg": b"<?xml"}
"""The picture formats a snapshot is written in, by suffix, with their signatures."""


def check_picture(output: Path, option: str, inputs: Iterable[Path | None] = (), *, makes_folder: bool = False) -> None:
    """As :func:`check_output`, and refuse a picture ``output`` whose suffix names no format of
    :data:`PICTURES` (matplotlib would fail after the work, or write ``OUT.png`` for ``OUT``); an
    earlier picture of its kind may be replaced."""
    signature = PICTURES.get(output.suffix.lower())
    replaceable = starts_with(signature) if signature is not None else None
    holds = f"a {output.suffix} picture"
    check_output(output, option, inputs, replaceable=replaceable, holds=holds, makes_folder=makes_folder)
    if signature is None:
        kinds = ", ".join(PICTURES)
        raise ConfigError(f"{option} {output}: give a picture file ({kinds}), not {output.suffix or 'no suffix'}")


def centrelines_file(path: Path) -> bool | None:
    """Whether ``path`` holds flagtrack centrelines (an earlier output that may be replaced)."""
    from flagtrack.drivers.formats.centreline import is_centreline_file

    return is_centreline_file(path)
