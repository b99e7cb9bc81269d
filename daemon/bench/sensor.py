"""``flagtrack bench sensor``: the point-sensor check on the digital twin, and the sensor drivers' rates.

Accuracy part (no bus, no real time, so the figures do not depend on the machine's load): the twin
generates events as fast as it can, the core tracker reconstructs them, the simulated sensor samples
the true flag at x/L = 0.73 (noise, latency, a clock offset) and :func:`validate_point` synchronises
and compares, as the supervisor does at the end of each sweep point. Driver part: the ASCII (poll,
stream) and Modbus drivers against the simulated device on a pseudo-terminal.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypedDict

if TYPE_CHECKING:  # NumPy is imported when the benchmark runs (fast --help)
    import numpy as np

COMMAND = "sensor"
HELP = "point-sensor check on the twin (e/L, both clock syncs) and the sensor drivers' sample rates"


class BeamValues(TypedDict):
    """:class:`~flagtrack.daemon.core.pointsensor.BeamParams`' keyword arguments (NumPy-free at import)."""

    x_over_l: float
    units_per_reading: float
    zero_reading: float
    direction: int


BEAM: BeamValues = {
    "x_over_l": 0.73,
    "units_per_reading": 1 / 0.6,
    "zero_reading": 100.0,
    "direction": -1,
}  # mm, +y side
L_PX = 300.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Speeds, update interval, offset, durations."""
    parser.add_argument("--speeds", type=float, nargs="+", default=[5.0, 5.5, 6.0, 7.0], help="wind speeds, m/s")
    parser.add_argument("--tau", type=float, nargs="+", default=[0.0005, 0.001], help="update intervals, s")
    parser.add_argument("--offset-ms", type=float, default=3.0, help="injected sensor clock offset, ms")
    parser.add_argument("--noise", type=float, default=0.002, help="sensor noise, fraction of L")
    parser.add_argument("--record", type=float, default=2.0, help="seconds compared per point")
    parser.add_argument("--drivers", type=float, default=1.0, help="seconds per driver measurement (0: skip)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.set_defaults(run=run)


@dataclass
class TwinPoint:
    """One simulated point: the camera, the sensor, the centrelines, the sensor record, the triggers."""

    camera: Any
    sensor: Any
    lines: Any
    record: Any
    triggers: np.ndarray


def twin_point(
    speed_mps: float,
    *,
    tau_s: float = 0.001,
    offset_ms: float = 3.0,
    drift_ppm: float = 0.0,
    noise_over_l: float = 0.002,
    warm_s: float = 0.3,
    record_s: float = 1.0,
    seed: int = 3,
) -> TwinPoint:
    """Simulate one point: twin -> events -> core tracker, and the twin-reading sensor alongside."""
    import numpy as np

    from flagtrack.daemon.core.centreline import CentrelineBatch
    from flagtrack.daemon.core.pointsensor import BeamParams
    from flagtrack.daemon.core.tracker import Tracker
    from flagtrack.daemon.tracking.section import TrackingConfig
    from flagtrack.daemon.typed_yaml import from_mapping
    from flagtrack.drivers.camera.simulated import SimulatedCamera, SimulatedCameraConfig, fast_forward, trigger_edges
    from flagtrack.drivers.sensor.record import SensorRecord
    from flagtrack.drivers.sensor.twin import TwinSensor, TwinSensorParams

    camera = SimulatedCamera(
        from_mapping(
            SimulatedCameraConfig,
            {
                "speed_mps": speed_mps,
                "events_per_px2": 1.0,
                "trigger_period_ms": 50,
                "seed": seed,
                "slice_us": 4000,
                "flutter": {"onset_speed_mps": 4.9, "decay_speed_mps": 4.4, "tau_amp_s": 0.1},
            },
        )
    )
    camera.open()
    sensor = TwinSensor(
        TwinSensorParams(
            rate_hz=1000,
            noise_over_l=noise_over_l,
            latency_ms=2.0,
            clock_offset_ms=offset_ms,
            drift_ppm=drift_ppm,
            seed=seed,
        ),
        BeamParams(**BEAM),
        camera,
        "mm",
    )
    sensor.open()
    readings, events = [], []
    slice_s = camera.cfg.slice_us * 1e-6
    for _ in range(round((warm_s + record_s) / slice_s)):  # slice by slice, the sensor reading as it goes
        events += fast_forward(camera, slice_s)
        while len(got := sensor.read(0.0)):
            readings.append(got)
    tracking = from_mapping(TrackingConfig, {"root": [150, 240], "length": L_PX, "tau_s": tau_s})
    tracker = Tracker(tracking.tracker_params())
    lines = CentrelineBatch.concatenate([tracker.feed(np.concatenate(events)), tracker.finish()])
    lines = lines.select(lines.t_s >= warm_s)  # the chain starts straight
    t_us = np.concatenate([r.t_us for r in readings])
    pulses = np.concatenate([r.trigger_t_us for r in readings])
    keep = sensor.camera_us(t_us) >= warm_s * 1e6
    record = SensorRecord(
        "twin",
        "mm",
        "sensor",
        t_us[keep],
        np.concatenate([r.value for r in readings])[keep],
        pulses[sensor.camera_us(pulses) >= warm_s * 1e6],
        sum(r.missing for r in readings),
    )
    triggers = trigger_edges(camera.cfg, round(warm_s * 1e6), round((warm_s + record_s) * 1e6))
    return TwinPoint(camera, sensor, lines, record, triggers)


def _accuracy(args: argparse.Namespace) -> list[dict[str, Any]]:
    from flagtrack.daemon.core.pointsensor import BeamParams
    from flagtrack.daemon.core.sync import SyncParams
    from flagtrack.daemon.validation.point import FlagFrame, validate_point

    rows = []
    for tau_s in args.tau:
        for speed in args.speeds:
            point = twin_point(
                speed, tau_s=tau_s, offset_ms=args.offset_ms, noise_over_l=args.noise, record_s=args.record
            )
            started = time.perf_counter()
            v = validate_point(
                point.lines,
                point.record,
                point.triggers,
                FlagFrame(L_PX, (150.0, 240.0), 0.0),
                BeamParams(**BEAM),
                SyncParams(),
                "px",
            )
            check_s = time.perf_counter() - started
            f = v.fields()
            d_mean, _ = v.cloud_distance_over_l
            rows.append(
                {
                    "speed_mps": speed,
                    "tau_s": tau_s,
                    "a_over_l": point.camera.state.amp_over_l,
                    "f_hz": point.camera.state.frequency_hz,
                    "e_rms_over_l": f["sensor_error_rms_over_l"],
                    "e_max_over_l": f["sensor_error_max_over_l"],
                    "delta_rms_over_l": d_mean,
                    "trigger_offset_us": f["sensor_offset_us"],
                    "trigger_unc_us": f["sensor_offset_unc_us"],
                    "xcorr_offset_us": f["sensor_xcorr_offset_us"],
                    "xcorr_unc_us": f["sensor_xcorr_unc_us"],
                    "check_s": check_s,
                }
            )
    return rows


def _drivers(duration_s: float) -> list[dict[str, Any]]:
    from flagtrack.daemon.typed_yaml import from_mapping
    from flagtrack.drivers.sensor.device import DeviceParams, SimulatedSensorDevice
    from flagtrack.drivers.sensor.setup import SensorConfig, open_sensor

    cases: list[tuple[str, DeviceParams, dict[str, Any]]] = [
        ("ascii poll", DeviceParams(), {"driver": "ascii"}),
        ("ascii stream", DeviceParams(rate_hz=1000), {"driver": "ascii", "ascii": {"mode": "stream"}}),
        ("modbus", DeviceParams(protocol="modbus"), {"driver": "modbus", "modbus": {"scale": 0.01}}),
    ]
    rows = []
    for name, params, values in cases:
        with SimulatedSensorDevice(params, lambda t_us: 100.0) as device:
            sensor = open_sensor(
                from_mapping(SensorConfig, {**values, "port": device.port, "timeout_s": 0.1, "poll": {"rate_hz": 1000}})
            )
            sensor.open()
            n = missing = 0
            started = time.perf_counter()
            try:
                while time.perf_counter() - started < duration_s:
                    got = sensor.read(0.05)
                    n += len(got)
                    missing += got.missing
            finally:
                sensor.close()
            rows.append(
                {
                    "driver": name,
                    "requested_hz": 1000,
                    "rate_hz": n / (time.perf_counter() - started),
                    "missing": missing,
                }
            )
    return rows


def run(args: argparse.Namespace) -> int:
    """Print the accuracy table and the driver rates."""
    twin_point(5.5, record_s=0.05)  # warm up (numba compile)
    accuracy = _accuracy(args)
    drivers = _drivers(args.drivers) if args.drivers > 0 else []
    if args.json:
        print(json.dumps({"accuracy": accuracy, "drivers": drivers, "offset_us": args.offset_ms * 1e3}))
        return 0
    print(
        f"twin, sensor at x/L = 0.73, noise {100 * args.noise:.1f} % L, 1 kHz, injected offset "
        f"{args.offset_ms:.3f} ms, {args.record:g} s per point"
    )
    print(
        f"{'U m/s':>6} {'tau ms':>6} {'A/L':>5} {'f Hz':>5} {'e RMS %':>8} {'e max %':>8} {'dRMS %':>7} "
        f"{'trigger ms':>11} {'± us':>5} {'xcorr ms':>9} {'± us':>5} {'check s':>7}"
    )
    for r in accuracy:
        print(
            f"{r['speed_mps']:>6.2f} {1e3 * r['tau_s']:>6.2f} {r['a_over_l']:>5.2f} {r['f_hz']:>5.1f} "
            f"{100 * r['e_rms_over_l']:>8.2f} {100 * r['e_max_over_l']:>8.2f} {100 * r['delta_rms_over_l']:>7.2f} "
            f"{r['trigger_offset_us'] / 1e3:>11.4f} {r['trigger_unc_us']:>5.1f} {r['xcorr_offset_us'] / 1e3:>9.4f} "
            f"{r['xcorr_unc_us']:>5.1f} {r['check_s']:>7.3f}"
        )
    for r in drivers:
        print(
            f"{r['driver']:>12}: {r['rate_hz']:7.0f} samples/s of {r['requested_hz']} requested, "
            f"{r['missing']} missing (pty)"
        )
    return 0
