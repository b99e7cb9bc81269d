"""The prophesee adapter against a fake ``neuromorphic_drivers`` that streams real EVT 3.0 bytes."""

from __future__ import annotations

import dataclasses
import json
import sys

import numpy as np
import pytest
import yaml

from flagtrack.daemon.errors import ConfigError, DriverError
from flagtrack.drivers.camera import prophesee
from flagtrack.drivers.formats import make_decoder
from tests.fakes.helpers import read_until

DOC_YAML = """
camera:
  id: cam0
  adapter: prophesee
  hardware:
    serial: "00050423"
    biases: {diff_on: 20, diff_off: 500, hpf: 10}
    roi: {x: 200, y: 100, width: 800, height: 500}
    rate_limiter: {reference_period_us: 1000, maximum_events_per_period: 40}
    trigger_in: false
    stall_timeout_s: 5.0
"""


def test_events_and_triggers_decode_exactly_from_buffers_cut_anywhere(fake_nd) -> None:
    cam = fake_nd._fake.plug(fake_nd.FakeCamera())
    camera = prophesee.open_from_config({})
    info = camera.open()
    assert (info.adapter, info.width, info.height, info.encoding, info.serial) == (
        "prophesee",
        1280,
        720,
        "evt3",
        "00050423",
    )
    events, triggers, reads = read_until(camera, lambda: cam.feed is not None and cam.feed.exhausted)
    camera.close()
    assert len(cam.sent_events) > 10_000 and reads > 20
    np.testing.assert_array_equal(events, cam.sent_events)
    np.testing.assert_array_equal(triggers, cam.sent_triggers)
    assert len(triggers) == len(cam.triggers) > 0  # the trigger input is on by default


def test_silkyevcam_vga_streams_evt3_at_640x480(fake_nd) -> None:
    cam = fake_nd._fake.plug(fake_nd.FakeCamera(name=fake_nd.Name.CENTURYARKS_VGA, serial="SEC-VGA-1", seed=3))
    camera = prophesee.open_from_config({"serial": "SEC-VGA-1", "biases": {"diff_on": 400}})
    info = camera.open()
    assert (info.width, info.height, info.encoding) == (640, 480, "evt3")
    assert info.settings["model"] == "CenturyArks VGA" and info.settings["biases"]["diff_on"] == 400
    events, _, _ = read_until(camera, lambda: cam.feed.exhausted)
    np.testing.assert_array_equal(events, cam.sent_events)


