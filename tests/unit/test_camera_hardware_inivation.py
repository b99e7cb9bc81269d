"""The inivation adapter against a fake ``dv_processing`` giving decoded event batches in Unix time."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from flagtrack.daemon.errors import ConfigError, DriverError
from flagtrack.drivers.camera import inivation
from tests.fakes.helpers import read_until

DOC_YAML = """
camera:
  id: cam0
  adapter: inivation
  hardware:
    serial: DXA00093
    roi: {x: 40, y: 20, width: 560, height: 440}
    contrast_threshold_on: 12
    contrast_threshold_off: 40
    readout_fps: VARIABLE_15000
    trigger_in: true
"""


def _all_handed(camera: inivation.InivationCamera) -> bool:
    cam = camera._camera
    return cam._batches is not None and cam._handed >= len(cam._batches)


def test_events_and_triggers_arrive_exactly_in_camera_time(fake_dv) -> None:
    fake = fake_dv._fake.plug(fake_dv.FakeDvCamera())
    camera = inivation.open_from_config({"trigger_in": True})
    info = camera.open()
    assert (info.adapter, info.width, info.height, info.encoding, info.serial) == (
        "inivation",
        640,
        480,
        "evt3",
        "DXA00093",
    )
    assert info.settings["timestamp_offset_us"] == fake.timestamp_offset_us
    events, triggers, reads = read_until(camera, lambda: _all_handed(camera))
    assert reads > 5 and len(events) > 5000
    np.testing.assert_array_equal(events, fake.events)  # times back on the camera's clock, from 0
    np.testing.assert_array_equal(triggers, fake.triggers)
    assert events.dtype == fake.events.dtype


def test_yaml_settings_are_applied_and_read_back(fake_dv) -> None:
    fake = fake_dv._fake.plug(fake_dv.FakeDvCamera(duration_us=80_000))
    camera = inivation.open_from_config(yaml.safe_load(DOC_YAML)["camera"]["hardware"])
    s = camera.open().settings
    assert s["roi"] == {"x": 40, "y": 20, "width": 560, "height": 440}
    # the sensor's register holds 31 at most
    assert (s["contrast_threshold_on"], s["contrast_threshold_off"]) == (12, 31)
    assert s["readout_fps"] == "VARIABLE_15000" and s["trigger_in"] is True
    assert (s["camera"], s["firmware"], s["connection"]) == ("DVXplorer_DXA00093", 7, "LIBUSB_SPEED_SUPER")
    json.dumps(s)
    events, triggers, _ = read_until(camera, lambda: _all_handed(camera))
    np.testing.assert_array_equal(events, fake.sent_events)
    assert len(events) < len(fake.events) and events["x"].min() >= 40 and events["x"].max() < 600
    assert len(triggers) == len(fake.triggers)


def test_davis_biases_are_set_and_read_back(fake_dv) -> None:
    fake_dv._fake.plug(fake_dv.FakeDvCamera(model="DAVIS", serial="00000104", duration_us=30_000))
    hardware = yaml.safe_load("davis_biases: {On: [5, 120], Off: [3, 10]}")  # YAML 1.1: On/Off are booleans
    assert set(hardware["davis_biases"]) == {True, False}
    camera = inivation.open_from_config(hardware)
    info = camera.open()
    assert (info.width, info.height) == (346, 260)
    assert info.settings["davis_biases"] == {"On": [5, 120], "Off": [3, 10]}
    assert info.settings["trigger_in"] is False and info.settings["readout_fps"] is None


@pytest.mark.parametrize(
    "model, hardware, key, match",
    [
        ("DAVIS", {"contrast_threshold_on": 5}, "camera.hardware.contrast_threshold_on", "no such setting"),
        ("DVXplorer", {"davis_biases": {"On": [1, 2]}}, "camera.hardware.davis_biases.On", "no Davis346BiasCF"),
        ("DAVIS", {"davis_biases": {"Onn": [1, 2]}}, "camera.hardware.davis_biases.Onn", "known: Diff, On, Off"),
        ("DAVIS", {"davis_biases": {"On": [9, 2]}}, "camera.hardware.davis_biases.On", "refused"),
        ("DVXplorer", {"readout_fps": "FAST"}, "camera.hardware.readout_fps", "known: CONSTANT_100"),
        ("DVXplorer", {"roi": {"x": 600, "y": 0, "width": 100, "height": 10}}, "camera.hardware.roi", "does not fit"),
    ],
)
def test_settings_the_camera_lacks_or_refuses_name_the_key(
    fake_dv, model: str, hardware: dict, key: str, match: str
) -> None:
    fake_dv._fake.plug(fake_dv.FakeDvCamera(model=model))
    with pytest.raises(ConfigError, match=match) as err:
        inivation.open_from_config(hardware).open()
    assert err.value.key == key


@pytest.mark.parametrize(
    "hardware, key",
    [
        ({"serial_number": "x"}, "camera.hardware.serial_number"),
        ({"davis_biases": {"On": [1]}}, "camera.hardware.davis_biases.On"),
        ({"contrast_threshold_on": "high"}, "camera.hardware.contrast_threshold_on"),
        ({"stall_timeout_s": -0.5}, "camera.hardware.stall_timeout_s"),
    ],
)
def test_bad_hardware_keys_name_the_key(hardware: dict, key: str) -> None:
    with pytest.raises(ConfigError) as err:
        inivation.open_from_config(hardware)
    assert err.value.key == key


def test_missing_sdk_gives_the_install_line(no_sdk) -> None:
    with pytest.raises(DriverError, match=r"pip install -e '\.\[inivation\]' in flagtrack's folder"):
        inivation.open_from_config({}).open()


def test_missing_cameras_are_named(fake_dv) -> None:
    with pytest.raises(DriverError, match="first camera: cannot open the camera.*connected: none"):
        inivation.open_from_config({}).open()
    fake_dv._fake.plug(fake_dv.FakeDvCamera(serial="DXA1"))
    with pytest.raises(DriverError, match="camera 'DXA2': cannot open.*given serial number.*connected: DXA1"):
        inivation.open_from_config({"serial": "DXA2"}).open()


@pytest.mark.parametrize("raises", [False, True])
def test_unplug_raises_after_the_data_that_came(fake_dv, raises: bool) -> None:
    fake = fake_dv._fake.plug(fake_dv.FakeDvCamera(unplug_after_batches=4, unplug_raises=raises))
    camera = inivation.open_from_config({})
    camera.open()
    got = []
    with pytest.raises(DriverError, match="camera 'DXA00093': (the camera stopped running|camera failed)"):
        while True:
            if (data := camera.read(0.05)) is not None:
                got.append(data.events)
    assert len(got) == 4
    events = np.concatenate(got)
    np.testing.assert_array_equal(events, fake.events[: len(events)])


def test_a_stalled_camera_reads_none_then_raises(fake_dv) -> None:
    fake_dv._fake.plug(fake_dv.FakeDvCamera(stall_after_batches=2))
    camera = inivation.open_from_config({"stall_timeout_s": 0.2})
    camera.open()
    results = []
    with pytest.raises(DriverError, match="camera stopped delivering data"):
        for _ in range(100):
            results.append(camera.read(0.05))
    assert results[0] is not None and results[-1] is None
