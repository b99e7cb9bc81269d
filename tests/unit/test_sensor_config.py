"""The ``sensor:`` section, the deploy examples, the simulated camera's sync generator and true flag."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.config import RigConfig, load_rig
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.drivers.camera.simulated import SimulatedCamera, SimulatedCameraConfig, fast_forward, trigger_edges
from flagtrack.drivers.formats.packets import Packetizer, decode_packet
from flagtrack.drivers.sensor.ascii import AsciiSensorProtocol, LineParser
from flagtrack.drivers.sensor.modbus import ModbusSensorMap
from flagtrack.drivers.sensor.setup import SensorConfig

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", ["rig-sensor-sim.yaml", "rig-sensor-ascii.yaml", "rig-sensor-modbus.yaml"])
def test_deploy_examples_load(name: str) -> None:
    rig = load_rig(REPO / "deploy" / name)
    assert rig.sensor is not None and "sensor" in rig.services
    assert rig.sensor.beam.x_over_l == 0.73 and rig.sensor.beam.direction == -1


def test_docs_yaml_blocks_load() -> None:
    text = (REPO / "docs" / "sensor.md").read_text()
    blocks = [b.split("```", 1)[0] for b in text.split("```yaml\n")[1:]]
    assert len(blocks) >= 2
    for block in blocks:
        data = yaml.safe_load(block)
        if "sensor" in data:
            from_mapping(SensorConfig, data["sensor"], key="sensor")


def test_config_errors_name_the_key_and_the_file(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text("sensor: {driver: simulated, beam: {x_over_l: 2.0}}\nservices: [camera, sensor]\n")
    with pytest.raises(ConfigError, match=r"sensor.beam.*x_over_l|x_over_l") as caught:
        load_rig(path)
    assert caught.value.path == str(path)
    path.write_text("sensor: {driver: serial}\n")
    with pytest.raises(ConfigError, match="sensor.driver"):
        load_rig(path)
    with pytest.raises(ConfigError, match="needs a 'sensor:'"):
        from_mapping(RigConfig, {"services": ["sensor"]})


def test_line_parser_reads_samples_pulses_wraps_and_refusals() -> None:
    parser = LineParser(AsciiSensorProtocol(mode="stream", time_wrap_counts=1000, scale=2.0, offset=1.0))
    assert parser.parse("D 990 10.5") == ("sample", 22.0, 990)
    assert parser.parse("D 5 -----")[0:1] == ("sample",) and np.isnan(parser.parse("D 7 ---")[1])
    assert parser.parse("D 20 3") == ("sample", 7.0, 1020)  # after the wrap
    assert parser.parse("T 30") == ("trigger", pytest.approx(np.nan, nan_ok=True), 1030)
    assert parser.parse("D 4.5")[0] == "untimed"  # the protocol promised the sensor's time
    assert parser.parse("ERR busy")[0] == "error" and parser.parse("hello")[0] == "other"
    host = LineParser(AsciiSensorProtocol(mode="poll"))
    assert host.parse("D 1234 5.0") == ("sample", 5.0, None)  # host-stamped: a time field is ignored
    with pytest.raises(ValueError, match="clock 'sensor'"):
        AsciiSensorProtocol(clock="sensor", reply=r"D (?P<value>\d+)")


def test_modbus_map_words_sign_and_invalid() -> None:
    m = ModbusSensorMap(words=2, signed=True, word_order="little", scale=0.001, offset=10.0, invalid_counts=(-1,))
    assert m.value([0xFFFE, 0xFFFF]) == pytest.approx(10.0 - 0.002)  # -2 counts, low word first
    assert np.isnan(m.value([0xFFFF, 0xFFFF]))
    assert ModbusSensorMap(scale=0.5).value([300]) == 150.0


def test_the_sync_generator_pulses_reach_the_camera_packets_and_survive_skips() -> None:
    cfg = SimulatedCameraConfig(speed_mps=0.0, trigger_period_ms=10, trigger_pulse_us=200, noise_rate_hz=2000)
    edges = np.concatenate([trigger_edges(cfg, t, t + 3000) for t in range(0, 60_000, 3000)])
    assert list(edges["t"][:4]) == [0, 200, 10_000, 10_200] and list(edges["edge"][:4]) == [1, 0, 1, 0]
    assert len(edges) == 12 and np.all(edges["channel"] == 0)
    camera = SimulatedCamera(cfg)
    camera.open()
    packetizer = Packetizer("evt3", cfg.width, cfg.height)
    got = []
    for _ in range(10):
        data = camera._generate(camera._t_us + cfg.slice_us)
        for packet in packetizer.push(data.events, data.triggers, data.t_until_us):
            got.append(decode_packet("evt3", packet.data, packet.t_offset_us)[1])
        if len(got) == 3:
            camera._skip(20_000)  # the twin falls behind: no events for 20 ms, the pulses are kept
    triggers = np.concatenate(got)
    rising = triggers["t"][triggers["edge"] == 1]
    assert list(rising) == list(range(0, rising[-1] + 1, 10_000))
    x, y = camera.truth.positions(np.array([13_000, 30_000, 10**7]), np.array([0.0, 150.0, 300.0]))
    assert np.all(np.isfinite(x[:2])) and np.all(np.isnan(x[2]))  # skipped time is known; the future is not
    np.testing.assert_allclose(y[:2, 0], 240.0)


def test_truth_is_what_the_events_were_drawn_from() -> None:
    camera = SimulatedCamera(SimulatedCameraConfig(speed_mps=6.0, noise_rate_hz=0, seed=2))
    camera.open()
    fast_forward(camera, 0.3)
    events = np.concatenate(fast_forward(camera, 0.03))
    x, y = camera.truth.positions(events["t"].astype(np.float64), np.linspace(0, 300, 301))
    distance = np.min(np.hypot(x - events["x"][:, None], y - events["y"][:, None]), axis=1)
    assert np.median(distance) < 1.0  # events lie on the true line (pixel centres, line width ~1 px)


def test_the_sensor_section_survives_the_run_logs_snapshot() -> None:
    rig = load_rig(REPO / "deploy" / "rig-sensor-modbus.yaml")
    stored = {k: v for k, v in rig.snapshot().items() if k != "path"}
    again = from_mapping(RigConfig, stored)  # what `flagtrack sweep --resume` and `flagtrack validate` read
    assert again.sensor == rig.sensor and again.sensor.beam.zero_reading is None
