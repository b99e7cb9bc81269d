"""What this host has for a rig, looked at without opening anything: serial ports, camera SDKs, free
space, the files the first day makes (:class:`~.findings.Findings` says what it lacks)."""

from __future__ import annotations

import importlib.util
import os
import shutil
from pathlib import Path

from flagtrack.daemon.rig.findings import Findings

SDK_MODULES = {"prophesee": "neuromorphic_drivers", "metavision": "metavision_hal", "inivation": "dv_processing"}
"""The import name of each hardware camera adapter's SDK."""
URL_SCHEMES = ("socket://", "rfc2217://", "loop://", "spy://", "hwgrep://", "alt://", "cp2110://")


def check_port(port: str, *, key: str, what: str, findings: Findings) -> None:
    """Note a serial device path that is not there now, or that this user may not open (a pyserial URL
    is not looked at); the rig's commands say so themselves when they open it."""
    if not findings.files or not port or port.startswith(URL_SCHEMES):
        return
    device = Path(port)
    if not device.exists():
        findings.later(
            f"{port} is not there now: plug {what} in (a USB adapter gets a stable name from a udev rule: "
            "deploy/99-flagtrack.rules)",
            key=key,
        )
    elif not os.access(device, os.R_OK | os.W_OK):
        findings.later(f"{port}: this user may not open it: add the user to its group (ls -l {port})", key=key)


def sdk_missing(adapter: str) -> str | None:
    """The SDK module the hardware ``adapter`` needs if it cannot be found here (None: found, or no SDK)."""
    module = SDK_MODULES.get(adapter)
    if module is None:
        return None
    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a module in sys.modules without a spec (a test's stand-in): there
        found = True
    return None if found else module


def free_bytes(folder: str | Path) -> int | None:
    """Free space for this user on the disk ``folder`` is (or would be made) on; None if unknown."""
    existing = Path(folder).expanduser().absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    try:
        return shutil.disk_usage(existing).free
    except OSError:
        return None


def size_text(n_bytes: float) -> str:
    """``n_bytes`` for people: ``4.8 GB``, ``310 MB``."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.1f} {unit}"
    return f"{n_bytes / 1e3:.0f} kB"
