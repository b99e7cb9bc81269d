"""The metavision adapter against a fake ``metavision_hal`` that streams real EVT 3.0 / 2.0 / 2.1 bytes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from flagtrack.daemon.errors import ConfigError, DriverError
from flagtrack.drivers.camera import hardware, metavision
from flagtrack.drivers.formats import FormatWarning
from tests.fakes.helpers import read_until

DOC_YAML = """
camera:
  id: cam0
  adapter: metavision
  hardware:
    serial: "00ca0009"
    format: EVT3
    biases: {bias_diff_on: 25, bias_diff_off: 30, bias_hpf: 0, bias_fo: 0, bias_refr: 20}
    roi: {x: 320, y: 180, width: 640, height: 360}
    rate_limiter_events_per_s: 1_002_000
    trigger_in: true
"""


@pytest.mark.parametrize(
    "api, sensor, fmt, options, encoding, published",
    [
        ("5.1", "IMX636", "EVT3", "", "EVT3", "evt2"),  # OpenEB 5: the HAL decodes, events published as EVT 2.0
        ("5.1", "IMX636", "EVT21", "", "EVT21", "evt2"),
        ("5.1", "Gen3.1", None, "", "EVT2", "evt2"),
        ("4.4", "IMX636", "EVT3", "", "EVT3", "evt3"),  # OpenEB 4: the device's bytes (numpy, then vectors)
        ("4.6", "IMX636", "EVT21", "", "EVT21", "evt2"),  # old format string: OpenEB's rule says legacy
        ("4.4", "IMX636", "EVT21", "endianness=little", "EVT21;endianness=little", "evt2"),
        ("4.6", "Gen3.1", None, "", "EVT2", "evt2"),
    ],
)
def test_events_decode_exactly_in_every_format(
    fake_hal, api: str, sensor: str, fmt: str | None, options: str, encoding: str, published: str
) -> None:
    fake_hal._fake.use_api(api)
    cam = fake_hal._fake.plug(fake_hal.FakeHalCamera(sensor=sensor, format_options=options, duration_us=60_000, seed=7))
    camera = metavision.open_from_config({"format": fmt} if fmt else {})
    info = camera.open()
    size = (1280, 720) if sensor == "IMX636" else (640, 480)
    assert (info.adapter, info.width, info.height, info.encoding) == ("metavision", *size, published)
    assert info.settings["device_encoding"] == encoding and info.serial == "00ca0009"
    assert info.settings["data_path"] == ("hal_decoder" if api == "5.1" else "device_bytes")
    events, triggers, reads = read_until(camera, lambda: camera._events_stream._feed.exhausted)
    camera.close()
    assert reads > 5 and len(cam.sent_events) > 1000
    np.testing.assert_array_equal(events, cam.sent_events)
    np.testing.assert_array_equal(triggers, cam.sent_triggers)


def test_corrupt_words_of_the_cameras_evt21_stream_are_reported_as_drops(fake_hal) -> None:
    fake_hal._fake.use_api("4.6")  # the device's bytes, decoded by flagtrack
    corrupt = (100, 2000, 2001, 5000)
    fake_hal._fake.plug(
        fake_hal.FakeHalCamera(format="EVT21", format_options="endianness=little", corrupt_words=corrupt)
    )
    camera = metavision.open_from_config({})
    camera.open()
    drops, data = [], None
    with pytest.warns(FormatWarning, match="corrupt EVT 2.1 word"):
        while not camera._events_stream._feed.exhausted or data is not None:
            data = camera.read(0.01)
            drops += data.drops if data is not None else ()
    camera.close()
    assert {d.reason for d in drops} == {hardware.CORRUPT_WORDS} and {d.unit for d in drops} == {"words"}
    assert sum(d.count for d in drops) == len(corrupt)


def test_the_hal_decodes_opaque_buffers_and_says_how_far_the_stream_is_complete(fake_hal) -> None:
    """OpenEB 5: the buffer's bytes are out of reach (the first real read failed on them); the HAL's decoder
    gives the events, triggers in memory it reuses (copied at once), and its last time as the horizon."""
    opaque = fake_hal._events_stream.raw_buffer(b"\x00" * 8)
    assert isinstance(opaque, fake_hal.RawBuffer) and opaque.size() == 8
    for read in (memoryview, bytes, list, lambda b: np.asarray(b, dtype=np.uint8)):
        with pytest.raises(TypeError):
            read(opaque)
    cam = fake_hal._fake.plug(fake_hal.FakeHalCamera(duration_us=80_000, seed=3))
    camera = metavision.open_from_config({"trigger_in": True})
    camera.open()
    got, horizon = [], -1
    for _ in range(100_000):  # the fake's stream ends
        if (data := camera.read(0.01)) is None:
            if camera._events_stream._feed.exhausted:
                break
            continue
        assert data.raw is None and data.t_until_us is not None and data.t_until_us >= horizon
        assert len(data.events) == 0 or data.events["t"].max() <= data.t_until_us
        horizon = data.t_until_us
        got.append(data)
    hal = camera._device
    camera.close()
    assert not hal.get_i_event_cd_decoder()._callbacks and not hal.get_i_event_ext_trigger_decoder()._callbacks
    triggers = np.concatenate([d.triggers for d in got])
    assert len(cam.sent_triggers) > 10
    np.testing.assert_array_equal(triggers, cam.sent_triggers)
    assert horizon == max(cam.sent_events["t"][-1], cam.sent_triggers["t"][-1])


@pytest.mark.parametrize("api", ["5.1", "4.6"])
def test_the_hal_logs_the_cameras_own_bytes_to_a_new_file_at_each_open(fake_hal, api: str, tmp_path: Path) -> None:
    fake_hal._fake.use_api(api)
    fake_hal._fake.plug(fake_hal.FakeHalCamera(serial="00ca/09", duration_us=30_000))
    logged = []
    for _ in range(2):
        camera = metavision.open_from_config({"raw_log_dir": str(tmp_path / "logs")})
        info = camera.open()
        feed = camera._events_stream._feed
        read_until(camera, lambda f=feed: f.exhausted)
        sent = feed.data
        camera.close()
        logged.append(Path(info.settings["raw_log"]))
    assert logged[0] != logged[1] and logged[0].parent == tmp_path / "logs" and logged[0].name.startswith("00ca_09_")
    for path in logged:
        data = path.read_bytes()
        assert data.endswith(sent) and data[: -len(sent)].endswith(b"% end\n")
    (tmp_path / "file").write_text("")
    with pytest.raises(ConfigError, match="cannot write the camera's bytes there") as err:
        metavision.open_from_config({"raw_log_dir": str(tmp_path / "file")}).open()
    assert err.value.key == "camera.hardware.raw_log_dir"


def test_yaml_settings_are_applied_and_read_back(fake_hal) -> None:
    cam = fake_hal._fake.plug(fake_hal.FakeHalCamera(duration_us=100_000))
    camera = metavision.open_from_config(yaml.safe_load(DOC_YAML)["camera"]["hardware"])
    info = camera.open()
    s = info.settings
    assert s["biases"] == {"bias_diff_on": 25, "bias_diff_off": 30, "bias_hpf": 0, "bias_fo": 0, "bias_refr": 20}
    assert s["roi"] == {"x": 320, "y": 180, "width": 640, "height": 360, "read_back": False}
    # the ERC counts events per 200 µs: 1 002 000 ev/s is 200.4 per period, the camera keeps 200 = 1 000 000 ev/s
    assert s["rate_limiter"] == {"enabled": True, "events_per_s": 1_000_000}
    assert s["trigger_in"] is True
    assert (s["sensor"], s["integrator"], s["available_formats"]) == ("IMX636", "Prophesee", ["EVT3", "EVT21"])
    json.dumps(s)
    events, triggers, _ = read_until(camera, lambda: camera._events_stream._feed.exhausted)
    np.testing.assert_array_equal(events, cam.sent_events)
    assert len(cam.sent_triggers) == len(cam.triggers) > 0
    np.testing.assert_array_equal(triggers, cam.sent_triggers)
    assert events["x"].min() >= 320 and events["x"].max() < 960 and events["y"].min() >= 180
    assert np.bincount(events["t"] // 200).max() <= 200


def test_trigger_input_off_by_default_on_the_fake_hal(fake_hal) -> None:
    fake_hal._fake.plug(fake_hal.FakeHalCamera(duration_us=50_000))
    camera = metavision.open_from_config({})
    info = camera.open()
    assert info.settings["trigger_in"] is False and info.settings["rate_limiter"]["enabled"] is False
    _, triggers, _ = read_until(camera, lambda: camera._events_stream._feed.exhausted)
    assert len(triggers) == 0


@pytest.mark.parametrize(
    "hardware, key, match",
    [
        ({"biases": {"bias_diff_on": 500}}, "camera.hardware.biases.bias_diff_on", r"allowed: -85\.\.140"),
        ({"biases": {"bias_pr": 5}}, "camera.hardware.biases.bias_pr", "unknown bias"),
        ({"roi": {"x": 1200, "y": 0, "width": 100, "height": 10}}, "camera.hardware.roi", "does not fit"),
        ({"rate_limiter_events_per_s": 2_000_000_000}, "camera.hardware.rate_limiter_events_per_s", "refused"),
    ],
)
def test_values_the_camera_refuses_name_the_key(fake_hal, hardware: dict, key: str, match: str) -> None:
    fake_hal._fake.plug(fake_hal.FakeHalCamera())
    with pytest.raises(ConfigError, match=match) as err:
        metavision.open_from_config(hardware).open()
    assert err.value.key == key


def test_a_camera_without_erc_refuses_a_rate_limit(fake_hal) -> None:
    fake_hal._fake.plug(fake_hal.FakeHalCamera(sensor="Gen3.1"))
    with pytest.raises(ConfigError, match="no event rate controller") as err:
        metavision.open_from_config({"rate_limiter_events_per_s": 1000}).open()
    assert err.value.key == "camera.hardware.rate_limiter_events_per_s"


@pytest.mark.parametrize(
    "hardware, key",
    [
        ({"seriall": "x"}, "camera.hardware.seriall"),
        ({"biases": {"bias_fo": 1.5}}, "camera.hardware.biases.bias_fo"),
        ({"rate_limiter_events_per_s": -5}, "camera.hardware.rate_limiter_events_per_s"),
        ({"evt21_endianness": "big"}, "camera.hardware.evt21_endianness"),
        ({"roi": {"x": 0, "y": 0, "width": 10}}, "camera.hardware.roi.height"),
    ],
)
def test_bad_hardware_keys_name_the_key(hardware: dict, key: str) -> None:
    with pytest.raises(ConfigError) as err:
        metavision.open_from_config(hardware)
    assert err.value.key == key


def test_missing_openeb_says_how_to_get_it(no_sdk) -> None:
    with pytest.raises(DriverError, match="install OpenEB.*metavision_hal"):
        metavision.open_from_config({}).open()


def test_missing_camera_and_unsupported_format_are_named(fake_hal) -> None:
    with pytest.raises(DriverError, match="first camera: camera not found"):
        metavision.open_from_config({}).open()
    fake_hal._fake.plug(fake_hal.FakeHalCamera(serial="AAA"))
    with pytest.raises(DriverError, match=r"camera 'BBB': camera not found \(connected: AAA"):
        metavision.open_from_config({"serial": "BBB"}).open()
    with pytest.raises(DriverError, match="camera 'AAA': cannot open.*EVT2 is not supported"):
        metavision.open_from_config({"serial": "AAA", "format": "EVT2"}).open()


def test_unplug_and_stall_raise(fake_hal) -> None:
    cam = fake_hal._fake.plug(fake_hal.FakeHalCamera(serial="U", unplug_after_bytes=20_000))
    fake_hal._fake.plug(fake_hal.FakeHalCamera(serial="S", stall_after_bytes=3_000))
    camera = metavision.open_from_config({"serial": "U"})
    camera.open()
    got = []
    with pytest.raises(DriverError, match="camera 'U': the camera's events stream stopped"):
        while True:
            if (data := camera.read(0.05)) is not None:
                got.append(data.events)
    events = np.concatenate(got)
    np.testing.assert_array_equal(events, cam.sent_events[: len(events)])
    camera.close()
    camera.close()
    assert cam.stopped == 1
    camera = metavision.open_from_config({"serial": "S", "stall_timeout_s": 0.2})
    camera.open()
    with pytest.raises(DriverError, match="camera 'S': camera stopped delivering data"):
        for _ in range(100):
            camera.read(0.05)
