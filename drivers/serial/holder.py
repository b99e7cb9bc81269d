"""Who holds the lock of a device: the ``flock`` owners listed in Linux's ``/proc/locks``, for the one
line that refuses a second owner of a serial port."""

from __future__ import annotations

import os
from pathlib import Path


def port_holders(device: str, proc: Path = Path("/proc")) -> list[str]:
    """``pid N (command line)`` of each process holding an ``flock`` on ``device`` (the command is
    ``?`` where this user may not see it); empty where ``/proc/locks`` cannot be read."""
    try:
        target = os.stat(device)
        table = (proc / "locks").read_text()
    except OSError:
        return []
    wanted = f"{os.major(target.st_dev):02x}:{os.minor(target.st_dev):02x}:{target.st_ino}"
    holders = []
    for line in table.splitlines():
        words = line.split()
        if len(words) >= 6 and words[1] == "FLOCK" and _same_file(words[5], wanted) and words[4].isdigit():
            pid = int(words[4])
            who = "this process" if pid == os.getpid() else _command(proc / str(pid))
            holders.append(f"pid {pid} ({who})")
    return sorted(set(holders))


def _same_file(field: str, wanted: str) -> bool:
    """``/proc/locks``' ``major:minor:inode`` against ours (the kernel prints the numbers in hex or
    decimal padding depending on its version: compare as numbers)."""
    try:
        major, minor, inode = field.split(":")
        w_major, w_minor, w_inode = wanted.split(":")
        return (int(major, 16), int(minor, 16), int(inode)) == (int(w_major, 16), int(w_minor, 16), int(w_inode))
    except ValueError:
        return False


def _command(pid_dir: Path) -> str:
    try:
        words = (pid_dir / "cmdline").read_bytes().split(b"\0")
    except OSError:
        return "?"
    text = " ".join(w.decode(errors="replace") for w in words if w)
    return text[:120] or "?"
