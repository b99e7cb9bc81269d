"""One run of ``flagtrack bench live``: a tracker, a camera replaying a file and, with ``record``, a
recorder, each its own process, joined by Zenoh over loopback TCP; this process subscribes to the
centrelines and the tracker's status and times every update."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.bench.live_figures import cpu_snapshot, cpu_use, events_digest, kept_up, p50_p99, tenths_ms

_START_S = 120  # a service process starts within this (a first run compiles its kernels)


def measure(
    recording: Path,
    tracker: dict[str, Any],
    packet_us: int,
    *,
    speed: float,
    wall_s: float | None,
    secure: bool = False,
    record: bool = False,
    keep_lines: bool = False,
) -> dict[str, Any]:
    """Replay ``recording`` at ``speed`` (0: as fast as possible) for at most ``wall_s`` after the
    first centreline (None: to the end) and measure the updates' latency, the processes' CPU, the
    tracker's counts; ``record``: also whether the recorder's file has the source's events;
    ``keep_lines``: also return the updates (``lines``, a CentrelineBatch)."""
    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.daemon.schema import CentrelineMessage, TrackerStatus
    from flagtrack.daemon.transport import Bus

    port = free_port()
    rig = f"bench{os.getpid()}{int(time.time() * 1000) % 100000}"
    with tempfile.TemporaryDirectory() as tmp:
        endpoint = f"{'tls' if secure else 'tcp'}/127.0.0.1:{port}"
        common = {
            "rig": rig,
            "tracker": tracker,
            "tracker_service": {"batch_updates": 64, "max_batch_delay_s": 0.001},
            "camera": camera_section(recording, packet_us, speed),  # (one rig file: the tracker sees the replay's pace)
        }
        security = secure_section(Path(tmp) / "certs") if secure else {}
        connect = {"bus": {"connect": [endpoint], **security}}
        recorder_at = f"{'tls' if secure else 'tcp'}/127.0.0.1:{free_port()}"  # (peers route nothing for others)
        configs = write_configs(
            Path(tmp),
            tracker={**common, "bus": {"listen": [endpoint], **security}},
            bench={**common, **connect},
            camera={**common, "bus": {"connect": [endpoint, *([recorder_at] if record else [])], **security}},
            recorder={
                **common,
                "bus": {"listen": [recorder_at], **security},
                "recorder": {"directory": str(Path(tmp) / "rec"), "path": "run"},
            },
        )
        procs = {"tracker": start("tracker", configs["tracker"])}
        try:
            with Bus(load_rig(configs["bench"], services=()).bus_config_for(["operator"])) as bus:
                lines = bus.subscribe(bus.keys.centrelines(), CentrelineMessage, capacity=10_000_000)
                status = bus.subscribe(bus.keys.tracker_status(), TrackerStatus, capacity=10_000, ring=True)
                if status.recv(timeout_s=_START_S) is None:  # the tracker is up (it reports once a second)
                    raise RuntimeError("the tracker process did not start")
                if record:  # recording from launch: its sidecar says it began
                    (Path(tmp) / "rec").mkdir()
                    procs["recorder"] = start("recorder", configs["recorder"])
                    if not _wait(lambda: (Path(tmp) / "rec" / "run.json").exists(), _START_S):
                        raise RuntimeError("the recorder process did not start")
                procs["camera"] = start("camera", configs["camera"])
                got = _collect(lines, procs, wall_s)
                stop(procs["camera"])
                final = _last_status(status, 1.2)
                if record:
                    stop(procs.pop("recorder"))
                    got["recorded_equal_source"] = _same_events(recording, Path(tmp) / "rec")
        finally:
            for proc in procs.values():
                stop(proc)
    return _figures(got, final, keep_lines, tracker.get("max_lag_ms"))


def _collect(lines: Any, procs: dict[str, subprocess.Popen], wall_s: float | None) -> dict[str, Any]:
    """The centreline messages until the final one (or ``wall_s`` after the first), with the time
    each arrived here, and the processes' CPU meanwhile."""
    messages, arrived, cpu_start = [], [], None
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        msg = lines.recv(timeout_s=0.5)
        if msg is None:
            continue
        arrived.append(time.time_ns())
        if cpu_start is None:
            cpu_start = cpu_snapshot(procs)
            if wall_s:  # measure wall_s from the first centreline on
                deadline = time.monotonic() + wall_s
        messages.append(msg)
        if msg.final:
            break
    cpu = cpu_use(cpu_start, cpu_snapshot(procs)) if cpu_start else {}
    return {"messages": messages, "arrived_ns": arrived, "cpu_cores": cpu}


