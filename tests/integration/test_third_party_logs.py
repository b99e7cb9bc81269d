"""No third-party log line before flagtrack's own error (issue 32): a Modbus drive that cannot be
opened gives the one ``flagtrack tunnel: error: ...`` line, not pymodbus's ERROR line before it."""

from __future__ import annotations

import os
import pty
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
MODBUS_TUNNEL = REPO / "deploy" / "tunnel-modbus.yaml"


@pytest.fixture
def pty_port() -> Iterator[str]:
    """A real pseudo-terminal nobody answers on (the 8E1 line settings of a Modbus drive fail on it)."""
    master, slave = pty.openpty()
    try:
        yield os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


def tunnel_get(port: str, *options: str) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, "-m", "flagtrack.daemon", *options, "tunnel", "get", "-c", str(MODBUS_TUNNEL)]
    return subprocess.run([*argv, "--port", port], capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("where", ["pty", "regular file"])
def test_a_modbus_drive_that_cannot_be_opened_is_one_line(where: str, pty_port: str, tmp_path: Path) -> None:
    port = pty_port if where == "pty" else str(tmp_path / "not-a-tty")
    if where != "pty":
        Path(port).write_bytes(b"")
    result = tunnel_get(port)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("flagtrack tunnel: error: "), result.stderr
    assert port in lines[0] and "Modbus" in lines[0]
    assert "pymodbus" not in result.stderr


def test_pymodbus_speaks_with_vv(tmp_path: Path) -> None:
    """What pymodbus says is silenced, not lost: -vv (debug) shows it before flagtrack's line."""
    port = tmp_path / "not-a-tty"
    port.write_bytes(b"")
    result = tunnel_get(str(port), "-vv")
    assert result.returncode == 2
    assert "pymodbus" in result.stderr
    assert result.stderr.splitlines()[-1].startswith("flagtrack tunnel: error: ")
