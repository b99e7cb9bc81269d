"""``roi: auto`` and the rate limiter's ``auto`` (issue 31): worked out from the rig's tracker section
and handed to the SDK (fakes that speak the real SDKs' API), said in the status and the log."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
import yaml

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.camera import open_hardware_camera
from flagtrack.daemon.rig.config import load_rig
from tests.fakes.helpers import read_until

RIG = """
rig: auto
camera:
  adapter: {adapter}
  hardware: {hardware}
tracker: {{root: [150, 240], length: 300, direction_deg: 0}}
services: [camera]
"""
BOX = {"x": 120, "y": 0, "width": 457, "height": 667}
"""The demo's flag (root 150, 240 px, L 300, 10 links, alpha 0.6): reach 1.32 L = 396 px, plus 0.1 L:
columns 150 - 30 .. 150 + 426, rows 240 - 426 (cut at 0) .. 240 + 426, on a 1280x720 sensor."""


def rig_file(tmp_path: Path, adapter: str, hardware: dict, extra: str = "") -> Path:
    path = tmp_path / "rig.yaml"
    path.write_text(
        RIG.format(adapter=adapter, hardware=yaml.safe_dump(hardware, default_flow_style=True).strip()) + extra
    )
    return path


def unmasked(words: tuple, total: int) -> np.ndarray:
    """Indices of the lines a neuromorphic-drivers mask leaves on (bit set: masked)."""
    bits = np.unpackbits(np.array(words, dtype="<u8").view(np.uint8), bitorder="little")[:total]
    return np.flatnonzero(bits == 0)


def test_prophesee_gets_the_masks_of_the_flags_reach_and_a_rate_limiter(
    fake_nd, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    cam = fake_nd._fake.plug(fake_nd.FakeCamera(duration_us=60_000))
    rig = load_rig(rig_file(tmp_path, "prophesee", {"roi": "auto", "rate_limiter": "auto"}))
    with caplog.at_level(logging.INFO, logger="flagtrack.daemon.rig.camera"):
        opened = open_hardware_camera(rig)
    assert opened is not None
    info = opened.open()
    applied = cam.applied
    columns, rows = unmasked(applied.x_mask, 1280), unmasked(applied.y_mask, 720)
    assert (columns[0], columns[-1], rows[0], rows[-1]) == (120, 576, 0, 666)
    assert len(columns) == 457 and len(rows) == 667 and applied.mask_intersection_only is False
    # 2 x supervisor.expected_rate_mev_s (5 Mev/s) = 10 Mev/s = 2000 events per 200 µs
    assert (applied.rate_limiter.reference_period_us, applied.rate_limiter.maximum_events_per_period) == (200, 2000)
    assert info.settings["roi"] == BOX
    assert "columns 120..576, rows 0..666" in info.settings["auto"]["roi"]
    assert "10 Mev/s = 2 x supervisor.expected_rate_mev_s (5 Mev/s)" in info.settings["auto"]["rate_limiter"]
    said = [r.getMessage() for r in caplog.records]
    assert any("camera.hardware.roi auto: columns 120..576" in line for line in said)
    assert any("camera.hardware.rate_limiter auto: 2000 events per 200 µs" in line for line in said)
    events, _, _ = read_until(opened, lambda: cam.feed.exhausted)
    opened.close()
    assert len(events) and events["x"].min() >= 120 and events["x"].max() <= 576 and events["y"].max() <= 666


def test_metavision_gets_the_window_and_the_erc_rate(fake_hal, tmp_path: Path) -> None:
    cam = fake_hal._fake.plug(fake_hal.FakeHalCamera(duration_us=60_000))
    hardware = {"roi": "auto", "rate_limiter_events_per_s": "auto", "rate_margin": 3, "roi_half_angle_deg": 180}
    extra = "supervisor: {expected_rate_mev_s: 2.5}\n"
    opened = open_hardware_camera(load_rig(rig_file(tmp_path, "metavision", hardware, extra)))
    assert opened is not None
    info = opened.open()
    device = opened.camera._device
    window = device._roi.window
    # the whole disc: columns 150 - 426 (cut at 0) .. 576, rows 0 .. 666
    assert (window.x, window.y, window.width, window.height) == (0, 0, 577, 667) and device._roi.enabled
    assert device._erc.is_enabled() and device._erc.get_cd_event_rate() == 7_500_000  # 3 x 2.5 Mev/s
    assert info.settings["rate_limiter"] == {"enabled": True, "events_per_s": 7_500_000}
    assert "disc of radius 1.32 L" in info.settings["auto"]["roi"]
    events, _, _ = read_until(opened, lambda: opened.camera._events_stream._feed.exhausted)
    opened.close()
    np.testing.assert_array_equal(events, cam.sent_events)
    assert events["x"].max() <= 576 and events["y"].max() <= 666


def test_inivation_gets_the_crop_area(fake_dv, tmp_path: Path) -> None:
    fake_dv._fake.plug(fake_dv.FakeDvCamera())
    opened = open_hardware_camera(load_rig(rig_file(tmp_path, "inivation", {"roi": "auto"})))
    assert opened is not None
    info = opened.open()
    opened.close()
    width, height = info.width, info.height
    assert info.settings["roi"] == {"x": 120, "y": 0, "width": min(457, width - 120), "height": min(667, height)}


CALIBRATION = """format: flagtrack-calibration
version: 1
units: m
image_size: [1280, 720]
forward: {degree: 1, centre: [650.0, 240.0], scale: 1.0, exponents: [[0, 0], [1, 0], [0, 1]],
  x: [0.0, 0.002, 0.0], y: [0.0, 0.0, -0.002]}
