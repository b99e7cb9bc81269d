"""Files that must stay private to their owner: private keys, password files."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from flagtrack.daemon.errors import ConfigError


def require_private(path: Path, *, key: str) -> Path:
    """``path`` if it is a file only its owner may read or write (a private key, a password).

    Raises:
        ConfigError: missing, a folder, or readable or writable by its group or others (naming ``key``).
    """
    try:
        info = os.stat(path)
    except OSError as exc:
        raise ConfigError(f"cannot read {path}: {exc.strerror}", key=key) from exc
    if not stat.S_ISREG(info.st_mode):
        raise ConfigError(f"{path} is not a file", key=key)
    mode = stat.S_IMODE(info.st_mode)
    if mode & 0o077:
        raise ConfigError(f"{path} may be read by others (mode {mode:o}): chmod 600 it", key=key)
    return path
