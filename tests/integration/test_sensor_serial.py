"""Point-sensor drivers on real pseudo-terminals against simulated devices speaking their protocol,
and the sensor service over real Zenoh: a sensor that stops answering marks samples missing, never fails."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from flagtrack.daemon.errors import ConfigError, DriverError
from flagtrack.daemon.rig.build import build_services
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.schema import SensorSamples
from flagtrack.daemon.services.runner import ServiceGroup
from flagtrack.daemon.transport import Bus
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.drivers.sensor.device import DeviceParams, SimulatedSensorDevice
from flagtrack.drivers.sensor.modbus import ModbusSensorMap
from flagtrack.drivers.sensor.setup import SensorConfig, open_sensor
from tests.fakes.helpers import wait_until


def wave(t_us: int) -> float:
    return 100.0 + 10.0 * math.sin(2 * math.pi * 5.0 * t_us * 1e-6)


def sensor_config(port: str, **values: object) -> SensorConfig:
    return from_mapping(SensorConfig, {"driver": "ascii", "port": port, "timeout_s": 0.05, **values})


def gather(sensor, duration_s: float):
    t, v, pulses, missing = [], [], [], 0
    end = time.monotonic() + duration_s
    while time.monotonic() < end:
        got = sensor.read(0.02)
        t.append(got.t_us)
        v.append(got.value)
        pulses.append(got.trigger_t_us)
        missing += got.missing
    return np.concatenate(t), np.concatenate(v), np.concatenate(pulses), missing


def test_ascii_poll_samples_at_the_rate_stamped_by_the_host() -> None:
    with SimulatedSensorDevice(DeviceParams(), wave) as device:
        # a reply late by a stalled thread is still a reply (the 50 ms default would count it missing)
        sensor = open_sensor(sensor_config(device.port, poll={"rate_hz": 200}, timeout_s=0.5))
        info = sensor.open()
        try:
            t_us, values, _, missing = gather(sensor, 0.5)
        finally:
            sensor.close()
    assert info.clock == "host" and info.driver == "ascii"
    assert missing == 0 and np.all(np.isfinite(values))
    assert 30 <= len(values) <= 110  # 200 Hz for 0.5 s, under load fewer
    assert np.all((values > 89.99) & (values < 110.01)) and np.ptp(values) > 5
    assert abs(t_us[-1] * 1e-6 - time.time()) < 5.0 and np.all(np.diff(t_us) > 0)
    assert 3500 < np.median(np.diff(t_us)) < 10_000  # 5 ms, under load later


def test_ascii_stream_carries_the_device_clock_and_trigger_pulses() -> None:
    params = DeviceParams(rate_hz=500, trigger_period_ms=20, clock_offset_us=5_000_000)
    with SimulatedSensorDevice(params, wave) as device:
        sensor = open_sensor(sensor_config(device.port, ascii={"mode": "stream"}, poll={"rate_hz": 500}, timeout_s=0.5))
        info = sensor.open()
        try:
            t_us, values, pulses, missing = gather(sensor, 0.4)
        finally:
            sensor.close()
    assert info.clock == "sensor" and missing == 0
    assert len(t_us) >= 100 and t_us[0] >= 5_000_000
    steps = np.diff(t_us)
    assert np.all(np.abs(steps - 2000) <= 1)  # every sample, on the device's clock
    np.testing.assert_allclose(values, [wave(int(t)) for t in t_us], atol=1e-4)
    assert len(pulses) >= 10 and np.all(np.abs(np.diff(pulses) - 20_000) <= 1)


def test_ascii_out_of_range_readings_are_missing_samples_not_failures() -> None:
    with SimulatedSensorDevice(DeviceParams(), wave) as device:
        sensor = open_sensor(sensor_config(device.port, poll={"rate_hz": 200}))
        sensor.open()
        device.inject(out_of_range=True)
        try:
            _, values, _, missing = gather(sensor, 0.2)
        finally:
            sensor.close()
    assert len(values) > 10 and np.all(np.isnan(values)) and missing == len(values)


@pytest.mark.parametrize(("words", "signed", "order"), [(1, False, "big"), (2, True, "little")])
def test_modbus_register_reading_with_scale_and_offset(words: int, signed: bool, order: str) -> None:
    pytest.importorskip("pymodbus")
    modbus_map = {
        "device_id": 7,
        "register": 40,
        "kind": "holding",
        "words": words,
        "signed": signed,
        "word_order": order,
        "scale": 0.001 if words == 2 else 0.01,
        "offset": -50.0 if signed else 0.0,
    }
    map_obj = from_mapping(ModbusSensorMap, modbus_map)
    shifted = (lambda t: wave(t) - 130.0) if signed else wave  # signed: readings below zero
    with SimulatedSensorDevice(DeviceParams(protocol="modbus", modbus=map_obj), shifted) as device:
        sensor = open_sensor(
            from_mapping(
                SensorConfig,
                {
                    "driver": "modbus",
                    "port": device.port,
                    "modbus": modbus_map,
                    "poll": {"rate_hz": 100},
                    "timeout_s": 0.5,
                },
            )
        )
        info = sensor.open()
        try:
            _, values, _, missing = gather(sensor, 0.5)
        finally:
            sensor.close()
    assert info.driver == "modbus" and info.clock == "host" and missing == 0
    assert len(values) >= 10
    low, high = (-40.0, -20.0) if signed else (90.0, 110.0)
    assert np.all((values >= low - 0.002) & (values <= high + 0.002)) and np.ptp(values) > 3


def test_a_silent_device_gives_missing_samples_then_a_driver_error_to_reopen() -> None:
    with SimulatedSensorDevice(DeviceParams(), wave) as device:
        sensor = open_sensor(sensor_config(device.port, poll={"rate_hz": 200, "fail_after_s": 0.4, "retry_s": 0.02}))
        sensor.open()
        device.inject(mute=True)
        missing, nans = 0, 0
        with pytest.raises(DriverError, match="no valid reply") as caught:
            for _ in range(200):
                got = sensor.read(0.05)
                missing += got.missing
                nans += int(np.isnan(got.value).sum())
        sensor.close()
    assert caught.value.device == device.port
    assert nans >= 3 and missing >= nans  # each failed exchange counts the periods it took


def test_config_errors_name_the_key() -> None:
    with pytest.raises(ConfigError, match="needs a port"):
        from_mapping(SensorConfig, {"driver": "ascii"}, key="sensor")
    with pytest.raises(ConfigError, match="sensor.driver"):
        open_sensor(SensorConfig(driver="simulated"), camera=None)
    with pytest.raises(ConfigError, match="reply"):
        from_mapping(SensorConfig, {"driver": "ascii", "port": "x", "ascii": {"reply": "D (?P<v>.*)"}})
    with pytest.raises(ConfigError, match="sensor"):
        from_mapping(RigConfig, {"services": ["camera", "sensor"]})


def test_the_sensor_service_survives_a_silent_sensor_and_recovers() -> None:
    with SimulatedSensorDevice(DeviceParams(), wave) as device:
        rig = from_mapping(
            RigConfig,
            {
                "rig": f"sensor{time.monotonic_ns() % 10**9}",
                "sensor": {
                    "id": "ls1",
                    "driver": "ascii",
                    "port": device.port,
                    "timeout_s": 0.05,
                    "reopen_s": 0.2,
                    "poll": {"rate_hz": 200, "fail_after_s": 0.3, "retry_s": 0.02},
                    "publish_interval_s": 0.05,
                },
                "services": ["sensor"],
            },
        )
        with Bus(rig.bus_config) as bus:
            sub = bus.subscribe(bus.keys.sensor_samples("ls1"), SensorSamples)
            services = build_services(rig, bus, ["sensor"])
            group = ServiceGroup(services)
            group.start()

            unmuted: list[float] = []

            def fault() -> None:
                wait_until(lambda: services[0].samples >= 50, 10, "samples flowing before the fault")
                device.inject(mute=True)
                time.sleep(1.2)  # silent for longer than fail_after_s: declared silent, reopened
                device.inject(mute=False)
                unmuted.append(time.monotonic())

            def recovered() -> bool:  # 20 finite values sent after the device spoke again
                late = [m for t, m in messages if unmuted and t > unmuted[0]]
                return bool(late) and np.isfinite(np.concatenate([m.value for m in late])).sum() >= 20

            injector = threading.Thread(target=fault)
            injector.start()
            messages = []
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and not recovered():
                if (msg := sub.recv(timeout_s=0.1)) is not None:
                    messages.append((time.monotonic(), msg))
            injector.join()
            report = group.shutdown(5)
    service = services[0]
    assert not report.errors and "sensor/ls1" in report.finished
    assert service.failures >= 1 and service.opened >= 2  # declared silent, reopened
    values = np.concatenate([m.value for _, m in messages])
    assert np.isnan(values).sum() >= 3 and sum(m.missing for _, m in messages) >= 50  # ~1 s at 200 Hz lost
    assert recovered()  # flowing again
    assert all(m.clock == "host" and m.units == "mm" for _, m in messages if len(m.t_us))
    seqs = [m.seq for _, m in messages]
    assert seqs == sorted(seqs)
