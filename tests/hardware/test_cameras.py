"""Real cameras: run with ``pytest tests/hardware --device ADAPTER[:SERIAL]`` (skipped without ``--device``).

ADAPTER is ``prophesee`` (neuromorphic-drivers), ``metavision`` (OpenEB HAL) or ``inivation``
(dv-processing); without a serial the first camera is used. Point the camera at something that moves
(a hand waving, a flickering light): the tests need events. Examples::

    pytest tests/hardware --device prophesee:00050423
    pytest tests/hardware --device metavision --device inivation:DXA00093
"""

from __future__ import annotations

import importlib
import time

import numpy as np
import pytest

from flagtrack.drivers.camera.base import CameraInfo

pytestmark = pytest.mark.hardware
ADAPTERS = ("prophesee", "metavision", "inivation")


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "device" in metafunc.fixturenames:
        names = [d for d in metafunc.config.getoption("--device") if d.split(":", 1)[0] in ADAPTERS]
        metafunc.parametrize(
            "device",
            names
            or [
                pytest.param(
                    "none",
                    marks=pytest.mark.skip(reason="no camera named: --device prophesee|metavision|inivation[:SERIAL]"),
                )
            ],
        )


def camera_for(device: str, **settings: object):
    adapter, _, serial = device.partition(":")
    module = importlib.import_module(f"flagtrack.drivers.camera.{adapter}")
    hardware = dict(settings)
    if serial:
        hardware["serial"] = serial
    return module.open_from_config(hardware)


def stream(camera, seconds: float) -> tuple[np.ndarray, int]:
    """Events read for ``seconds`` of wall time, and the number of non-empty reads."""
    parts, reads = [], 0
    stop = time.monotonic() + seconds
    while time.monotonic() < stop:
        data = camera.read(0.05)
        if data is not None and len(data.events):
            parts.append(data.events)
            reads += 1
    return (np.concatenate(parts) if parts else np.zeros(0, dtype=[("t", "<i8")])), reads


def roi_of(info: CameraInfo) -> dict[str, int]:
    return {"x": info.width // 4, "y": info.height // 4, "width": info.width // 2, "height": info.height // 2}


def test_events_flow(device: str) -> None:
    camera = camera_for(device)
    info = camera.open()
    try:
        assert info.width > 0 and info.height > 0 and info.encoding in ("evt2", "evt3")
        events, reads = stream(camera, 2.0)
    finally:
        camera.close()
    assert len(events) > 1000 and reads > 10, "no events: is something moving in front of the camera?"
    assert events["x"].max() < info.width and events["y"].max() < info.height
    span_s = (int(events["t"].max()) - int(events["t"].min())) * 1e-6
    assert 1.0 < span_s < 3.0  # camera time advances with wall time
    assert 0.05 < np.mean(events["p"]) < 0.95  # both polarities


def test_settings_are_applied_and_read_back(device: str) -> None:
    probe = camera_for(device)
    info = probe.open()
    probe.close()
    roi = roi_of(info)
    camera = camera_for(device, roi=roi, trigger_in=True)
    info = camera.open()
    try:
        settings = info.settings
        assert {k: settings["roi"][k] for k in roi} == roi
        assert settings["trigger_in"] is True
        events, _ = stream(camera, 2.0)
    finally:
        camera.close()
    assert len(events) > 100, "no events inside the ROI: is something moving in the middle of the view?"
    inside = (
        (events["x"] >= roi["x"])
        & (events["x"] < roi["x"] + roi["width"])
        & (events["y"] >= roi["y"])
        & (events["y"] < roi["y"] + roi["height"])
    )
    assert inside.all(), f"{np.count_nonzero(~inside)} events outside the ROI {roi}"


def test_the_camera_can_be_opened_again_after_close(device: str) -> None:
    for _ in range(2):
        camera = camera_for(device)
        camera.open()
        camera.close()
        camera.close()
