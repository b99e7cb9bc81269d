"""Where a recording's files go: ``BASE.raw``, its sidecar ``BASE.json``, its ``BASE_centrelines.h5``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

RECORDING_SUFFIXES = (".raw", ".json", "_centrelines.h5")
"""The files of a recording ``BASE``: ``BASE.raw``, its sidecar, its centrelines."""


def recording_base(directory: str | Path, path: str) -> Path:
    """The base path (no extension) of a recording named ``path``: as given if absolute, else in ``directory``."""
    base = Path(path).expanduser()
    return base if base.is_absolute() else Path(directory).expanduser() / base


def recording_file(base: Path, suffix: str) -> Path:
    """The file of recording ``base`` with ``suffix`` (one of :data:`RECORDING_SUFFIXES`)."""
    return base.with_name(base.name + suffix)


def confined_base(path: str, roots: Sequence[str | Path]) -> Path:
    """The base path of the recording a command names, if it stays inside one of ``roots``.

    ``path`` is relative to the first root, or absolute inside one. It is refused when it is empty,
    starts with ``~`` (not expanded: ``~user`` would name another home), has a ``..`` part, or
    resolves (symbolic links followed) outside every root, or when one of the recording's files is a
    symbolic link. Nothing is created. Returns the resolved path.

    Raises:
        ValueError: naming the path and why.
    """
    if not path or "\x00" in path:
        raise ValueError("an empty path or one with a NUL character")
    folders = [Path(root).expanduser().resolve() for root in roots]
    where = " or ".join(map(str, folders))
    if path.startswith("~"):
        raise ValueError(f"{path!r}: '~' is not expanded in a command; name a path in {where}")
    given = Path(path)
    if ".." in given.parts:
        raise ValueError(f"{path!r}: '..' is not allowed; name a path in {where}")
    resolved = (given if given.is_absolute() else folders[0] / given).resolve()
    if not any(resolved != folder and resolved.is_relative_to(folder) for folder in folders):
        raise ValueError(f"{path!r} resolves to {resolved}, outside {where}")
    for suffix in RECORDING_SUFFIXES:
        file = recording_file(resolved, suffix)
        if file.is_symlink():
            raise ValueError(f"{path!r}: {file} is a symbolic link")
    return resolved


def part_base(first_base: Path, part: int) -> Path:
    """The base of part ``part`` of the recording whose first part is ``first_base``: ``BASE_stream<part>``."""
    return first_base if part == 1 else first_base.with_name(f"{first_base.name}_stream{part}")
