"""Request/response sampling at a steady rate, shared by the ASCII (poll mode) and Modbus drivers.

One exchange per sample; a failed exchange (no reply, garbage) becomes a NaN sample and counts the
sample periods it took as missing, then the next attempt waits ``retry_s``. After ``fail_after_s``
without a valid reply the next :meth:`Poller.read` raises DriverError so the owner can reopen the port.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.sensor.base import HostClock, SensorReading, reading

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PollParams:
    """Timing of a polled sensor.

    Attributes:
        rate_hz: samples requested per second (an exchange slower than that sets the pace).
        retry_s: wait after a failed exchange.
        fail_after_s: no valid reply for this long: the sensor is declared silent (reopened by the service).
        batch_s: one read gathers samples for at most this long.
    """

    rate_hz: float = 500.0
    retry_s: float = 0.05
    fail_after_s: float = 2.0
    batch_s: float = 0.02

    def __post_init__(self) -> None:
        if not (self.rate_hz > 0 and self.retry_s >= 0 and self.fail_after_s > 0 and self.batch_s > 0):
            raise ValueError("rate_hz, fail_after_s and batch_s must be positive, retry_s >= 0")


class Poller:
    """Calls ``exchange`` at ``rate_hz``; ``exchange`` returns (value, sensor time µs or None).

    Args:
        exchange: one request/reply; raises DriverError on failure; NaN value = the device answered
            but has no reading (out of range).
        params: timing.
        clock: host clock for host-stamped samples.
        device: port name for errors.
        sensor_clock: the replies carry the device's time; a failed exchange then adds no NaN
            sample (its time on that clock is unknown), only to the missing count.
    """

    def __init__(
        self,
        exchange: Callable[[], tuple[float, int | None]],
        params: PollParams,
        clock: HostClock,
        device: str,
        sensor_clock: bool = False,
    ) -> None:
        self.exchange = exchange
        self.sensor_clock = sensor_clock
        self.params = params
        self.clock = clock
        self.device = device
        self.failures = 0
        self._period_s = 1.0 / params.rate_hz
        self._next_s = time.monotonic()
        self._last_ok_s = time.monotonic()
        self._last_error = ""

    def read(self, timeout_s: float) -> SensorReading:
        silent_s = time.monotonic() - self._last_ok_s
        if silent_s > self.params.fail_after_s:
            self._last_ok_s = time.monotonic()  # the owner reopens; give the reopened port its own time
            raise DriverError(f"no valid reply for {silent_s:.1f} s ({self._last_error})", device=self.device)
        end_s = time.monotonic() + max(0.0, min(timeout_s, self.params.batch_s))
        t_us: list[int] = []
        values: list[float] = []
        missing = 0
        while True:
            now_s = time.monotonic()
            if self._next_s > now_s:
                if self._next_s >= end_s:
                    time.sleep(max(0.0, end_s - now_s))
                    break
                time.sleep(self._next_s - now_s)
            t0_us = self.clock.now_us()
            try:
                value, t_sensor_us = self.exchange()
                failed = False
            except DriverError as exc:
                value, t_sensor_us, failed = math.nan, None, True
                self._last_error = str(exc)
            t1_us = self.clock.now_us()
            if not (failed and self.sensor_clock):
                t_us.append(t_sensor_us if t_sensor_us is not None else (t0_us + t1_us) // 2)
                values.append(value)
            now_s = time.monotonic()
            if failed:
                self.failures += 1
                missing += max(1, round((t1_us - t0_us) * 1e-6 * self.params.rate_hz))
                self._next_s = now_s + self.params.retry_s
            else:
                self._last_ok_s = now_s
                missing += int(math.isnan(value))
                self._next_s = max(self._next_s + self._period_s, now_s - self._period_s)
            if now_s >= end_s:
                break
        return reading(t_us, values, (), missing)