def test_yaml_settings_are_applied_and_read_back(fake_nd) -> None:
    cam = fake_nd._fake.plug(fake_nd.FakeCamera(duration_us=100_000))
    hardware = yaml.safe_load(DOC_YAML)["camera"]["hardware"]
    camera = prophesee.open_from_config(hardware)
    info = camera.open()
    settings = info.settings
    applied = cam.applied
    # biases: the device clamps diff_off to its bound (190); the adapter reports what the device uses
    assert settings["biases"]["diff_on"] == applied.biases.diff_on == 20
    assert settings["biases"]["diff_off"] == applied.biases.diff_off == 190
    assert settings["biases_clamped"] == ["diff_off"] and settings["biases_bounds"]["diff_off"] == [-35, 190]
    assert settings["roi"] == {"x": 200, "y": 100, "width": 800, "height": 500}
    assert settings["rate_limiter"] == {"reference_period_us": 1000, "maximum_events_per_period": 40}
    assert settings["trigger_in"] is False and applied.enable_external_trigger is False
    assert settings["serial"] == "00050423" and settings["temperature_celsius"] == pytest.approx(36.5)
    json.dumps(settings)  # goes on the bus as JSON
    events, triggers, _ = read_until(camera, lambda: cam.feed.exhausted)
    np.testing.assert_array_equal(events, cam.sent_events)
    assert len(triggers) == 0
    assert len(events) < len(cam.events)  # the sensor really applied ROI and rate limiter
    assert events["x"].min() >= 200 and events["x"].max() < 1000
    assert events["y"].min() >= 100 and events["y"].max() < 600
    assert np.bincount(events["t"] // 1000).max() <= 40


def test_roi_masks_are_the_complement_of_the_region() -> None:
    words = prophesee._mask_words(3, 5, 70, 2)
    bits = np.unpackbits(np.array(words, dtype="<u8").view(np.uint8), bitorder="little")
    assert list(np.flatnonzero(bits == 0)) == [3, 4, 5, 6, 7] + list(range(70, 128))


@pytest.mark.parametrize(
    "hardware, key",
    [
        ({"serail": "x"}, "camera.hardware.serail"),
        (yaml.safe_load("serial: 00050423"), "camera.hardware.serial"),  # unquoted: YAML reads an (octal) number
        ({"biases": {"diff_on": "high"}}, "camera.hardware.biases.diff_on"),
        ({"biases": [1, 2]}, "camera.hardware.biases"),
        ({"roi": {"x": 0, "width": 4, "height": 4}}, "camera.hardware.roi.y"),
        ({"roi": {"x": 0, "y": 0, "width": 0, "height": 4}}, "camera.hardware.roi"),
        (
            {"rate_limiter": {"reference_period_us": 0, "maximum_events_per_period": 5}},
            "camera.hardware.rate_limiter.reference_period_us",
        ),
        ({"trigger_in": "yes"}, "camera.hardware.trigger_in"),
        ({"encoding": "evt4"}, "camera.hardware.encoding"),
        ({"stall_timeout_s": -1}, "camera.hardware.stall_timeout_s"),
    ],
)
def test_bad_hardware_keys_name_the_key(hardware: dict, key: str) -> None:
    with pytest.raises(ConfigError) as err:
        prophesee.open_from_config(hardware)
    assert err.value.key == key and key in str(err.value)


@pytest.mark.parametrize(
    "hardware, key",
    [
        ({"biases": {"bogus": 1}}, "camera.hardware.biases.bogus"),
        ({"roi": {"x": 600, "y": 0, "width": 100, "height": 10}}, "camera.hardware.roi"),
        ({"trigger_in": True}, "camera.hardware.trigger_in"),
    ],
)
def test_settings_the_model_lacks_name_the_key_and_release_the_device(fake_nd, hardware: dict, key: str) -> None:
    cam = fake_nd._fake.plug(fake_nd.FakeCamera(name=fake_nd.Name.CENTURYARKS_VGA, serial="V1"))
    with pytest.raises(ConfigError) as err:
        prophesee.open_from_config(hardware).open()
    assert err.value.key == key
    assert cam.opened == cam.closed == 1


def test_missing_sdk_gives_the_install_line(no_sdk) -> None:
    camera = prophesee.open_from_config({"serial": "1"})  # checking the config imports nothing
    with pytest.raises(DriverError, match=r"pip install -e '\.\[prophesee\]' in flagtrack's folder"):
        camera.open()
    assert sys.modules.get("neuromorphic_drivers") is None


def test_devices_not_found_or_unusable_are_named(fake_nd) -> None:
    with pytest.raises(DriverError, match="first camera: no such Prophesee-sensor camera"):
        prophesee.open_from_config({}).open()
    fake_nd._fake.plug(fake_nd.FakeCamera(serial="AAA"))
    with pytest.raises(DriverError, match=r"camera '123'.*connected: Prophesee EVK4 'AAA'"):
        prophesee.open_from_config({"serial": "123"}).open()
    fake_nd._fake.reset()
    fake_nd._fake.plug(fake_nd.FakeCamera(serial="BBB", error="permission denied"))
    with pytest.raises(DriverError, match="camera 'BBB'.*permission denied.*udev"):
        prophesee.open_from_config({"serial": "BBB"}).open()


def test_an_inivation_camera_is_pointed_to_its_adapter(fake_nd) -> None:
    fake_nd._fake.plug(fake_nd.FakeCamera(name=fake_nd.Name.INIVATION_DVXPLORER, serial="DXA1"))
    with pytest.raises(DriverError, match="use adapter: inivation"):
        prophesee.open_from_config({"serial": "DXA1"}).open()


def test_unplugged_mid_stream_raises_after_the_data_that_came(fake_nd) -> None:
    cam = fake_nd._fake.plug(fake_nd.FakeCamera(unplug_after_bytes=40_000))
    camera = prophesee.open_from_config({})
    camera.open()
    got = []
    decoder = make_decoder("evt3", strict=True)  # the adapter hands over the camera's own EVT 3.0 bytes
    with pytest.raises(DriverError, match="camera '00050423': camera failed or was unplugged"):
        while True:
            data = camera.read(0.05)
            if data is not None:
                got.append(decoder.decode(data.raw)[0])
    events = np.concatenate(got)
    assert 1000 < len(events) < len(cam.sent_events)
    np.testing.assert_array_equal(events, cam.sent_events[: len(events)])
    camera.close()
    camera.close()
    assert cam.closed == 1


def test_a_stalled_camera_reads_none_then_raises(fake_nd) -> None:
    fake_nd._fake.plug(fake_nd.FakeCamera(stall_after_bytes=5_000))
    camera = prophesee.open_from_config({"stall_timeout_s": 0.3})
    camera.open()
    results = []
    with pytest.raises(DriverError, match="camera stopped delivering data"):
        for _ in range(200):
            results.append(camera.read(0.05))
    assert results[0] is not None and results[-1] is None
    camera.close()


def read_all(camera, cam) -> tuple[list, bytes]:
    """Read until the fake's stream is exhausted: every drop reported and every byte received."""
    drops, received = [], []
    while not (cam.feed is not None and cam.feed.exhausted):
        data = camera.read(0.01)
        if data is not None:
            drops += data.drops
            received.append(data.raw)
    return drops, b"".join(received)


def test_usb_packets_the_host_ring_drops_are_reported_with_the_data_after_them(fake_nd) -> None:
    cam = fake_nd._fake.plug(fake_nd.FakeCamera(ring_drops={5: 3, 12: 2}))
    camera = prophesee.open_from_config({})
    camera.open()
    drops, received = read_all(camera, cam)
    camera.close()
    full = prophesee.DeviceDrop(prophesee.RING_FULL, 3, "usb_packets")
    assert drops == [full, dataclasses.replace(full, count=2)]
    assert cam.dropped_packets == 5 and camera.dropped_packets == 5  # the library's count, which only grows
    lost = sum(b - a for a, b in cam.lost)
    assert lost > 0 and received == bytes(np.delete(np.frombuffer(cam.feed.data, np.uint8), _ranges(cam.lost)))


def test_a_backlog_over_the_limit_is_cleared_and_reported(fake_nd) -> None:
    cam = fake_nd._fake.plug(fake_nd.FakeCamera(backlog_at={4: 2, 10: 6}))
    camera = prophesee.open_from_config({"max_backlog_packets": 3})
    info = camera.open()
    assert info.settings["max_backlog_packets"] == 3
    drops, received = read_all(camera, cam)
    camera.close()
    assert cam.cleared == [6]  # 2 waiting is within the limit: only the 6 are cleared (clear_backlog(until=0))
    assert drops == [prophesee.DeviceDrop(prophesee.BACKLOG_CLEARED, 6, "usb_packets")]
    assert received == bytes(np.delete(np.frombuffer(cam.feed.data, np.uint8), _ranges(cam.lost)))


def test_an_overflow_the_count_does_not_show_is_a_drop_of_unknown_size(fake_nd) -> None:
    camera = prophesee.open_from_config({})
    ring = fake_nd.RawRingStatus(0.0, 0, 1, False, [0], 0)  # a hole in the bytes, the count unchanged
    camera._note_drops(fake_nd.RawStatus(0.0, ring))
    camera._note_drops(fake_nd.RawStatus(0.0, fake_nd.RawRingStatus(0.0, 0, 1, False, None, 0)))
    assert camera._drops == [prophesee.DeviceDrop(prophesee.RING_FULL, 0, "usb_packets")]


@pytest.mark.parametrize("value", [0, -2])
def test_max_backlog_packets_must_be_positive(value: int) -> None:
    with pytest.raises(ConfigError, match="max_backlog_packets"):
        prophesee.open_from_config({"max_backlog_packets": value})


def _ranges(spans: list[tuple[int, int]]) -> np.ndarray:
    return np.concatenate([np.arange(a, b) for a, b in spans]) if spans else np.zeros(0, dtype=np.int64)
