"""``flagtrack bench soak --minutes M --rate R``: the rig's services under load for a long time.

Separate processes joined by a Zenoh router over loopback TCP, as on a rig (``flagtrack router``):
``flagtrack tracker``, ``flagtrack recorder`` (recording from launch), ``flagtrack supervisor`` (monitor mode, a simulated
tunnel: its bus monitor follows the event rate and the services), ``flagtrack camera`` replaying a
flapping-line recording in a loop at ``R`` Mev/s, and this process, subscribed to the centrelines
and the camera's status. After ``M`` minutes the camera stops; once the recorder has written what
was sent, every process is stopped and the recording is read back.

Reported: packets lost (the tracker's missing packets, the recorder's gaps and queue drops), events
sent (the camera's count) against events recorded (read back from the ``.raw`` file), the resident
memory of every process every few seconds (``/proc/<pid>/status``) and its growth after the first
minute, the latency (camera reception to arrival here) p50/p99 per minute, and the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # NumPy is imported when the benchmark runs (fast --help)
    import numpy as np


COMMAND = "soak"
HELP = "camera -> tracker -> recorder (+ supervisor) as processes for M minutes at R Mev/s: loss, memory, latency"
DESCRIPTION = """\
The rig's services as separate processes for --minutes at --rate Mev/s: packets lost, events recorded
against sent, memory growth of each process and latency per minute. More: docs/reliability.md,
docs/commands.md.
"""
RSS_EVERY_S = 2.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the soak benchmark."""
    parser.add_argument("--minutes", type=float, default=10.0, help="how long the camera streams")
    parser.add_argument("--rate", type=float, default=10.0, help="camera event rate, Mev/s")
    parser.add_argument("--tau", type=float, default=5e-4, help="tracker update interval, s")
    parser.add_argument("--cache", type=Path, default=None, help="folder for the replayed recording")
    parser.add_argument("--json", action="store_true", help="end with one JSON object")


