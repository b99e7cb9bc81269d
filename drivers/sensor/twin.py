"""A simulated point sensor that measures the digital twin's true flag at the beam's position.

It samples at ``rate_hz`` on its own clock (``t_sensor = t_cam * (1 + drift) + offset``), reads the
twin's true centreline (:class:`~flagtrack.drivers.camera.simulated.TwinTruth`) at the camera time
of each sample, intersects it with the beam (the same ``BeamParams`` as the comparison, in the
twin's pixels), turns the lateral displacement into a reading and adds Gaussian noise. A sample is
delivered ``latency_ms`` of camera time after it was taken. It also stamps the camera's sync pulses
(the simulated camera's trigger generator) on its own clock, as a sensor wired to the same trigger
line would. The simulated camera must run in the same process.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from flagtrack.daemon.core.pointsensor import BeamParams, beam_lateral, lateral_to_reading
from flagtrack.drivers.sensor.base import SensorInfo, SensorReading, reading

log = logging.getLogger(__name__)

_N_S = 129  # points along the true centreline for the beam intersection (error ~1e-4 L)


@dataclass(frozen=True)
class TwinSensorParams:
    """The simulated sensor (config ``sensor.simulated``).

    Attributes:
        rate_hz: samples per second (sensor clock).
        noise_over_l: standard deviation of the reading noise, fraction of L.
        latency_ms: camera time between a sample and its delivery.
        clock_offset_ms: sensor clock minus camera clock.
        drift_ppm: the sensor clock runs this much fast.
        record_triggers: stamp the camera's sync pulses (rising edges) on the sensor clock.
        trigger_jitter_us: standard deviation of those stamps.
        max_read_s: camera time of samples produced per read at most.
        seed: noise seed.
    """

    rate_hz: float = 1000.0
    noise_over_l: float = 0.002
    latency_ms: float = 2.0
    clock_offset_ms: float = 0.0
    drift_ppm: float = 0.0
    record_triggers: bool = True
    trigger_jitter_us: float = 1.0
    max_read_s: float = 0.05
    seed: int = 1

    def __post_init__(self) -> None:
        if not (self.rate_hz > 0 and self.noise_over_l >= 0 and self.latency_ms >= 0 and self.max_read_s > 0):
            raise ValueError("rate_hz and max_read_s must be positive, noise_over_l and latency_ms >= 0")


class TwinSensor:
    """A :class:`~flagtrack.drivers.sensor.base.PointSensor` of the digital twin.

    Args:
        params: sampling, noise, latency and clock.
        beam: where it looks and how a lateral displacement becomes a reading (twin pixels).
        camera: the :class:`~flagtrack.drivers.camera.simulated.SimulatedCamera` (its ``truth``,
            ``cfg`` and trigger generator).
        units: unit of the readings.
    """

    def __init__(self, params: TwinSensorParams, beam: BeamParams, camera: Any, units: str = "px") -> None:
        from flagtrack.drivers.camera.simulated import trigger_edges

        self.params, self.beam, self.camera, self.units = params, beam, camera, units
        self._trigger_edges = trigger_edges
        cfg = camera.cfg
        self.length = float(cfg.length_px)
        self.x_beam = beam.x_over_l * self.length
        self._s = np.linspace(0.0, self.length, _N_S)
        self._rng = np.random.default_rng(params.seed)
        self._period_us = 1e6 / params.rate_hz
        self._next_k: int | None = None
        self._pulses_until_us = 0
        self.muted = False

    def sensor_us(self, t_cam_us: np.ndarray) -> np.ndarray:
        """Camera-clock times to this sensor's clock, µs (float)."""
        p = self.params
        return np.asarray(t_cam_us, dtype=np.float64) * (1 + p.drift_ppm * 1e-6) + p.clock_offset_ms * 1000

    def camera_us(self, t_sensor_us: np.ndarray) -> np.ndarray:
        """This sensor's clock to camera-clock times, µs (float)."""
        p = self.params
        return (np.asarray(t_sensor_us, dtype=np.float64) - p.clock_offset_ms * 1000) / (1 + p.drift_ppm * 1e-6)

    def open(self) -> SensorInfo:
        self._next_k = None
        return SensorInfo(
            "simulated",
            "digital twin",
            self.units,
            "sensor",
            self.params.rate_hz,
            {
                "noise_over_l": self.params.noise_over_l,
                "latency_ms": self.params.latency_ms,
                "clock_offset_ms": self.params.clock_offset_ms,
                "drift_ppm": self.params.drift_ppm,
            },
        )

    def read(self, timeout_s: float) -> SensorReading:
        available_us = self.camera.truth.horizon_us - self.params.latency_ms * 1000
        if self._next_k is None:
            if available_us <= 0:
                time.sleep(max(0.0, min(timeout_s, 0.005)))
                return reading()
            self._next_k = math.ceil(float(self.sensor_us(np.array([available_us]))[0]) / self._period_us)
            self._pulses_until_us = int(available_us)
        last_k = min(
            math.floor(float(self.sensor_us(np.array([available_us]))[0]) / self._period_us),
            self._next_k + math.ceil(self.params.max_read_s * self.params.rate_hz) - 1,
        )
        if last_k < self._next_k:
            time.sleep(max(0.0, min(timeout_s, 0.002)))
            return reading()
        k = np.arange(self._next_k, last_k + 1)
        self._next_k = last_k + 1
        t_sensor_us = np.round(k * self._period_us).astype(np.int64)
        t_cam_us = self.camera_us(t_sensor_us)
        pulses = self._pulses(int(t_cam_us[-1]) + 1)
        if self.muted:
            return reading(missing=len(k))
        values = self._readings(t_cam_us)
        return reading(t_sensor_us, values, pulses, int(np.isnan(values).sum()))

    def _readings(self, t_cam_us: np.ndarray) -> np.ndarray:
        cfg = self.camera.cfg
        x, y = self.camera.truth.positions(t_cam_us, self._s)
        lateral = beam_lateral(x, y, cfg.root_px, cfg.direction_deg, self.x_beam, self.beam.side)
        noise_reading = self.params.noise_over_l * self.length / self.beam.units_per_reading
        return lateral_to_reading(lateral, self.beam) + self._rng.normal(0.0, noise_reading, len(lateral))

    def _pulses(self, until_cam_us: int) -> np.ndarray:
        """The sync pulses (rising edges) of camera time up to ``until_cam_us``, stamped on the sensor clock."""
        if not self.params.record_triggers or until_cam_us <= self._pulses_until_us:
            return np.zeros(0, dtype=np.int64)
        edges = self._trigger_edges(self.camera.cfg, self._pulses_until_us, until_cam_us)
        self._pulses_until_us = until_cam_us
        rising = edges["t"][edges["edge"] == 1].astype(np.float64)
        jitter = self._rng.normal(0.0, self.params.trigger_jitter_us, len(rising))
        return np.round(self.sensor_us(rising) + jitter).astype(np.int64)

    def close(self) -> None:
        self._next_k = None
