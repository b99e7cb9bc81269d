"""``flagtrack bench live``'s figures: percentiles, CPU per event and the cores' ceiling, the
processes' CPU from ``/proc``, the machine's wake-up floor, and how far the live updates are from
the offline reconstruction of the same file."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

KEPT_UP_MS = 10.0
"""The real-time run kept up if its last updates are at most this much later than its first (median)."""


def p50_p99(values_ms: Any) -> tuple[float, float]:
    """p50 and p99 of some latencies (ms), NaN for none."""
    if len(values_ms) == 0:
        return float("nan"), float("nan")
    return float(np.percentile(values_ms, 50)), float(np.percentile(values_ms, 99))


def tenths_ms(publish_ms: np.ndarray) -> tuple[float, float]:
    """The median latency (ms) of the first and of the last tenth of the updates (NaN for none)."""
    if not len(publish_ms):
        return float("nan"), float("nan")
    tenth = max(len(publish_ms) // 10, 1)
    return float(np.median(publish_ms[:tenth])), float(np.median(publish_ms[-tenth:]))


def kept_up(publish_ms: np.ndarray, missing: int, max_lag_ms: float | None = None) -> bool:
    """No packet lost, and the last tenth of the updates (median) at most :data:`KEPT_UP_MS` later
    than the first tenth (a tracker that falls behind adds its backlog to every update's latency),
    or within the tracker's latency budget ``max_lag_ms`` (it kept up by shedding: the shed
    fraction says how much)."""
    if not len(publish_ms) or missing:
        return False
    first, last = tenths_ms(publish_ms)
    return bool(last <= first + KEPT_UP_MS or (max_lag_ms is not None and last <= max_lag_ms))


def throughput_figures(throughput: dict[str, Any], n_events: int) -> dict[str, Any]:
    """The throughput run's sustained rate (None if the tracker did not finish the stream), CPU per
    event and the cores' ceiling at that cost (empty and None when the run lost packets: its rate then
    counts events the tracker never saw)."""
    done = throughput["complete"] and throughput["elapsed_s"] > 0
    sustained = n_events / throughput["elapsed_s"] / 1e6 if done else None
    lossless = throughput["missing_packets"] == 0
    per_event = cpu_per_event_ns(throughput["cpu_cores"], sustained) if sustained is not None and lossless else {}
    ns = sum(per_event.values())  # 0 if no clock tick of CPU fell in a very short run: no ceiling then
    return {
        "sustained_mev_s": sustained,
        "cpu_ns_per_event": per_event,
        "cpu_ceiling_mev_s": (os.cpu_count() or 1) * 1e3 / ns if ns > 0 else None,
    }


def cpu_per_event_ns(cores: dict[str, float], rate_mev_s: float) -> dict[str, float]:
    """CPU ns per event of the camera and the tracker, from their cores at ``rate_mev_s``."""
    return {name: cores[name] * 1e3 / rate_mev_s for name in ("camera", "tracker") if name in cores}


def wakeup_lateness_ms(n: int = 1000) -> tuple[float, float]:
    """(p50, p99) of how late a 1 ms sleep of this process returns, ms: the scheduling floor of the
    machine (a VM's host can hold a core for milliseconds), measured before the pipeline runs."""
    late = np.empty(n)
    for i in range(n):
        start = time.perf_counter()
        time.sleep(1e-3)
        late[i] = (time.perf_counter() - start) * 1e3 - 1.0
    return p50_p99(late)


def cpu_snapshot(procs: dict[str, subprocess.Popen]) -> dict[str, float]:
    """Wall time and CPU seconds so far of the named processes and of this one ("bench")."""
    snapshot = {"wall": time.monotonic(), "bench": time.process_time()}
    for name, proc in procs.items():
        seconds = process_cpu_s(proc.pid)
        if seconds is not None:
            snapshot[name] = seconds
    return snapshot


def cpu_use(start: dict[str, float], end: dict[str, float]) -> dict[str, float]:
    """Cores each process used between two snapshots (1.0 = one core busy all the time)."""
    wall = max(end["wall"] - start["wall"], 1e-9)
    return {name: (end[name] - start[name]) / wall for name in start if name != "wall" and name in end}


def process_cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a process, all threads (Linux /proc; ``None`` elsewhere)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def offline_centrelines(recording: Path, tracker: dict[str, Any], folder: Path) -> Any:
    """``flagtrack reconstruct`` of ``recording`` with the ``tracker:`` section ``tracker`` (a
    CentrelineBatch), through a file in ``folder``."""
    from flagtrack.daemon.tracking.offline import reconstruct_file
    from flagtrack.daemon.tracking.section import TrackingConfig
    from flagtrack.daemon.tracking.setup import tracking_setup
    from flagtrack.daemon.typed_yaml import from_mapping
    from flagtrack.drivers.formats.centreline import read_centrelines

    setup = tracking_setup(from_mapping(TrackingConfig, tracker, key="tracker"))
    output = folder / "offline.h5"
    reconstruct_file(recording, output, setup)
    return read_centrelines(output)[0]


def max_eps_over_l(live: Any, offline: Any, length: float) -> float | None:
    """The largest eps_RMS / L between the live updates and the offline ones at the same times
    (those the live tracker made; None when it made none of the offline times)."""
    from flagtrack.daemon.core.metrics import eps_rms

    if len(live) == 0 or len(offline) == 0:
        return None
    index = np.clip(np.searchsorted(offline.t_s, live.t_s - 1e-9), 0, len(offline) - 1)
    same = np.abs(offline.t_s[index] - live.t_s) <= 1e-9
    if not same.any():
        return None
    _, eps = eps_rms(live.select(same), offline.select(index[same]))
    return float(np.max(eps)) / length


def events_digest(path: Path) -> tuple[int, str]:
    """(events, a digest of their times, coordinates and polarities, in order) of an event file:
    equal for two files with the same events, however each cuts them into chunks."""
    import hashlib

    from flagtrack.drivers.formats import open_events

    digest, n = hashlib.sha256(), 0
    with open_events(path) as reader:
        for chunk in reader:
            events = np.ascontiguousarray(chunk.events)
            digest.update(events.tobytes())
            n += len(events)
    return n, digest.hexdigest()