def rss_mb(pid: int) -> float | None:
    """Resident memory of process ``pid``, MB (``VmRSS`` of ``/proc/<pid>/status``); None if gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def rss_growth_mb(samples: list[tuple[float, float]], after_s: float) -> float:
    """Largest RSS after ``after_s`` minus the RSS at ``after_s`` (samples: (seconds, MB)), MB."""
    import numpy as np

    if not samples:
        return 0.0
    times = np.array([t for t, _ in samples])
    values = np.array([v for _, v in samples])
    base = values[min(int(np.searchsorted(times, after_s)), len(values) - 1)]
    later = values[times >= after_s]
    return float(max(later.max() - base, 0.0)) if len(later) else 0.0


def _configs(folder: Path, recording: Path, speed: float, tau_s: float, port: int) -> dict[str, Path]:
    """One rig file per process (each a client of the router at ``port``)."""
    endpoint = f"tcp/127.0.0.1:{port}"
    common: dict[str, Any] = {
        "rig": f"soak{os.getpid()}",
        "tracker": {"root": [60, 240], "length": 400, "tau_s": tau_s},
        "tracker_service": {"batch_updates": 64, "max_batch_delay_s": 0.002},
    }
    client = {"bus": {"mode": "client", "connect": [endpoint]}}
    sections: dict[str, dict[str, Any]] = {
        "tracker": client,
        "recorder": {**client, "recorder": {"directory": str(folder / "rec"), "path": "soak"}},
        "supervisor": {
            **client,
            "supervisor": {"mode": "monitor", "required": ["tracker", "recorder"], "startup_timeout_s": 300},
            "tunnel": {"driver": "simulated"},
        },
        "camera": {
            **client,
            "camera": {
                "adapter": "replay",
                "packet_us": 1000,
                "replay": {"path": str(recording), "speed": speed, "loop": True, "slice_us": 1000},
            },
        },
        "bench": client,
    }
    paths = {}
    for name, section in sections.items():
        paths[name] = folder / f"{name}.yaml"
        paths[name].write_text(json.dumps({**common, **section}))
    return paths


def per_minute_max(samples: list[tuple[float, float]]) -> list[float]:
    """The largest RSS (MB) of each minute of ``samples`` ((seconds, MB)): a plateau or a climb."""
    out: dict[int, float] = {}
    for t, value in samples:
        out[int(t // 60)] = max(out.get(int(t // 60), 0.0), value)
    return [round(out[m], 1) for m in sorted(out)]


class Sampler:
    """RSS of the named processes every :data:`RSS_EVERY_S`, from ``start`` (monotonic s)."""

    def __init__(self, procs: dict[str, int], start: float) -> None:
        self.procs, self.start = procs, start
        self.samples: dict[str, list[tuple[float, float]]] = {name: [] for name in procs}
        self._next = 0.0

    def poll(self, now: float) -> None:
        if now < self._next:
            return
        self._next = now + RSS_EVERY_S
        for name, pid in self.procs.items():
            value = rss_mb(pid)
            if value is not None:
                self.samples[name].append((now - self.start, value))


def soak(minutes: float, rate_mev_s: float, tau_s: float, recording: Path, folder: Path) -> dict[str, Any]:
    """Run the processes for ``minutes`` at ``rate_mev_s``; the figures (see the module doc)."""
    import numpy as np

    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.daemon.schema import CameraStatus, CentrelineMessage, TrackerStatus
    from flagtrack.daemon.transport import Bus
    from flagtrack.drivers.formats import open_events

    file_rate = _event_rate(recording)
    from flagtrack.daemon.bench.live_run import free_port

    port = free_port()
    configs = _configs(folder, recording, rate_mev_s * 1e6 / file_rate, tau_s, port)
    procs: dict[str, subprocess.Popen] = {}
    try:
        procs["router"] = _start(folder, "router", "--listen", f"tcp/127.0.0.1:{port}")
        _wait_for(
            lambda: "listening" in (folder / "router.log").read_text(), 60, f"the router to listen ({_logs(folder)})"
        )
        for name in ("tracker", "recorder", "supervisor"):  # started together: their start-ups overlap
            procs[name] = _start(folder, name, "-c", str(configs[name]))
        with Bus(load_rig(configs["bench"], services=()).bus_config_for(["operator"])) as bus:
            lines = bus.subscribe(bus.keys.centrelines(), CentrelineMessage, capacity=10_000_000, ring=True)
            tracker_status = bus.subscribe(bus.keys.tracker_status(), TrackerStatus, capacity=10_000, ring=True)
            camera_status = bus.subscribe(bus.keys.camera_status("cam0"), CameraStatus, capacity=100)
            alive = bus.watch_liveliness()
            _wait_for(
                lambda: all(alive.is_alive(bus.keys.alive(n)) for n in ("tracker", "recorder", "supervisor")),
                120,
                f"the tracker, the recorder and the supervisor ({_logs(folder)})",
            )
            procs["camera"] = _start(folder, "camera", "-c", str(configs["camera"]))
            sampler = Sampler({name: p.pid for name, p in procs.items()} | {"bench": os.getpid()}, time.monotonic())
            per_minute = _latencies(lines, minutes, sampler, folder)
            sent = _stop_camera(procs["camera"], camera_status)
            recorded_by_sidecar = _wait_recorded(folder / "rec" / "soak.json", sent, sampler)
            missing = 0
            while (s := tracker_status.recv(timeout_s=0.5)) is not None:
                missing = s.missing_packets
            load = os.getloadavg()
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in procs.values():
            try:
                proc.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
    sidecar = json.loads((folder / "rec" / "soak.json").read_text())
    with open_events(folder / "rec" / "soak.raw", strict=True) as reader:
        recorded = sum(len(chunk.events) for chunk in reader)
    lost_recorder = sidecar["missing_packets"] + sidecar["dropped_packets"] + sidecar["malformed_packets"]
    latency = [np.concatenate(m) for m in per_minute if m]
    after_s = min(60.0, minutes * 30)  # growth after the first minute (after half of a shorter run)
    growth = {name: round(rss_growth_mb(s, after_s), 1) for name, s in sampler.samples.items()}
    return {
        "minutes": minutes,
        "rate_mev_s": rate_mev_s,
        "lost_packets": int(missing + lost_recorder),
        "tracker_missing_packets": int(missing),
        "recorder_lost_packets": int(lost_recorder),
        "events_sent": int(sent),
        "events_recorded": int(recorded),
        "events_recorded_sidecar": int(recorded_by_sidecar),
        "rss_growth_mb": max(growth.values()),
        "rss_growth_mb_by_process": growth,
        "rss_mb_last": {name: round(s[-1][1], 1) for name, s in sampler.samples.items() if s},
        "rss_mb_per_minute": {name: per_minute_max(s) for name, s in sampler.samples.items()},
        "latency_p50_ms": round(float(np.percentile(np.concatenate(latency), 50)), 2) if latency else None,
        "latency_p99_ms": round(float(np.percentile(np.concatenate(latency), 99)), 2) if latency else None,
        "latency_p50_ms_per_minute": [round(float(np.percentile(m, 50)), 2) for m in latency],
        "latency_p99_ms_per_minute": [round(float(np.percentile(m, 99)), 2) for m in latency],
        "load_average_1_5_15": [round(x, 2) for x in load],
        "cpu_count": os.cpu_count(),
    }


def _latencies(lines: Any, minutes: float, sampler: Sampler, folder: Path) -> list[list[np.ndarray]]:
    """Latency (ms) of every centreline update, per minute from the first one, for ``minutes``."""
    per_minute: list[list[np.ndarray]] = []
    start = None
    while start is None or time.monotonic() - start < minutes * 60:
        msg = lines.recv(timeout_s=0.2)
        now = time.monotonic()
        sampler.poll(now)
        if msg is None:
            if start is None and now - sampler.start > 120:
                raise RuntimeError(f"no centreline within 120 s of the camera's start: {_logs(folder)}")
            continue
        start = start or now
        if now - start >= minutes * 60:
            break
        minute = int((now - start) // 60)
        while len(per_minute) <= minute:
            per_minute.append([])
        per_minute[minute].append((time.time_ns() - msg.source_ns) * 1e-6)
    return per_minute


def _wait_for(predicate: Any, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out after {timeout_s:g} s waiting for {what}")
        time.sleep(0.05)


def _start(folder: Path, *args: str) -> subprocess.Popen:
    """``flagtrack ARGS`` as a process, its stderr to ``folder/<command>.log`` (a pipe would fill up)."""
    with (folder / f"{args[0]}.log").open("w") as log:
        return subprocess.Popen([sys.executable, "-m", "flagtrack.daemon", *args], stdout=log, stderr=log)


def _logs(folder: Path) -> str:
    """The last line of each process's log, for an error message."""
    tails = []
    for path in sorted(folder.glob("*.log")):
        lines = path.read_text(errors="replace").strip().splitlines()
        tails.append(f"{path.stem}: {lines[-1] if lines else '(nothing)'}")
    return "; ".join(tails)


