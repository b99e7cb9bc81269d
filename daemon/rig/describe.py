"""One line per part of a rig saying what it would do, for ``flagtrack config check``: the bus, each
service of the table (:data:`DESCRIPTIONS`, one per service) and the tunnel."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.rig.host import free_bytes, size_text
from flagtrack.daemon.rig.plan import estimate_plan
from flagtrack.daemon.rig.sections import RigSections
from flagtrack.daemon.services.viewer import effective_sink

SDK_NAMES = {"prophesee": "neuromorphic-drivers", "metavision": "OpenEB HAL", "inivation": "dv-processing"}


def bus_line(rig: RigConfig) -> str:
    """The bus: mode, endpoints, namespace, security."""
    bus = rig.bus_config
    parts: list[str] = [bus.mode]
    if bus.listen:
        parts.append(f"listens on {', '.join(bus.listen)}")
    if bus.connect:
        parts.append(f"connects to {', '.join(bus.connect)}")
    parts.append(f"namespace {bus.namespace}")
    security = bus.security
    if security is not None and security.tls is not None:
        parts.append("mutual TLS" + (", access control" if security.acl else ""))
    return ", ".join(parts)


def camera_line(rig: RigSections) -> str:
    camera = rig.camera
    if camera.adapter == "simulated":
        sim = camera.simulated
        speed = f"the tunnel's speed, else {sim.speed_mps:g} m/s"
        return (
            f"{camera.id}: simulated (digital twin) {sim.width}x{sim.height}, flag at root "
            f"({sim.root_px[0]:g}, {sim.root_px[1]:g}) px, length {sim.length_px:g} px, wind: {speed}"
        )
    if camera.adapter == "replay" and camera.replay is not None:
        replay = camera.replay
        pace = "as fast as possible" if replay.speed == 0 else f"at x{replay.speed:g}"
        return f"{camera.id}: replay of {replay.path} {pace}{', in a loop' if replay.loop else ''}"
    hardware = dict(camera.hardware)
    serial = hardware.pop("serial", None)
    which = f"serial {serial}" if serial else "the first camera found"
    settings = "; ".join(f"{key} {_plain(value)}" for key, value in hardware.items()) or "its default settings"
    return f"{camera.id}: {camera.adapter} ({SDK_NAMES[camera.adapter]}), {which}; {settings}"


def tracker_line(rig: RigSections) -> str:
    t = rig.tracker
    root = f"({t.root[0]:g}, {t.root[1]:g})" if t.root is not None else "not given"
    units = f"units of the calibration {t.calibration}" if t.calibration is not None else "pixels (no calibration)"
    length = f"{t.length:g}" if t.length is not None else "not given"
    return (
        f"root {root}, length {length}, direction {t.direction_deg:g} deg, {t.joints} joints, "
        f"tau {t.tau_s * 1e3:g} ms; in {units}"
    )


def recorder_line(rig: RigSections) -> str:
    r = rig.recorder
    when = f"records from the start to {r.path}" if r.path else "records on command"
    return f"into {r.directory}; {when}"


def disk_line(rig: RigSections, names: tuple[str, ...] | list[str]) -> str | None:
    """The free space of the folders the services write, and what it holds (None: they write none)."""
    parts = []
    supervisor = rig.supervisor
    rate_bytes_s = supervisor.expected_rate_mev_s * 1e6 * supervisor.bytes_per_event
    free = free_bytes(rig.recorder.directory) if "recorder" in names else None
    if free is not None:
        minutes = (
            f", about {free / rate_bytes_s / 60:.0f} min at {supervisor.expected_rate_mev_s:g} Mev/s"
            if rate_bytes_s
            else ""
        )
        parts.append(f"{rig.recorder.directory}: {size_text(free)} free{minutes}")
    estimate = estimate_plan(rig) if "supervisor" in names else None
    free = free_bytes(supervisor.runs_dir) if estimate is not None else None
    if estimate is not None and free is not None:
        parts.append(
            f"{supervisor.runs_dir}: {size_text(free)} free, the sweep needs about {size_text(estimate.disk_bytes)}"
        )
    return "; ".join(parts) or None


def viewer_line(rig: RigSections) -> str:
    v = rig.viewer
    sinks = {
        "spawn": "a Rerun window",
        "serve": f"the web viewer on http://{v.serve_host}:{v.web_port}",
        "rrd": f"the file {v.rrd_path}",
        "none": "nothing (sink none)",
    }
    if v.sink == "auto":  # decided where it runs: say both
        here = "a window" if effective_sink(v) == "spawn" else f"none here: the file {v.rrd_path}"
        return f"a Rerun window where there is a display ({here})"
    return sinks[v.sink]


def supervisor_line(rig: RigSections) -> str:
    s = rig.supervisor
    if s.mode == "feedback":
        f = s.feedback
        return (
            f"feedback: holds A/L {f.target_amplitude_over_l:g} between {f.min_speed_mps:g} and "
            f"{f.max_speed_mps:g} m/s for {f.duration_s:g} s; run folders in {s.runs_dir}"
        )
    estimate = estimate_plan(rig)
    if estimate is None:
        return f"{s.mode}: publishes the flag's state (no sweep plan); run folders in {s.runs_dir}"
    sweep = s.sweep
    assert sweep is not None  # an estimate comes from a plan
    return (
        f"sweep: {estimate.points} points, {estimate.lowest_mps:.2f} to {estimate.highest_mps:.2f} m/s, "
        f"{' then '.join(estimate.branches)}; settle {sweep.settle_s:g} s, record {sweep.record_s:g} s: "
        f"about {_duration(estimate.duration_s)}, about {size_text(estimate.disk_bytes)} in {s.runs_dir}"
    )


def sensor_line(rig: RigSections) -> str:
    sensor = rig.sensor
    if sensor is None:
        return "no sensor: section"
    where = "reads the twin's flag" if sensor.driver == "simulated" else f"on {sensor.port}"
    return f"{sensor.id}: {sensor.driver} {where}, beam at x/L {sensor.beam.x_over_l:g}"


def flagstate_line(rig: RigSections) -> str:
    f = rig.flag_state
    return (
        f"the flag's amplitude, frequency and phase cycle by cycle from the centrelines, every {f.interval_s:g} s "
        f"(cycles up to {f.max_cycle_s:g} s)"
    )


def tunnel_line(rig: RigSections) -> str:
    tunnel = rig.tunnel
    if tunnel is None:
        return "no tunnel: section"
    safety = tunnel.safety
    if tunnel.driver == "simulated":
        link = f"simulated ({tunnel.sim.protocol} on a pseudo-terminal)"
    else:
        link = f"{tunnel.driver} on {tunnel.port}, {tunnel.baudrate} baud"
    return (
        f"{link}; {safety.min_speed_mps:g} to {safety.max_speed_mps:g} m/s, ramp {safety.max_ramp_mps2:g} m/s2, "
        f"keep-alive {safety.keepalive_s:g} s, controller watchdog {safety.watchdog_s:g} s"
    )


DESCRIPTIONS: dict[str, Callable[[RigSections], str]] = {
    "supervisor": supervisor_line,
    "recorder": recorder_line,
    "tracker": tracker_line,
    "flagstate": flagstate_line,
    "viewer": viewer_line,
    "sensor": sensor_line,
    "camera": camera_line,
}
"""One line per service of the table (tests/unit/test_config_check.py: every service has one)."""


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _plain(value: Any) -> str:
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} {_plain(v)}" for k, v in value.items()) + "}"
    return str(value)
