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

The tracker runs with its latency budget (``tracker.max_lag_ms``, ``--max-lag-ms``): in the real-time
and latency runs it sheds the packets it could not publish in time, and the figures say how much
(``realtime_shed_fraction``: of the file's events), and how far its updates are from the offline
reconstruction of the same file at the same times (``realtime_accuracy_vs_offline_max_over_l``,
the largest eps_RMS / L), and the median latency to publication of its last tenth of updates
(``realtime_publish_latency_end_ms``: a tracker that falls behind grows it; one that sheds holds it
near the budget). The throughput run replays as fast as possible, which is never shed.
With ``--record`` a recorder process joins the real-time run and the figures say whether its file
has the source's events (``recorded_equal_source``): the whole rig on one machine.

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
import sys
import tempfile
from pathlib import Path
from typing import Any

COMMAND = "live"
HELP = "sustained event rate and latency of camera -> Zenoh -> tracker on a replayed recording"
DESCRIPTION = """\
Replays a recording through camera -> Zenoh -> tracker as separate processes: sustained throughput,
keeping up in real time (what the tracker's latency budget shed, how close its updates are to the
offline reconstruction), latency to publication and the bus's own latency (p50, p99); --record adds
a recorder; --secure repeats each run on a secured bus. More: docs/live.md, docs/commands.md.
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
    parser.add_argument(
        "--max-lag-ms",
        type=float,
        default=None,
        help="the tracker's latency budget, ms (tracker.max_lag_ms; default: the config's default)",
    )
    parser.add_argument(
        "--record", action="store_true", help="a recorder process joins the real-time run; its file is checked"
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
    """Run the measurements and print them."""
    from flagtrack.daemon.bench.live_figures import (
        max_eps_over_l,
        offline_centrelines,
        throughput_figures,
        wakeup_lateness_ms,
    )
    from flagtrack.daemon.bench.live_print import print_plain, secure_results
    from flagtrack.daemon.bench.live_run import bus_floor
    from flagtrack.daemon.bench.reconstruct import LENGTH, ROOT
    from flagtrack.daemon.tracking.section import TrackingConfig

    if args.packet_us < 1:
        raise SystemExit("flagtrack bench live: --packet-us must be positive")
    if args.camera_rate <= 0 or args.latency_rate <= 0 or args.seconds <= 0:
        raise SystemExit("flagtrack bench live: --camera-rate, --latency-rate and --seconds must be positive")
    if args.max_lag_ms is not None and not args.max_lag_ms > 0:
        raise SystemExit("flagtrack bench live: --max-lag-ms must be positive")
    cache = args.cache or Path(tempfile.gettempdir()) / "flagtrack-bench"
    cache.mkdir(parents=True, exist_ok=True)
    load_start = os.getloadavg()
    recording, n_events = _recording_of(cache, args.seconds, args.camera_rate)
    latency_recording, latency_events = _recording_of(cache, args.latency_seconds, args.latency_rate)
    max_lag_ms = args.max_lag_ms if args.max_lag_ms is not None else TrackingConfig().max_lag_ms
    tracker = {"root": list(ROOT), "length": LENGTH, "tau_s": args.tau, "max_lag_ms": max_lag_ms}
    wakeup = wakeup_lateness_ms()
    runs = _runs(args, tracker, recording, latency_recording)
    bus = bus_floor(latency_recording, args.packet_us, args.latency_seconds)
    throughput, realtime, latency = runs["throughput"], runs["realtime"], runs["latency"]
    with tempfile.TemporaryDirectory() as tmp:
        offline = offline_centrelines(recording, tracker, Path(tmp))
    live_lines = realtime.pop("lines")
    results = {
        "kernels": _kernels_state(),
        "cpu_count": os.cpu_count(),
        "load_average_start": list(load_start),
        "max_lag_ms": max_lag_ms,
        "events": n_events,
        "file_rate_mev_s": n_events / args.seconds / 1e6,
        "packet_us": args.packet_us,
        **throughput_figures(throughput, n_events),
        "throughput_missing_packets": throughput["missing_packets"],
        "throughput_updates": throughput["updates"],
        "throughput_shed_packets": throughput["shed_packets"],
        "realtime_kept_up": realtime["kept_up"],
        "realtime_missing_packets": realtime["missing_packets"],
        "realtime_updates": realtime["updates"],
        "realtime_offline_updates": len(offline),
        "realtime_publish_latency_p50_ms": realtime["publish_p50_ms"],
        "realtime_publish_latency_p99_ms": realtime["publish_p99_ms"],
        "realtime_publish_latency_end_ms": realtime["publish_end_ms"],
        "realtime_shed_fraction": realtime["shed_events"] / n_events if n_events else 0.0,
        "realtime_shed_packets": realtime["shed_packets"],
        "realtime_accuracy_vs_offline_max_over_l": max_eps_over_l(live_lines, offline, LENGTH)
        if live_lines is not None
        else None,
        "realtime_cpu_cores": realtime["cpu_cores"],
        **({"recorded_equal_source": realtime["recorded_equal_source"]} if args.record else {}),
        "latency_file_rate_mev_s": latency_events / args.latency_seconds / 1e6,
        "latency_rate_mev_s": args.latency_rate,
        "latency_updates": latency["updates"],
        "latency_p50_ms": latency["p50_ms"],
        "latency_p99_ms": latency["p99_ms"],
        "publish_latency_p50_ms": latency["publish_p50_ms"],
        "publish_latency_p99_ms": latency["publish_p99_ms"],
        "latency_missing_packets": latency["missing_packets"],
        "latency_shed_fraction": latency["shed_events"] / latency_events if latency_events else 0.0,
        "latency_tracker_cores": latency["cpu_cores"].get("tracker"),
        "throughput_cpu_cores": throughput["cpu_cores"],
        "latency_cpu_cores": latency["cpu_cores"],
        "wakeup_late_p50_ms": wakeup[0],
        "wakeup_late_p99_ms": wakeup[1],
        "bus_packets": bus["packets"],
        "bus_p50_ms": bus["p50_ms"],
        "bus_p99_ms": bus["p99_ms"],
        "load_average_end": list(os.getloadavg()),
    }
    if args.secure:
        results.update(secure_results(n_events, runs, results))
    if args.json:
        print(json.dumps(results))
    else:
        print_plain(args, results, runs)
    return 0


def _recording_of(cache: Path, seconds: float, rate_mev_s: float) -> tuple[Path, int]:
    """The cached recording of ``seconds`` at about ``rate_mev_s`` (made on first use), and its events."""
    from flagtrack.daemon.bench.reconstruct import make_recording
    from flagtrack.drivers.formats import open_events

    path = cache / f"live-{seconds:g}s-{rate_mev_s:g}mevs.raw"
    if not path.exists():
        print(f"bench live: making {path} ...", file=sys.stderr)
        make_recording(path, seconds, rate_mev_s=rate_mev_s)
    with open_events(path) as reader:
        return path, sum(len(chunk.events) for chunk in reader)


def _runs(
    args: argparse.Namespace, tracker: dict[str, Any], recording: Path, latency_recording: Path
) -> dict[str, dict[str, Any]]:
    """The throughput, real-time and latency runs (and their secured twins with ``--secure``)."""
    from flagtrack.daemon.bench.live_run import measure

    runs: dict[str, dict[str, Any]] = {}
    plans = [
        ("throughput", recording, 0.0, None),
        ("realtime", recording, 1.0, None),  # to the end, backlog included: its growth is the answer
        ("latency", latency_recording, 1.0, args.latency_seconds),
    ]
    for name, path, speed, wall_s in plans:
        secured = args.secure and name != "realtime"  # (the secured figures are throughput and latency)
        for secure in (False, True) if secured else (False,):  # each secured run right after its plain twin
            realtime = name == "realtime"
            runs[name + ("_secure" if secure else "")] = measure(
                path,
                tracker,
                args.packet_us,
                speed=speed,
                wall_s=wall_s,
                secure=secure,
                record=args.record and realtime,
                keep_lines=realtime,
            )
    return runs


def _kernels_state() -> str:
    """Whether the services load kernels compiled ahead of time or numba compiles them."""
    from flagtrack.daemon.aot.cache import build_dir, read_manifest

    manifest = read_manifest(build_dir())
    return "compiled ahead of time" if manifest is not None else "numba (no usable `flagtrack kernels build`)"
