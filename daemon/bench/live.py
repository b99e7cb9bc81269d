"""``flagtrack bench live``: replay a recording through camera -> Zenoh -> tracker, as separate processes.

Three processes on this machine, joined by Zenoh over loopback TCP (multicast scouting off): a
``flagtrack tracker`` (listening), a ``flagtrack camera`` replaying a flapping-line recording
(``drivers/sim/quickline``, made on first use with ``--camera-rate`` Mev/s of camera data, 40 by
default: a sensor near its read-out limit) and this process, which subscribes to the centrelines and
the tracker status.

The camera hands the tracker the recording's own EVT 3.0 bytes, cut into packets of ``--packet-us``
of camera time (native bytes, as a device's), and each process loads the kernels built by
``flagtrack kernels build`` when there is one (the line "kernels" says which).

1. Throughput: the file is replayed as fast as possible; the sustained rate is the events of the
   file over the time from the first packet to the tracker's last centreline, and the tracker must
   report no missing packet.
2. Real time: the same file at its own pace (speed 1), as the device would send it; the tracker
   *keeps up* if no packet is lost and the latency of the last tenth of the updates (median) is
   within 10 ms of that of the first tenth (a tracker that falls behind adds its backlog to every
   update's latency). p50 and p99 of the latency to publication.
3. Latency: a recording of ``--latency-rate`` Mev/s (5 by default; made on first use) replayed at
   its own pace for at most ``--latency-seconds``; each update's latency runs from the adapter's
   reception of the packet that completed its window (``sent_ns``) to the publication of the
   centreline message by the tracker (``published_ns``, the latency the live-pipeline issue asks
   for) and to its arrival here (the bus hop back to a subscriber in another process included);
   p50 and p99 of both.

4. The bus alone: the latency run's recording replayed at its own pace to this process, no tracker;
   p50 and p99 of each packet's time from the adapter's reception (``sent_ns``) to its arrival here.
   Every update pays at least this before the tracker starts on it.

From the throughput run it also derives the CPU each event costs the camera and the tracker (their
cores over the sustained rate) and the rate the machine's cores could carry at that cost if nothing
else ran and the work split perfectly (the pipeline's ceiling here).

With ``--secure`` each run is made twice, plain and then secured as ``bus.security`` secures a rig
(mutual TLS on every link, each process its own certificate, access control made from the rig,
default deny), and the secured figures are reported next to the plain ones with their ratio.

In both runs it also reports the cores each process used while the centrelines came (from
``/proc``, Linux only): the camera, the tracker and this process share the machine, and when
together they keep it busy, packets wait for a core and the latency's tail grows. Before both, it
measures how late a 1 ms sleep of this process wakes up (p50, p99): the machine's own scheduling
floor, which every hop of the pipeline pays.
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
from typing import Any

COMMAND = "live"
KEPT_UP_MS = 10.0
"""The real-time run kept up if its last updates are at most this much later than its first (median)."""
HELP = "sustained event rate and latency of camera -> Zenoh -> tracker on a replayed recording"
DESCRIPTION = """\
Replays a recording through camera -> Zenoh -> tracker as separate processes: sustained throughput,
keeping up in real time, latency to publication and the bus's own latency (p50, p99); --secure
repeats each run on a secured bus. More: docs/live.md, docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the live benchmark."""
    parser.add_argument(
        "--seconds", type=float, default=2.0, help="recording length, s (at 40 Mev/s: 2 s ~ 80 M events)"
    )
    parser.add_argument(
        "--camera-rate", type=float, default=40.0, help="event rate of the recording (camera data), Mev/s"
    )
    parser.add_argument("--latency-rate", type=float, default=5.0, help="event rate of the latency run, Mev/s")
    parser.add_argument("--latency-seconds", type=float, default=4.0, help="wall time of the latency run, s")
    parser.add_argument("--tau", type=float, default=2.5e-4, help="tracker update interval, s")
    parser.add_argument(
        "--packet-us",
        type=int,
        default=1000,
        help="camera time per event packet, us (the default "
        "of camera.packet_us); the replay hands over as much per read when paced",
    )
    parser.add_argument("--cache", type=Path, default=None, help="folder for the recording")
    parser.add_argument(
        "--secure",
        action="store_true",
        help="also run both measurements secured (mutual TLS, one certificate per process, access "
        "control) and report them next to the plain ones",
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def run(args: argparse.Namespace) -> int:
    """Run both measurements and print them."""
    from flagtrack.daemon.bench.reconstruct import LENGTH, ROOT, make_recording
    from flagtrack.drivers.formats import open_events

    if args.packet_us < 1:
        raise SystemExit("flagtrack bench live: --packet-us must be positive")
    if args.camera_rate <= 0 or args.latency_rate <= 0 or args.seconds <= 0:
        raise SystemExit("flagtrack bench live: --camera-rate, --latency-rate and --seconds must be positive")
    cache = args.cache or Path(tempfile.gettempdir()) / "flagtrack-bench"
    cache.mkdir(parents=True, exist_ok=True)

    def recording_of(seconds: float, rate_mev_s: float) -> tuple[Path, int]:
        """The cached recording of ``seconds`` at about ``rate_mev_s``, and its number of events."""
        path = cache / f"live-{seconds:g}s-{rate_mev_s:g}mevs.raw"
        if not path.exists():
            print(f"bench live: making {path} ...", file=sys.stderr)
            make_recording(path, seconds, rate_mev_s=rate_mev_s)
        with open_events(path) as reader:
            return path, sum(len(chunk.events) for chunk in reader)

    recording, n_events = recording_of(args.seconds, args.camera_rate)
    latency_recording, latency_events = recording_of(args.latency_seconds, args.latency_rate)
    file_rate = n_events / args.seconds
    tracker = {"root": list(ROOT), "length": LENGTH, "tau_s": args.tau}
    wakeup = _wakeup_lateness_ms()
    runs: dict[str, dict[str, Any]] = {}
    plans = [
        ("throughput", recording, 0.0, None),
        ("realtime", recording, 1.0, None),  # to the end, backlog included: its growth is the answer
        ("latency", latency_recording, 1.0, args.latency_seconds),
    ]
    for name, path, speed, wall_s in plans:
        secured = args.secure and name != "realtime"  # (the secured figures are throughput and latency)
        for secure in (False, True) if secured else (False,):  # each secured run right after its plain twin
            runs[name + ("_secure" if secure else "")] = _measure(
                path, tracker, args.packet_us, speed=speed, loop=False, wall_s=wall_s, secure=secure
            )
    bus = _bus_floor(latency_recording, args.packet_us, args.latency_seconds)
    throughput, realtime, latency = runs["throughput"], runs["realtime"], runs["latency"]
    results = {
        "kernels": _kernels_state(),
        "events": n_events,
        "file_rate_mev_s": file_rate / 1e6,
        "packet_us": args.packet_us,
        **_throughput_figures(throughput, n_events),
        "throughput_missing_packets": throughput["missing_packets"],
        "throughput_updates": throughput["updates"],
        "realtime_kept_up": realtime["kept_up"],
        "realtime_missing_packets": realtime["missing_packets"],
        "realtime_updates": realtime["updates"],
        "realtime_publish_latency_p50_ms": realtime["publish_p50_ms"],
        "realtime_publish_latency_p99_ms": realtime["publish_p99_ms"],
        "realtime_cpu_cores": realtime["cpu_cores"],
        "latency_file_rate_mev_s": latency_events / args.latency_seconds / 1e6,
        "latency_rate_mev_s": args.latency_rate,
        "latency_updates": latency["updates"],
        "latency_p50_ms": latency["p50_ms"],
        "latency_p99_ms": latency["p99_ms"],
        "publish_latency_p50_ms": latency["publish_p50_ms"],
        "publish_latency_p99_ms": latency["publish_p99_ms"],
        "latency_missing_packets": latency["missing_packets"],
        "throughput_cpu_cores": throughput["cpu_cores"],
        "latency_cpu_cores": latency["cpu_cores"],
        "wakeup_late_p50_ms": wakeup[0],
        "wakeup_late_p99_ms": wakeup[1],
        "bus_packets": bus["packets"],
        "bus_p50_ms": bus["p50_ms"],
        "bus_p99_ms": bus["p99_ms"],
    }
    if args.secure:
        results.update(_secure_results(n_events, runs, results))
    if args.json:
        print(json.dumps(results))
    else:
        _print_plain(args, results, runs)
    return 0


def _print_plain(args: argparse.Namespace, results: dict[str, Any], runs: dict[str, dict[str, Any]]) -> None:
    """The figures as lines for a reader."""
    throughput, realtime, latency = runs["throughput"], runs["realtime"], runs["latency"]
    wakeup = (results["wakeup_late_p50_ms"], results["wakeup_late_p99_ms"])
    per_event = results["cpu_ns_per_event"]
    print(
        f"camera -> Zenoh -> tracker, separate processes, {results['events'] / 1e6:.1f} M events "
        f"({results['file_rate_mev_s']:.1f} Mev/s of camera data), tau = {args.tau * 1e6:g} us, "
        f"packets of {args.packet_us} us"
    )
    print(f"  kernels: {results['kernels']}")
    sustained = results["sustained_mev_s"]
    print(
        f"  throughput: {sustained:.1f} Mev/s sustained, {throughput['missing_packets']} packets lost"
        if sustained
        else "  throughput: the tracker did not finish the stream"
    )
    print(
        f"  real time at {results['file_rate_mev_s']:.1f} Mev/s over {realtime['updates']} updates: "
        f"{'kept up' if realtime['kept_up'] else 'fell behind'}, {realtime['missing_packets']} packets lost, "
        f"to publication p50 {realtime['publish_p50_ms']:.2f} ms, p99 {realtime['publish_p99_ms']:.2f} ms"
    )
    print(
        f"  latency at {args.latency_rate:g} Mev/s over {latency['updates']} updates, "
        f"{latency['missing_packets']} packets lost:"
    )
    print(
        f"    to publication by the tracker: p50 {latency['publish_p50_ms']:.2f} ms, "
        f"p99 {latency['publish_p99_ms']:.2f} ms"
    )
    print(f"    to arrival at a subscriber:    p50 {latency['p50_ms']:.2f} ms, p99 {latency['p99_ms']:.2f} ms")
    print(
        f"  the bus alone at {args.latency_rate:g} Mev/s (camera -> a subscriber, no tracker, "
        f"{results['bus_packets']} packets): p50 {results['bus_p50_ms']:.2f} ms, p99 {results['bus_p99_ms']:.2f} ms"
    )
    if per_event:
        print(
            "  CPU per event in the throughput run: "
            + ", ".join(f"{name} {ns:.1f} ns" for name, ns in per_event.items())
            + f": {os.cpu_count()} cores at that cost carry at most {results['cpu_ceiling_mev_s']:.1f} Mev/s"
        )
    elif sustained:
        print(
            "  CPU per event: not measured (the throughput run lost packets, so its rate counts events the "
            "tracker never saw: a file longer than the tracker's queue, tracker_service.queue_bytes)"
        )
    print(
        f"  this machine, idle: a 1 ms sleep wakes up p50 {wakeup[0]:.2f} ms, p99 {wakeup[1]:.2f} ms late "
        f"(every hop of the pipeline waits for such a wake-up)"
    )
    for label, cores in (
        ("throughput run", throughput["cpu_cores"]),
        ("real-time run", realtime["cpu_cores"]),
        ("latency run", latency["cpu_cores"]),
    ):
        if cores:
            used = ", ".join(f"{name} {value:.2f}" for name, value in cores.items())
            print(f"  CPU in the {label} (cores; this machine has {os.cpu_count()}): {used}")
    if args.secure:
        _print_secure(results)


def _kernels_state() -> str:
    """Whether the services load kernels compiled ahead of time or numba compiles them."""
    from flagtrack.daemon.aot.cache import build_dir, read_manifest

    manifest = read_manifest(build_dir())
    return "compiled ahead of time" if manifest is not None else "numba (no usable `flagtrack kernels build`)"


def _secure_results(n_events: int, runs: dict[str, dict[str, Any]], plain: dict[str, Any]) -> dict[str, Any]:
    """The secured runs' figures and their ratios to the plain ones (secured / plain)."""
    throughput, latency = runs["throughput_secure"], runs["latency_secure"]
    secure = {
        "secure_sustained_mev_s": _throughput_figures(throughput, n_events)["sustained_mev_s"],
        "secure_throughput_missing_packets": throughput["missing_packets"],
        "secure_latency_updates": latency["updates"],
        "secure_latency_p50_ms": latency["p50_ms"],
        "secure_latency_p99_ms": latency["p99_ms"],
        "secure_publish_latency_p50_ms": latency["publish_p50_ms"],
        "secure_publish_latency_p99_ms": latency["publish_p99_ms"],
        "secure_latency_missing_packets": latency["missing_packets"],
        "secure_throughput_cpu_cores": throughput["cpu_cores"],
        "secure_latency_cpu_cores": latency["cpu_cores"],
    }
    for name in ("sustained_mev_s", "latency_p50_ms", "latency_p99_ms", "publish_latency_p50_ms",
                 "publish_latency_p99_ms"):  # fmt: skip
        a, b = plain[name], secure[f"secure_{name}"]
        secure[f"ratio_{name}"] = b / a if a and b else None
    return secure