def _event_rate(recording: Path) -> float:
    """Events per second of camera time in ``recording``."""
    from flagtrack.drivers.formats import open_events

    first, last, n = None, 0, 0
    with open_events(recording) as reader:
        for chunk in reader:
            if len(chunk.events):
                first = int(chunk.events["t"][0]) if first is None else first
                last, n = int(chunk.events["t"][-1]), n + len(chunk.events)
    return n / max((last - (first or 0)) * 1e-6, 1e-3)


def _stop_camera(camera: subprocess.Popen, status: Any) -> int:
    """SIGINT the camera; the events it sent, from its last status."""
    camera.send_signal(signal.SIGINT)
    camera.communicate(timeout=60)
    sent = 0
    while (msg := status.recv(timeout_s=0.5)) is not None:  # its last status came before it exited
        sent = msg.events
    return sent


def _wait_recorded(sidecar: Path, sent: int, sampler: Sampler, timeout_s: float = 120.0) -> int:
    """Wait until the recorder's sidecar counts ``sent`` events (or stops growing); its count."""
    deadline, last, still_since = time.monotonic() + timeout_s, -1, time.monotonic()
    while time.monotonic() < deadline:
        sampler.poll(time.monotonic())
        try:
            events = json.loads(sidecar.read_text())["events"]
        except (OSError, ValueError, KeyError):
            events = 0
        if events >= sent:
            return events
        if events != last:
            last, still_since = events, time.monotonic()
        elif time.monotonic() - still_since > 10:  # the sidecar is rewritten every fsync interval
            return events
        time.sleep(0.2)
    return last


def run(args: argparse.Namespace) -> int:
    """Make (or reuse) the recording, soak, print."""
    from flagtrack.daemon.bench.reconstruct import make_recording

    cache = args.cache or Path(tempfile.gettempdir()) / "flagtrack-bench"
    cache.mkdir(parents=True, exist_ok=True)
    recording = cache / "soak-0.5s.raw"  # ~6 Mev/s of camera data, replayed in a loop at --rate
    if not recording.exists():
        print(f"bench soak: making {recording} ...", file=sys.stderr)
        make_recording(recording, 0.5)
    with tempfile.TemporaryDirectory(prefix="flagtrack-soak-") as tmp:  # the recording is deleted after
        result = soak(args.minutes, args.rate, args.tau, recording, Path(tmp))
    print(
        f"soak: {result['minutes']:g} min at {result['rate_mev_s']:g} Mev/s: {result['lost_packets']} packets lost, "
        f"{result['events_recorded']} of {result['events_sent']} events recorded, RSS growth after the first "
        f"minute {result['rss_growth_mb_by_process']} MB, latency p50/p99 per minute "
        f"{list(zip(result['latency_p50_ms_per_minute'], result['latency_p99_ms_per_minute']))} ms; "
        f"load {result['load_average_1_5_15']} on {result['cpu_count']} cores",
        file=sys.stderr,
    )
    if args.json:
        print(json.dumps(result))
    return 0
