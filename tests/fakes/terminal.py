"""A command run with its stderr on a real pseudo-terminal, and what the terminal received."""

from __future__ import annotations

import fcntl
import os
import pty
import select
import struct
import subprocess
import termios
import time
from collections.abc import Sequence


def run_on_a_terminal(
    argv: Sequence[str], *, columns: int = 80, rows: int = 24, timeout_s: float = 60.0, exit_s: float = 30.0
) -> str:
    """Run ``argv`` (stdout discarded) with stderr on a pty of ``columns`` x ``rows``; return what it
    drew there once every process holding the terminal has closed it (or after ``timeout_s``: the
    command is then killed). Asserts that the command exited with 0 within ``exit_s`` after that."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, columns, 0, 0))
    try:
        proc = subprocess.Popen(list(argv), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=slave)
    finally:
        os.close(slave)
    received = bytearray()
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            if not select.select([master], [], [], 0.5)[0]:
                continue
            try:
                data = os.read(master, 4096)
            except OSError:  # EIO: every process holding the terminal has closed it
                break
            if not data:
                break
            received += data
    finally:
        os.close(master)
        if proc.poll() is None and time.monotonic() >= deadline:
            proc.kill()
        code = proc.wait(timeout=exit_s)
    shown = received.decode(errors="replace")
    assert code == 0, shown
    return shown