def _print_secure(results: dict[str, Any]) -> None:
    def ratio(name: str) -> str:
        value = results[f"ratio_{name}"]
        return f"x{value:.2f}" if value else "-"

    sustained = results["secure_sustained_mev_s"]
    print("  secured (mutual TLS, a certificate per process, access control), next to the plain runs:")
    print(
        f"    throughput: {sustained:.1f} Mev/s ({ratio('sustained_mev_s')}), "
        f"{results['secure_throughput_missing_packets']} packets lost"
        if sustained
        else "    throughput: the tracker did not finish the stream"
    )
    print(
        f"    to publication: p50 {results['secure_publish_latency_p50_ms']:.2f} ms "
        f"({ratio('publish_latency_p50_ms')}), p99 {results['secure_publish_latency_p99_ms']:.2f} ms "
        f"({ratio('publish_latency_p99_ms')})"
    )
    print(
        f"    to a subscriber: p50 {results['secure_latency_p50_ms']:.2f} ms ({ratio('latency_p50_ms')}), "
        f"p99 {results['secure_latency_p99_ms']:.2f} ms ({ratio('latency_p99_ms')}), "
        f"{results['secure_latency_missing_packets']} packets lost"
    )
    for label in ("throughput", "latency"):
        cores = results[f"secure_{label}_cpu_cores"]
        if cores:
            print(f"    CPU in the secured {label} run (cores): " + ", ".join(f"{k} {v:.2f}" for k, v in cores.items()))


