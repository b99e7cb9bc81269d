"""How ``flagtrack bench live`` prints its figures for a reader, and the secured runs' figures."""

from __future__ import annotations

import argparse
import os
from typing import Any

from flagtrack.daemon.bench.live_figures import throughput_figures


def print_plain(args: argparse.Namespace, results: dict[str, Any], runs: dict[str, dict[str, Any]]) -> None:
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
    _print_shed(results)
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


def _print_shed(results: dict[str, Any]) -> None:
    """What the real-time run's latency budget shed, the accuracy kept, and the recorder's file."""
    accuracy = results.get("realtime_accuracy_vs_offline_max_over_l")
    print(
        f"    latency budget {results.get('max_lag_ms')} ms: shed {results.get('realtime_shed_fraction', 0.0):.1%} "
        f"of the events ({results.get('realtime_shed_packets', 0)} packets); "
        + (
            f"updates within {accuracy:.3%} of L of the offline reconstruction at the same times "
            f"({results.get('realtime_updates')} of its {results.get('realtime_offline_updates')})"
            if accuracy is not None
            else "no update to compare with the offline reconstruction"
        )
    )
    if "recorded_equal_source" in results:
        same = results["recorded_equal_source"]
        print(f"    the recorder's file {'has' if same else 'does NOT have'} the source's events")


def secure_results(n_events: int, runs: dict[str, dict[str, Any]], plain: dict[str, Any]) -> dict[str, Any]:
    """The secured runs' figures and their ratios to the plain ones (secured / plain)."""
    throughput, latency = runs["throughput_secure"], runs["latency_secure"]
    secure = {
        "secure_sustained_mev_s": throughput_figures(throughput, n_events)["sustained_mev_s"],
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
