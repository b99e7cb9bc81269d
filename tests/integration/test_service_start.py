"""Every service of a rig starts before any runs; one that cannot start stops the rig with one line, and
what the others opened is closed again (here: the supervisor's tunnel, a real pseudo-terminal whose
exclusive lock another program then takes), with the tunnel never commanded."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from flagtrack.daemon.cli import main
from flagtrack.daemon.rig.build import build_services
from flagtrack.daemon.rig.config import load_rig
from flagtrack.daemon.services.runner import StartError, run_services
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.tunnel.setup import open_tunnel
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel
from tests.integration.test_transport import free_port

NOWHERE = "192.0.2.1"  # TEST-NET-1 (RFC 5737): an address this host does not have


def rig_file(tmp_path: Path, port: str) -> Path:
    """A supervisor on the tunnel at ``port`` (first in the table: it starts first) and a viewer that
    serves on an address the host does not have (it starts after, and cannot)."""
    rig = {
        "rig": f"start{free_port()}",
        "bus": {"listen": [f"tcp/127.0.0.1:{free_port()}"]},
        "tunnel": {"driver": "ascii", "port": port, "timeout_s": 0.3},
        "supervisor": {"mode": "monitor", "runs_dir": str(tmp_path / "runs")},
        "viewer": {"sink": "serve", "serve_host": NOWHERE, "grpc_port": free_port(), "web_port": free_port()},
        "services": ["supervisor", "viewer"],
    }
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    return path


@pytest.mark.slow
def test_a_service_that_cannot_start_closes_those_started_before_it(sim: SimulatedTunnel, tmp_path: Path) -> None:
    rig = load_rig(rig_file(tmp_path, sim.port))
    with Bus(rig.bus_config) as bus:
        services = build_services(rig, bus, list(rig.services))
        with pytest.raises(StartError) as caught:
            run_services(services, handle_signals=False)
        supervisor = services[0]
        assert supervisor.tunnel is not None  # type: ignore[attr-defined]  # it had started: the tunnel opened
        again = open_tunnel(rig.tunnel)  # type: ignore[arg-type]  # its lock is free: the supervisor closed it
        again.close()
    message = str(caught.value)
    assert message.startswith("the viewer service could not start: ") and NOWHERE in message and "\n" not in message
    assert sim.valid_commands == 0  # never started, never commanded


@pytest.mark.slow
def test_up_says_which_service_could_not_start_in_one_line(
    sim: SimulatedTunnel, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["up", "-q", "-c", str(rig_file(tmp_path, sim.port))]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flagtrack up: error: the viewer service could not start: "), lines
    assert "key 'viewer.serve_host'" in lines[0] and sim.valid_commands == 0
