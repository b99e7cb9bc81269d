"""Recordings flagtrack simulated say so in their RAW header; a camera's recordings keep naming its maker.

(That OpenEB's HAL still opens a simulated recording is tested on the real HAL in
tests/integration/test_camera_metavision_openeb.py.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon import __version__
from flagtrack.daemon.core.events import make_events
from flagtrack.daemon.schema import EventPacket
from flagtrack.daemon.services.recorder import RecordingPart
from flagtrack.drivers.formats import read_events
from flagtrack.drivers.formats.packets import Packetizer
from flagtrack.drivers.formats.raw_file import read_header_bytes
from flagtrack.drivers.formats.raw_header import parse_raw_header, raw_header
from flagtrack.drivers.sim.simulate import write_events_file

EVENTS = make_events(np.arange(0, 3000, 10), np.arange(300) % 64, np.arange(300) % 48, np.arange(300) % 2)


def header_fields(path: Path) -> dict[str, str]:
    return parse_raw_header(read_header_bytes(path))[0]


def test_a_simulated_header_names_flagtrack_and_no_camera_plugin() -> None:
    fields, _ = parse_raw_header(raw_header("evt3", 64, 48, {"camera_id": "cam0"}, simulated=True))
    assert fields["camera_integrator_name"] == fields["integrator_name"] == "flagtrack"
    assert fields["simulator"] == f"flagtrack {__version__}" and fields["camera_id"] == "cam0"
    assert not {"plugin_name", "plugin_integrator_name"} & set(fields)
    assert "Prophesee" not in raw_header("evt2", 64, 48, simulated=True).decode()
    camera, _ = parse_raw_header(raw_header("evt3", 64, 48))
    assert camera["camera_integrator_name"] == "Prophesee" and "simulator" not in camera


def test_flagtrack_simulate_writes_a_simulated_header(tmp_path: Path) -> None:
    path, n = write_events_file(tmp_path / "sim_00000", [EVENTS[:100], EVENTS[100:]], 64, 48)
    assert path.suffix == ".raw" and n == len(EVENTS)
    assert header_fields(path)["camera_integrator_name"] == "flagtrack"
    np.testing.assert_array_equal(read_events(path).events, EVENTS)


@pytest.mark.parametrize("adapter, integrator", [("simulated", "flagtrack"), ("metavision", "Prophesee")])
def test_the_recorder_says_a_simulated_camera_was_simulated(adapter: str, integrator: str, tmp_path: Path) -> None:
    packets = Packetizer("evt3", 64, 48).push(EVENTS, t_until_us=10_000)
    part = RecordingPart(base=tmp_path / "rec", config={"camera": {"id": "cam0", "adapter": adapter}})
    for seq, p in enumerate(packets):
        part.write_packet(
            EventPacket("cam0", seq, p.t_first_us, p.t_last_us, p.n_events, 64, 48, "evt3", 1, data=p.data)
        )
    part.close()
    fields = header_fields(part.raw_path)
    assert fields["camera_integrator_name"] == integrator and fields["camera_id"] == "cam0"
    assert ("simulator" in fields) == (adapter == "simulated")
    np.testing.assert_array_equal(read_events(part.raw_path).events, EVENTS)