inverse: {degree: 1, centre: [0.0, 0.0], scale: 1.0, exponents: [[0, 0], [1, 0], [0, 1]],
  x: [650.0, 500.0, 0.0], y: [240.0, 0.0, -500.0]}
"""
"""2 mm per pixel, origin at pixel (650, 240), y up, on a 1280x720 sensor."""


def test_a_calibrated_geometry_is_mapped_through_the_calibration(fake_nd, tmp_path: Path) -> None:
    """The demo's flag given in metres through a calibration masks the same pixels (to one, at the edges)."""
    (tmp_path / "cal.yaml").write_text(CALIBRATION)
    fake_nd._fake.plug(fake_nd.FakeCamera(duration_us=20_000))
    path = rig_file(tmp_path, "prophesee", {"roi": "auto"})
    in_metres = "tracker: {root: [-1.0, 0.0], length: 0.6, direction_deg: 0, calibration: cal.yaml}"
    path.write_text(path.read_text().replace("tracker: {root: [150, 240], length: 300, direction_deg: 0}", in_metres))
    opened = open_hardware_camera(load_rig(path))
    assert opened is not None
    info = opened.open()
    opened.close()
    roi = info.settings["roi"]
    edges = lambda b: (b["x"], b["y"], b["x"] + b["width"], b["y"] + b["height"])  # noqa: E731
    assert all(abs(a - b) <= 1 for a, b in zip(edges(roi), edges(BOX), strict=True)), roi
    assert (
        "radius 1.32 L = 0.792 m" in info.settings["auto"]["roi"]
        and "through the calibration" in info.settings["auto"]["roi"]
    )


@pytest.mark.parametrize(
    "hardware, tracker, match, key",
    [
        ({"roi": "auto"}, "tracker: {length: 300}", "set tracker.root and tracker.length", "camera.hardware.roi"),
        ({"roi_margin_over_l": 0.2}, "", "only used with roi: auto", "camera.hardware.roi_margin_over_l"),
        ({"rate_margin": 2}, "", "only used with rate_limiter: auto", "camera.hardware.rate_margin"),
        ({"roi": "auto", "rate_margin": 0.5}, "", r"must be in \[1, 1000\]", "camera.hardware.rate_margin"),
        ({"roi": "auto", "roi_half_angle_deg": "wide"}, "", "must be a number", "camera.hardware.roi_half_angle_deg"),
        (
            {"roi": "auto"},
            "tracker: {root: [-900, -900], length: 300}",
            "no pixel of the sensor",
            "camera.hardware.roi",
        ),
    ],
)
def test_what_cannot_be_worked_out_is_one_line_naming_the_key(
    fake_nd, tmp_path: Path, hardware: dict, tracker: str, match: str, key: str
) -> None:
    path = rig_file(tmp_path, "prophesee", hardware)
    if tracker:
        text = path.read_text().replace("tracker: {root: [150, 240], length: 300, direction_deg: 0}", tracker)
        path.write_text(text)
    with pytest.raises(ConfigError, match=match) as caught:
        load_rig(path)  # checked when the rig is loaded, before any device is opened
    assert caught.value.key == key and str(path) in str(caught.value)


def test_a_reach_beyond_the_sensor_is_refused_when_the_camera_opens(fake_nd, tmp_path: Path) -> None:
    fake_nd._fake.plug(fake_nd.FakeCamera(name=fake_nd.Name.CENTURYARKS_VGA, serial="VGA1"))
    path = rig_file(tmp_path, "prophesee", {"roi": "auto"})
    path.write_text(path.read_text().replace("root: [150, 240]", "root: [1200, 240]"))
    with pytest.raises(ConfigError, match="lies off the 640x480 sensor") as caught:
        open_hardware_camera(load_rig(path))  # the box starts at column 1170: only the device says it is off
    assert caught.value.key == "camera.hardware.roi"