def _measure(  # noqa: PLR0915 - one measurement, step by step
    recording: Path,
    tracker: dict[str, Any],
    packet_us: int,
    *,
    speed: float,
    loop: bool,
    wall_s: float | None,
    secure: bool = False,
) -> dict[str, Any]:
    import numpy as np

    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.daemon.schema import CentrelineMessage, TrackerStatus
    from flagtrack.daemon.transport import Bus

    port = _free_port()
    rig = f"bench{os.getpid()}{int(time.time() * 1000) % 100000}"
    with tempfile.TemporaryDirectory() as tmp:
        tracker_cfg, camera_cfg = Path(tmp) / "tracker.yaml", Path(tmp) / "camera.yaml"
        common = {"rig": rig, "tracker": tracker, "tracker_service": {"batch_updates": 64, "max_batch_delay_s": 0.001}}
        endpoint = f"{'tls' if secure else 'tcp'}/127.0.0.1:{port}"
        security = _secure_section(Path(tmp) / "certs") if secure else {}
        tracker_cfg.write_text(json.dumps({**common, "bus": {"listen": [endpoint], **security}}))
        bench_cfg = Path(tmp) / "bench.yaml"
        bench_cfg.write_text(json.dumps({**common, "bus": {"connect": [endpoint], **security}}))
        camera_cfg.write_text(
            json.dumps(
                {
                    **common,
                    "bus": {"connect": [endpoint], **security},
                    "camera": _camera_section(recording, packet_us, speed, loop),
                }
            )
        )
        tracker_proc = _start("tracker", tracker_cfg)
        procs = [tracker_proc]
        try:
            with Bus(load_rig(bench_cfg, services=()).bus_config_for(["operator"])) as bus:
                lines = bus.subscribe(bus.keys.centrelines(), CentrelineMessage, capacity=10_000_000)
                status = bus.subscribe(bus.keys.tracker_status(), TrackerStatus, capacity=10_000, ring=True)
                if status.recv(timeout_s=60) is None:  # the tracker is up (it reports once a second)
                    raise RuntimeError("the tracker process did not start")
                camera_proc = _start("camera", camera_cfg)
                procs.append(camera_proc)
                watched = {"tracker": tracker_proc, "camera": camera_proc}  # their CPU use is reported
                latencies, published, updates, first_ns, last_ns, complete = [], [], 0, None, None, False
                cpu_start: dict[str, float] | None = None
                deadline = time.monotonic() + 600
                while time.monotonic() < deadline:
                    msg = lines.recv(timeout_s=0.5)
                    if msg is None:
                        continue
                    now = time.time_ns()
                    if first_ns is None and wall_s:  # measure wall_s from the first centreline on
                        deadline = time.monotonic() + wall_s
                    if first_ns is None:
                        cpu_start = _cpu_snapshot(watched)
                    if first_ns is None and len(msg.source_ns):
                        first_ns = int(msg.source_ns.min())
                    last_ns = now
                    updates += len(msg.t_s)
                    latencies.append((now - msg.source_ns) * 1e-6)
                    published.append((msg.published_ns - msg.source_ns) * 1e-6)
                    if msg.final:
                        complete = True
                        break
                cpu = _cpu_use(cpu_start, _cpu_snapshot(watched)) if cpu_start else {}
                camera_proc.send_signal(signal.SIGINT)
                camera_proc.communicate(timeout=30)
                time.sleep(1.2)
                missing = 0
                while (s := status.recv(timeout_s=0.1)) is not None:
                    missing = s.missing_packets
        finally:
            for proc in procs:
                if proc.poll() is None:
                    proc.send_signal(signal.SIGINT)
            for proc in procs:
                proc.communicate(timeout=30)
    lat = np.concatenate(latencies) if latencies else np.zeros(0)
    pub = np.concatenate(published) if published else np.zeros(0)
    tenth = max(len(pub) // 10, 1)
    (lat_p50, lat_p99), (pub_p50, pub_p99) = _p50_p99(lat), _p50_p99(pub)
    return {
        "complete": complete,
        "kept_up": bool(len(pub) and missing == 0 and np.median(pub[-tenth:]) <= np.median(pub[:tenth]) + KEPT_UP_MS),
        "updates": updates,
        "missing_packets": missing,
        "cpu_cores": cpu,
        "elapsed_s": ((last_ns or 0) - (first_ns or 0)) * 1e-9,
        "p50_ms": lat_p50,
        "p99_ms": lat_p99,
        "publish_p50_ms": pub_p50,
        "publish_p99_ms": pub_p99,
    }


def _camera_section(recording: Path, packet_us: int, speed: float, loop: bool) -> dict[str, Any]:
    """The ``camera:`` section of a replay of ``recording`` cut into packets of ``packet_us``."""
    return {
        "adapter": "replay",
        "packet_us": packet_us,
        "replay": {"path": str(recording), "speed": speed, "loop": loop, "slice_us": packet_us},
    }


def _bus_floor(recording: Path, packet_us: int, wall_s: float) -> dict[str, Any]:
    """The camera's packets straight to this process at the recording's pace, for at most ``wall_s``
    from the first: how many came, and p50 and p99 (ms) of their time from ``sent_ns`` to arrival."""
    import numpy as np

    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.daemon.schema import EventPacket
    from flagtrack.daemon.transport import Bus

    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    rig = f"bus{os.getpid()}{int(time.time() * 1000) % 100000}"
    with tempfile.TemporaryDirectory() as tmp:
        bench_cfg, camera_cfg = Path(tmp) / "bench.yaml", Path(tmp) / "camera.yaml"
        bench_cfg.write_text(json.dumps({"rig": rig, "bus": {"listen": [endpoint]}}))
        camera = _camera_section(recording, packet_us, 1.0, False)
        camera_cfg.write_text(json.dumps({"rig": rig, "bus": {"connect": [endpoint]}, "camera": camera}))
        transit_ms: list[float] = []
        with Bus(load_rig(bench_cfg, services=()).bus_config_for(["operator"])) as bus:
            packets = bus.subscribe(bus.keys.camera_events("cam0"), EventPacket, capacity=1_000_000)
            camera_proc = _start("camera", camera_cfg)
            try:
                deadline = time.monotonic() + 120  # the camera process starts (kernels loaded) within this
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
                camera_proc.send_signal(signal.SIGINT)
                camera_proc.communicate(timeout=30)
    p50, p99 = _p50_p99(np.array(transit_ms))
    return {"packets": len(transit_ms), "p50_ms": p50, "p99_ms": p99}


def _p50_p99(values_ms: Any) -> tuple[float, float]:
    """p50 and p99 of some latencies (ms), NaN for none."""
    import numpy as np

    if len(values_ms) == 0:
        return float("nan"), float("nan")
    return float(np.percentile(values_ms, 50)), float(np.percentile(values_ms, 99))


def _throughput_figures(throughput: dict[str, Any], n_events: int) -> dict[str, Any]:
    """The throughput run's sustained rate (None if the tracker did not finish the stream), CPU per
    event and the cores' ceiling at that cost (empty and None when the run lost packets: its rate then
    counts events the tracker never saw)."""
    done = throughput["complete"] and throughput["elapsed_s"] > 0
    sustained = n_events / throughput["elapsed_s"] / 1e6 if done else None
    lossless = throughput["missing_packets"] == 0
    per_event = _cpu_per_event_ns(throughput["cpu_cores"], sustained) if sustained is not None and lossless else {}
    ns = sum(per_event.values())  # 0 if no clock tick of CPU fell in a very short run: no ceiling then
    return {
        "sustained_mev_s": sustained,
        "cpu_ns_per_event": per_event,
        "cpu_ceiling_mev_s": (os.cpu_count() or 1) * 1e3 / ns if ns > 0 else None,
    }


def _cpu_per_event_ns(cores: dict[str, float], rate_mev_s: float) -> dict[str, float]:
    """CPU ns per event of the camera and the tracker, from their cores at ``rate_mev_s``."""
    return {name: cores[name] * 1e3 / rate_mev_s for name in ("camera", "tracker") if name in cores}


def _secure_section(folder: Path) -> dict[str, Any]:
    """``bus.security`` of the secured runs: a new CA and certificates for the camera, the tracker and
    this process (the ``operator``, which may read every key), mutual TLS, access control."""
    from flagtrack.daemon.security import certs

    certs.init(folder, ["camera", "tracker", "operator"])
    tls = {"ca": str(folder / "ca.pem"), "cert": str(folder / "{identity}.pem"), "key": str(folder / "{identity}.key")}
    return {"security": {"tls": tls, "acl": True, "operators": ["operator"]}}


def _wakeup_lateness_ms(n: int = 1000) -> tuple[float, float]:
    """(p50, p99) of how late a 1 ms sleep of this process returns, ms: the scheduling floor of the
    machine (a VM's host can hold a core for milliseconds), measured before the pipeline runs."""
    import numpy as np

    late = np.empty(n)
    for i in range(n):
        start = time.perf_counter()
        time.sleep(1e-3)
        late[i] = (time.perf_counter() - start) * 1e3 - 1.0
    return _p50_p99(late)


def _cpu_snapshot(procs: dict[str, subprocess.Popen]) -> dict[str, float]:
    """Wall time and CPU seconds so far of the named processes and of this one ("bench")."""
    snapshot = {"wall": time.monotonic(), "bench": time.process_time()}
    for name, proc in procs.items():
        seconds = _process_cpu_s(proc.pid)
        if seconds is not None:
            snapshot[name] = seconds
    return snapshot


def _cpu_use(start: dict[str, float], end: dict[str, float]) -> dict[str, float]:
    """Cores each process used between two snapshots (1.0 = one core busy all the time)."""
    wall = max(end["wall"] - start["wall"], 1e-9)
    return {
        name: (end[name] - start[name]) / wall
        for name in ("camera", "tracker", "bench")
        if name in start and name in end
    }


def _process_cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a process, all threads (Linux /proc; ``None`` elsewhere)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _start(service: str, config: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "flagtrack.daemon", service, "-c", str(config)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]
