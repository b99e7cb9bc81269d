"""The viewer's `serve` sink listens on the address the rig names (loopback by default), not on every
interface as Rerun's own serve_grpc and serve_web_viewer do."""

from __future__ import annotations

from pathlib import Path

import pytest

from flagtrack.daemon.services.viewer import ViewerConfig, close_recording, open_recording
from tests.integration.test_transport import free_port


def listening(port: int) -> set[str]:
    """The local addresses (IPv4 dotted) on which something listens on TCP ``port`` (Linux /proc)."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            address, hex_port = local.split(":")
            if state == "0A" and int(hex_port, 16) == port:  # LISTEN
                if len(address) == 8:
                    found.add(".".join(str(int(address[i : i + 2], 16)) for i in (6, 4, 2, 0)))
                else:
                    found.add("::" if set(address) == {"0"} else address)
    return found


@pytest.mark.parametrize("host", ["127.0.0.1", "0.0.0.0"])
def test_the_serve_sink_listens_where_the_config_says(host: str) -> None:
    cfg = ViewerConfig(sink="serve", serve_host=host, grpc_port=free_port(), web_port=free_port())
    rec, description = open_recording(cfg)
    try:
        addresses = listening(cfg.grpc_port) | listening(cfg.web_port)
        rec.log("probe", __import__("rerun").TextLog("hello"))
    finally:
        close_recording(rec)
    assert addresses == {host} and f":{cfg.web_port}" in description
    assert listening(cfg.grpc_port) == set()  # the server went with the recording


def test_the_default_is_loopback() -> None:
    assert ViewerConfig().serve_host == "127.0.0.1"
