"""What a batch output was made from, recorded in it, and the check that makes a rerun skip it.

Each centreline file a batch writes carries, as HDF5 root attributes (all named ``batch_*``):

- ``batch_input_size``, ``batch_input_mtime_ns``: the input's size (bytes) and modification time (ns)
  when it was read;
- ``batch_input_blake2b``: BLAKE2b (32 bytes, hex) of the input's content, streamed in 1 MiB blocks;
- ``batch_params_blake2b``: BLAKE2b of the effective parameters: the tracking set-up's attributes
  (every processing parameter, the calibration's attributes, the units) and the flagtrack version,
  as canonical JSON; per-file provenance (``input_file``, ``input_format``, event counts) is not in it.

An output is up to date when it holds these, its ``input_file`` is the input (resolved), the parameters'
digest and the input's size are the same, and either the modification time is the same or, when it
differs (a copy, a ``touch``), the content's digest is. ``checksum`` compares the content's digest
whatever the time says.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flagtrack.daemon import __version__

SIZE, MTIME, DIGEST, PARAMS = "batch_input_size", "batch_input_mtime_ns", "batch_input_blake2b", "batch_params_blake2b"
STAMP_ATTRS = (SIZE, MTIME, DIGEST, PARAMS)
_BLOCK = 1 << 20


def file_digest(path: str | Path) -> str:
    """BLAKE2b-256 of the file's content, hex, read in 1 MiB blocks (about 0.8 GB/s on one core here)."""
    digest = hashlib.blake2b(digest_size=32)
    block = bytearray(_BLOCK)
    view = memoryview(block)
    with open(path, "rb", buffering=0) as handle:
        while n := handle.readinto(block):
            digest.update(view[:n])
    return digest.hexdigest()


def params_digest(attrs: Mapping[str, Any]) -> str:
    """BLAKE2b-256 (hex) of the parameters ``attrs`` (a tracking set-up's ``attrs``) and flagtrack's version."""
    text = json.dumps({**attrs, "flagtrack_version": __version__}, sort_keys=True, default=_plain, allow_nan=True)
    return hashlib.blake2b(text.encode(), digest_size=32).hexdigest()


def _plain(value: Any) -> Any:
    """JSON for what ``json`` does not know: paths, NumPy scalars and arrays."""
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"cannot digest a parameter of type {type(value).__name__}")


@dataclass(frozen=True)
class InputStat:
    """The input's size (bytes) and modification time (ns) as the file system reports them."""

    size: int
    mtime_ns: int

    @classmethod
    def of(cls, path: str | Path) -> InputStat:
        """Stat ``path`` (raises ``OSError`` if it cannot)."""
        st = os.stat(path)
        return cls(st.st_size, st.st_mtime_ns)


def stamp_attrs(stat: InputStat, digest: str, params: str) -> dict[str, Any]:
    """The ``batch_*`` attributes of an output made from an input of ``stat`` and ``digest`` with ``params``."""
    return {SIZE: stat.size, MTIME: stat.mtime_ns, DIGEST: digest, PARAMS: params}


def read_stamp(output: str | Path) -> dict[str, Any] | None:
    """The ``batch_*`` attributes and ``input_file`` of an output, or None (absent, unreadable, unstamped)."""
    import h5py

    try:
        with h5py.File(output, "r") as f:
            if not all(name in f.attrs for name in (*STAMP_ATTRS, "input_file")):
                return None
            return {name: _value(f.attrs[name]) for name in (*STAMP_ATTRS, "input_file")}
    except OSError:  # absent, or not HDF5
        return None


def _value(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    return value.item() if hasattr(value, "item") else value


def up_to_date(
    recorded: Mapping[str, Any] | None, input_file: str, stat: InputStat, params: str, *, checksum: bool = False
) -> bool | None:
    """Whether an output stamped ``recorded`` is up to date, without reading the input if possible.

    Returns:
        False: redo it (no stamp, another input file, other parameters, another size); True: up to date
        (same modification time, and ``checksum`` not asked); None: only the content's digest can tell
        (compare :func:`file_digest` of the input with ``recorded[DIGEST]``).
    """
    if recorded is None or recorded["input_file"] != input_file or recorded[PARAMS] != params:
        return False
    if int(recorded[SIZE]) != stat.size:
        return False
    if int(recorded[MTIME]) == stat.mtime_ns and not checksum:
        return True
    return None
