"""The point-sensor service: runs one sensor driver and publishes its samples on the bus.

Publishes :class:`~flagtrack.daemon.schema.SensorSamples` on ``<ns>/sensor/<id>/samples`` every
``publish_interval_s`` (also when only missing samples are to report), and declares its
liveliness as ``sensor/<id>``. The sensor is auxiliary: nothing it does stops the other services.
A sensor that cannot be opened, fails or goes silent is closed and reopened every ``reopen_s``,
and the samples it should have given meanwhile are counted as missing.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import numpy as np

from flagtrack.daemon.schema import SensorSamples
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.transport import Bus, Publisher
from flagtrack.drivers.sensor.base import PointSensor, SensorReading
from flagtrack.drivers.sensor.setup import SensorConfig

log = logging.getLogger(__name__)


class SensorService:
    """Publishes one point sensor's samples until stopped.

    Args:
        bus: the bus.
        cfg: the ``sensor:`` section.
        factory: opens the driver (called again to reopen it after a failure).
    """

    def __init__(self, bus: Bus, cfg: SensorConfig, factory: Callable[[], PointSensor]) -> None:
        self.bus = bus
        self.cfg = cfg
        self.factory = factory
        self.name = f"sensor/{cfg.id}"
        self.samples = 0
        self.missing = 0
        self.failures = 0
        self.opened = 0
        self.units = cfg.units
        self.clock = "sensor"
        self.driver: PointSensor | None = None  # the open driver (tests inject faults through it)
        self._pending: list[SensorReading] = []
        self._pending_missing = 0
        self._seq = 0
        self._last_log_s = 0.0
        self._publisher: Publisher | None = None

    def start(self) -> None:
        """Declare the samples publisher (the driver opens in ``run``, and reopens there after a failure:
        a sensor that cannot be opened never stops the rig)."""
        self._publisher = self.bus.publisher(self.bus.keys.sensor_samples(self.cfg.id))

    def run(self, stop: threading.Event) -> None:
        publisher = self._publisher
        if publisher is None:
            raise RuntimeError(f"{self.name}: start() first")
        self.bus.declare_alive(self.name)
        sensor: PointSensor | None = None
        retry_at = 0.0
        down_since: float | None = None
        last_publish = time.monotonic()
        try:
            while not stop.is_set():
                beat(self.name, f"{self.samples} samples, {self.missing} missing, {self.failures} failures")
                now = time.monotonic()
                if sensor is None:
                    if now >= retry_at:
                        sensor = self._open()
                        retry_at = now + self.cfg.reopen_s
                    if sensor is None:
                        down_since = down_since or now
                        stop.wait(min(0.05, self.cfg.publish_interval_s))
                    elif down_since is not None:
                        self._pending_missing += round((time.monotonic() - down_since) * self.cfg.rate_hz)
                        down_since = None
                else:
                    sensor = self._read(sensor)
                    if sensor is None:
                        down_since, retry_at = time.monotonic(), time.monotonic() + self.cfg.reopen_s
                if time.monotonic() - last_publish >= self.cfg.publish_interval_s:
                    if down_since is not None:
                        self._pending_missing += round((time.monotonic() - down_since) * self.cfg.rate_hz)
                        down_since = time.monotonic()
                    self._publish(publisher)
                    last_publish = time.monotonic()
        finally:
            if sensor is not None:
                self._close(sensor)
            self._publish(publisher)
            log.info(
                "sensor %s: %d samples, %d missing, %d failures", self.cfg.id, self.samples, self.missing, self.failures
            )

    def _open(self) -> PointSensor | None:
        sensor = None
        try:
            sensor = self.factory()
            info = sensor.open()
        except Exception as exc:  # noqa: BLE001 - the sensor never stops the rig: report, retry later
            self._failed(f"cannot open: {exc}")
            if sensor is not None:
                self._close(sensor)
            return None
        self.units, self.clock = info.units, info.clock
        self.opened += 1
        self.driver = sensor
        log.info("sensor %s: %s %s, %s clock, %g Hz", self.cfg.id, info.driver, info.device, info.clock, info.rate_hz)
        return sensor

    def _read(self, sensor: PointSensor) -> PointSensor | None:
        try:
            got = sensor.read(self.cfg.publish_interval_s)
        except Exception as exc:  # noqa: BLE001 - silent or broken: close, reopen later
            self._failed(str(exc))
            self._close(sensor)
            return None
        if len(got) or got.missing or len(got.trigger_t_us):
            self._pending.append(got)
        return sensor

    def _failed(self, message: str) -> None:
        self.failures += 1
        now = time.monotonic()
        if now - self._last_log_s > 5.0:  # count repeated problems, log them rarely
            log.warning(
                "sensor %s: %s (%d failures so far; samples marked missing)", self.cfg.id, message, self.failures
            )
            self._last_log_s = now

    @staticmethod
    def _close(sensor: PointSensor) -> None:
        try:
            sensor.close()
        except Exception as exc:  # noqa: BLE001 - closing a dead port
            log.debug("sensor close failed: %s", exc)

    def _publish(self, publisher: Publisher) -> None:
        readings, self._pending = self._pending, []
        missing = self._pending_missing + sum(r.missing for r in readings)
        self._pending_missing = 0
        if not readings and not missing:
            return
        t_us = np.concatenate([r.t_us for r in readings]) if readings else np.zeros(0, np.int64)
        value = np.concatenate([r.value for r in readings]) if readings else np.zeros(0)
        pulses = np.concatenate([r.trigger_t_us for r in readings]) if readings else np.zeros(0, np.int64)
        wall_ns = max((r.wall_ns for r in readings if len(r)), default=0)
        publisher.put(
            SensorSamples(
                self.cfg.id,
                self._seq,
                self.units,
                t_us.astype(np.int64),
                value.astype(np.float64),
                pulses.astype(np.int64),
                int(missing),
                self.clock,
                int(wall_ns),
            )
        )
        self._seq += 1
        self.samples += len(t_us)
        self.missing += missing