def _figures(got: dict[str, Any], final: Any, keep_lines: bool, max_lag_ms: float | None) -> dict[str, Any]:
    from flagtrack.daemon.core.centreline import CentrelineBatch

    messages = got.pop("messages")
    arrived = got.pop("arrived_ns")
    lat = [(now - m.source_ns) * 1e-6 for m, now in zip(messages, arrived)]
    pub = [(m.published_ns - m.source_ns) * 1e-6 for m in messages]
    lat_ms = np.concatenate(lat) if lat else np.zeros(0)
    pub_ms = np.concatenate(pub) if pub else np.zeros(0)
    missing = final.missing_packets if final is not None else 0
    (lat_p50, lat_p99), (pub_p50, pub_p99) = p50_p99(lat_ms), p50_p99(pub_ms)
    first_ns = min((int(m.source_ns.min()) for m in messages if len(m.source_ns)), default=None)
    with_updates = [m for m in messages if len(m.t_s)]
    figures = {
        **got,
        "complete": bool(messages) and messages[-1].final,
        "kept_up": kept_up(pub_ms, missing, max_lag_ms),
        "updates": int(len(pub_ms)),
        "missing_packets": missing,
        "shed_packets": final.shed_packets if final is not None else 0,
        "shed_events": final.shed_events if final is not None else 0,
        "elapsed_s": (arrived[-1] - first_ns) * 1e-9 if arrived and first_ns is not None else 0.0,
        "p50_ms": lat_p50,
        "p99_ms": lat_p99,
        "publish_p50_ms": pub_p50,
        "publish_p99_ms": pub_p99,
        "publish_end_ms": tenths_ms(pub_ms)[1],
    }
    if keep_lines:
        figures["lines"] = CentrelineBatch.concatenate([m.batch() for m in with_updates]) if with_updates else None
    return figures


def _wait(condition: Any, timeout_s: float) -> bool:
    """Whether ``condition()`` came true within ``timeout_s`` (polled every 10 ms)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def _last_status(status: Any, quiet_s: float) -> Any:
    """The tracker's latest status, after waiting ``quiet_s`` for the one that counts the end."""
    time.sleep(quiet_s)
    last = None
    while (s := status.recv(timeout_s=0.1)) is not None:
        last = s
    return last


def _same_events(source: Path, folder: Path) -> bool:
    """Whether the recorder's one file in ``folder`` has the events of ``source``, in order."""
    raws = sorted(folder.glob("*.raw"))
    return len(raws) == 1 and events_digest(raws[0]) == events_digest(source)


def write_configs(folder: Path, **configs: dict[str, Any]) -> dict[str, Path]:
    """Each config as ``<name>.yaml`` in ``folder`` (JSON is YAML)."""
    paths = {}
    for name, config in configs.items():
        paths[name] = folder / f"{name}.yaml"
        paths[name].write_text(json.dumps(config))
    return paths


def camera_section(recording: Path, packet_us: int, speed: float) -> dict[str, Any]:
    """The ``camera:`` section of a replay of ``recording`` cut into packets of ``packet_us``."""
    return {
        "adapter": "replay",
        "packet_us": packet_us,
        "replay": {"path": str(recording), "speed": speed, "loop": False, "slice_us": packet_us},
    }


def bus_floor(recording: Path, packet_us: int, wall_s: float) -> dict[str, Any]:
    """The camera's packets straight to this process at the recording's pace, for at most ``wall_s``
    from the first: how many came, and p50 and p99 (ms) of their time from ``sent_ns`` to arrival."""
    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.daemon.schema import EventPacket
    from flagtrack.daemon.transport import Bus

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    rig = f"bus{os.getpid()}{int(time.time() * 1000) % 100000}"
    with tempfile.TemporaryDirectory() as tmp:
        configs = write_configs(
            Path(tmp),
            bench={"rig": rig, "bus": {"listen": [endpoint]}},
            camera={
                "rig": rig,
                "bus": {"connect": [endpoint]},
                # packets as cut (not joined at a low rate: their time in the camera is not the bus's)
                "camera": {**camera_section(recording, packet_us, 1.0), "min_packet_events": 0},
            },
        )
        transit_ms: list[float] = []
        with Bus(load_rig(configs["bench"], services=()).bus_config_for(["operator"])) as bus:
            packets = bus.subscribe(bus.keys.camera_events("cam0"), EventPacket, capacity=1_000_000)
            camera_proc = start("camera", configs["camera"])
            try:
                deadline = time.monotonic() + _START_S  # the camera process starts (kernels loaded) within this
                while time.monotonic() < deadline:
                    packet = packets.recv(timeout_s=0.5)
                    if packet is None:
                        continue
                    transit_ms.append((time.time_ns() - packet.sent_ns) * 1e-6)
                    if len(transit_ms) == 1:
                        deadline = time.monotonic() + wall_s
                    if packet.end_of_stream:
                        break
            finally:
                stop(camera_proc)
    p50, p99 = p50_p99(np.array(transit_ms))
    return {"packets": len(transit_ms), "p50_ms": p50, "p99_ms": p99}


def secure_section(folder: Path) -> dict[str, Any]:
    """``bus.security`` of the secured runs: a new CA and certificates for the camera, the tracker and
    this process (the ``operator``, which may read every key), mutual TLS, access control."""
    from flagtrack.daemon.security import certs

    certs.init(folder, ["camera", "tracker", "recorder", "operator"])
    tls = {"ca": str(folder / "ca.pem"), "cert": str(folder / "{identity}.pem"), "key": str(folder / "{identity}.key")}
    return {"security": {"tls": tls, "acl": True, "operators": ["operator"]}}


def start(service: str, config: Path) -> subprocess.Popen:
    """``flagtrack <service> -c <config>`` as a process of its own."""
    return subprocess.Popen(
        [sys.executable, "-m", "flagtrack.daemon", service, "-c", str(config)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


def stop(proc: subprocess.Popen) -> None:
    """Interrupt a service process (as Ctrl-C does) and wait for it to end."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=30)


def free_port() -> int:
    """A TCP port free on the loopback now."""
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]
