"""Hardware adapters (on fake SDKs) built from a rig file, run by the real camera service over Zenoh.

Every event the fake camera's sensor produced arrives in the packets (up to the packets' completeness
horizon: the camera service holds back the slot still open when the camera stalls), the status carries
the settings read back, and a stalled camera ends the service with an error status naming the stall.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.errors import DriverError
from flagtrack.daemon.rig.build import open_camera
from flagtrack.daemon.rig.config import load_rig
from flagtrack.daemon.schema import CameraStatus, EventPacket
from flagtrack.daemon.services.camera import CameraService, CameraStreamConfig
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats.packets import decode_packet
from tests.fakes.helpers import wait_subscribed
from tests.integration.test_transport import free_port

RIGS = {
    "prophesee": """
camera:
  id: cam0
  adapter: prophesee
  hardware: {serial: "00050423", biases: {diff_off: 30}, trigger_in: true, stall_timeout_s: 0.5}
""",
    "metavision": """
camera:
  id: cam0
  adapter: metavision
  hardware: {serial: "00ca0009", biases: {bias_diff_off: 30}, trigger_in: true, stall_timeout_s: 0.5}
""",
    "inivation": """
camera:
  id: cam0
  adapter: inivation
  hardware: {serial: DXA00093, contrast_threshold_on: 12, trigger_in: true, stall_timeout_s: 0.5}
""",
}


def plug(adapter: str, request: pytest.FixtureRequest):
    if adapter == "prophesee":
        nd = request.getfixturevalue("fake_nd")
        return nd._fake.plug(nd.FakeCamera(duration_us=150_000, seed=5))
    if adapter == "metavision":
        hal = request.getfixturevalue("fake_hal")
        return hal._fake.plug(hal.FakeHalCamera(duration_us=150_000, seed=5))
    dv = request.getfixturevalue("fake_dv")
    return dv._fake.plug(dv.FakeDvCamera(duration_us=150_000, seed=5))


@pytest.mark.parametrize("adapter", ["prophesee", "metavision", "inivation"])
def test_service_publishes_the_sensor_events_and_reports_the_stall(
    adapter: str, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    fake = plug(adapter, request)
    rig_path = tmp_path / "rig.yaml"
    rig_path.write_text(RIGS[adapter])
    camera = open_camera(load_rig(rig_path).camera)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/hw", listen=(endpoint,))) as cam_bus,
        Bus(BusConfig(namespace="flagtrack/hw", connect=(endpoint,))) as sub_bus,
    ):
        packets_sub = sub_bus.subscribe(sub_bus.keys.camera_events("cam0"), EventPacket, capacity=1_000_000)
        status_sub = sub_bus.subscribe(sub_bus.keys.camera_status("cam0"), CameraStatus)
        wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"), cam_bus.keys.camera_status("cam0"))
        service = CameraService(cam_bus, CameraStreamConfig(), camera)
        service.start()
        failure: list[BaseException] = []

        def run() -> None:
            try:
                service.run(threading.Event())
            except BaseException as exc:  # noqa: BLE001 - the stall ends the service with DriverError
                failure.append(exc)

        thread = threading.Thread(target=run)
        thread.start()
        thread.join(timeout=120)  # generous: in a fresh clone the first run compiles the codec kernels
        assert not thread.is_alive()
        statuses = []
        while (status := status_sub.recv(timeout_s=2.0)) is not None:
            statuses.append(status)
            if status.state == "error":
                break
        packets = []
        while len(packets) < service.packets and (msg := packets_sub.recv(timeout_s=5.0)) is not None:
            packets.append(msg)
    assert len(failure) == 1 and isinstance(failure[0], DriverError)
    assert [s.state for s in statuses] == ["streaming", "error"]
    assert "camera stopped delivering data" in statuses[-1].message
    published = "evt2" if adapter == "metavision" else "evt3"  # OpenEB 5: events from the HAL's decoder
    assert statuses[0].adapter == adapter and statuses[0].encoding == published
    settings = statuses[0].settings
    if adapter == "prophesee":
        assert settings["biases"]["diff_off"] == 30 and settings["trigger_in"] is True
    elif adapter == "metavision":
        assert settings["biases"]["bias_diff_off"] == 30 and settings["trigger_in"] is True
    else:
        assert settings["contrast_threshold_on"] == 12 and settings["trigger_in"] is True
    assert [p.seq for p in packets] == list(range(len(packets)))
    horizon = max(p.t_last_us for p in packets)
    sent = fake.sent_events
    assert horizon > sent["t"][-1] - 2_000  # all but the slot still open when the camera stalled
    decoded = np.concatenate([decode_packet(p.encoding, p.data, p.t_offset_us)[0] for p in packets])
    np.testing.assert_array_equal(decoded, sent[sent["t"] <= horizon])
    triggers = np.concatenate([decode_packet(p.encoding, p.data, p.t_offset_us)[1] for p in packets])
    want = fake.sent_triggers
    np.testing.assert_array_equal(triggers, want[want["t"] <= horizon])
