"""``flagtrack demo``: the whole rig on the built-in simulated rig, a short sweep through the onset."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

COMMAND = "demo"
HELP = "run the whole rig with no hardware: a short up-and-down sweep through the simulated flutter onset"
DESCRIPTION = """\
The whole rig with no hardware, over Zenoh on loopback: simulated tunnel, camera (digital twin),
tracker, recorder, supervisor, viewer and point sensor, in a sweep from 4 to 6 m/s and back through
the flag's onset and decay (about 2 minutes). Prints the onset and decay found, the sensor error and
where the results are. More: docs/commands.md.
"""

ONSET_MPS, DECAY_MPS, STEP_MPS = 4.9, 4.4, 0.25
PAPER_ERROR_OVER_L = 0.015  # the paper's e(t) stays within 0-1.5 % of L (section 4, figure 5c-e)


def demo_rig(out: Path, headless: bool, quick: bool = False) -> dict[str, Any]:
    """The demo's rig config (the same sections a user writes in YAML); ``quick``: 5 points, not 17."""
    from flagtrack.daemon.rig.twin import simulated_tunnel

    sweep = (
        {"range": {"start": 4.2, "stop": 5.2, "step": 0.5}, "settle_s": 1.0, "record_s": 1.5}
        if quick
        else {"range": {"start": 4.0, "stop": 6.0, "step": STEP_MPS}, "settle_s": 1.5, "record_s": 2.0}
    )
    return {
        "rig": f"demo{int(time.time() * 1000) % 100000}",
        # a light twin (0.25-0.36 Mev/s flapping) in 4 ms packets: the whole rig shares one Python process (one
        # GIL) on a small machine; with 2 ms packets the process was GIL-bound while the flag flapped and
        # the twin fell behind real time in about half the runs (1 in 9 with 4 ms, 2-core VM)
        "camera": {
            "id": "cam0",
            "adapter": "simulated",
            "packet_us": 4000,
            "simulated": {
                "events_per_px2": 0.6,
                "noise_rate_hz": 5000,
                "max_lag_s": 1.0,
                "flutter": {"onset_speed_mps": ONSET_MPS, "decay_speed_mps": DECAY_MPS, "tau_amp_s": 0.3},
                "trigger_period_ms": 50,  # sync generator on the trigger input: the sensor stamps the same pulses
            },
        },
        "tracker": {"root": [150, 240], "length": 300, "direction_deg": 0, "tau_s": 0.001},
        "tracker_service": {"batch_updates": 128, "max_batch_delay_s": 0.01},
        "recorder": {"directory": str(out / "recordings")},
        # the view, not the record (the .raw and centreline files keep every event and update): 10 frames a
        # second of at most 1 000 events, 200 tracker updates a second (README.md states the sizes)
        "viewer": {
            "sink": "rrd" if headless else "auto",
            "rrd_path": str(out / "demo.rrd"),
            "geometry_rate_hz": 10,
            "max_points": 1000,
            "update_rate_hz": 200,
        },  # fmt: skip
        "tunnel": simulated_tunnel(ramp_period_s=0.1),
        "supervisor": {
            "mode": "sweep",
            "runs_dir": str(out),
            "run_name": "sweep",
            "onset": {"learn_s": 2.0},
            "sweep": {**sweep, "branches": ["up", "down"]},
        },
        # the paper's validation (section 4, figure 5c-g), as deploy/rig-sensor-sim.yaml: a laser distance
        # sensor across the flag at x/L = 0.73 reading the twin's true flag, its clock 3 ms off the camera's
        "sensor": {
            "id": "om70",
            "driver": "simulated",
            "units": "mm",
            "simulated": {
                "rate_hz": 1000,
                "noise_over_l": 0.002,
                "latency_ms": 2.0,
                "clock_offset_ms": 3.0,
                "record_triggers": True,
            },
            "beam": {"x_over_l": 0.73, "units_per_reading": 1.6666667, "zero_reading": 100.0, "direction": -1},
            "sync": {"mode": "auto"},
        },
        "services": ["camera", "tracker", "recorder", "viewer", "supervisor", "sensor"],
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack demo``."""
    parser.add_argument("--out", type=Path, help="output folder (default: ./flagtrack-demo-<time>)")
    parser.add_argument(
        "--headless", action="store_true", help="no viewer window: write the Rerun view to an .rrd file"
    )
    parser.add_argument("--json", action="store_true", help="end with one JSON object of the results")
    parser.add_argument("--quick", action="store_true", help="a 5-point sweep (4.2, 4.7, 5.2 m/s) in about 30 s")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines or bar, only the results")
    parser.add_argument(
        "--feedback",
        action="store_true",
        help="instead: a control law holds the flag's A/L through a step (docs/control.md)",
    )


def run(args: argparse.Namespace) -> int:
    """Run the demo and report the simulated and detected onset and decay speeds and the sensor check."""
    if args.feedback:
        from flagtrack.daemon.commands._feedback_demo import run_feedback_demo

        return run_feedback_demo(args)
    from flagtrack.daemon.commands._progress import SweepProgressView
    from flagtrack.daemon.rig.config import RigConfig
    from flagtrack.daemon.rig.run import prepare_services, run_rig
    from flagtrack.daemon.typed_yaml import from_mapping

    def say(text: str) -> None:
        if not args.quiet:
            print(f"flagtrack demo: {text}", file=sys.stderr)

    out = (args.out or Path(f"flagtrack-demo-{time.strftime('%Y%m%d-%H%M%S')}")).expanduser().resolve()
    if (out / "sweep").exists():
        print(f"flagtrack demo: error: {out / 'sweep'} exists already; choose another --out", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    config = demo_rig(out, args.headless, args.quick)
    rig = from_mapping(RigConfig, config, key="demo")
    speeds = rig.supervisor.sweep.speed_values()  # type: ignore[union-attr]
    step_mps = float(speeds[1] - speeds[0])
    say(
        f"simulated onset {ONSET_MPS} m/s going up, decay {DECAY_MPS} m/s coming down; "
        f"sweeping {speeds[0]:g} -> {speeds[-1]:g} -> {speeds[0]:g} m/s in {step_mps:g} m/s steps "
        f"(about {'30 s' if args.quick else '2 minutes'}) into {out}; a laser distance sensor at x/L = 0.73 "
        "checks every point"
    )
    prepare_services(rig, list(rig.services), lambda text: say(f"{text} ..."))
    started = time.monotonic()
    with SweepProgressView(quiet=args.quiet) as progress:
        result = run_rig(
            rig,
            list(rig.services),
            shutdown_timeout_s=30.0,
            quiet=True,
            prepared=True,
            on_supervisor_state=progress,
            command="demo",
        )
    supervisor = result.service("supervisor")
    viewer = result.service("viewer")
    rrd = viewer.rrd_path if viewer is not None else None
    reason = supervisor.stop_reason if supervisor is not None else "not run"
    summary, text = demo_report(out / "sweep", rrd, step_mps)
    print(
        f"flagtrack demo: {reason} after {time.monotonic() - started:.0f} s, {summary['points']} points",
        file=sys.stderr,
    )
    print(text, file=sys.stderr)
    if args.json:
        print(json.dumps(summary))
    return result.code or (0 if reason == "finished" else 1)


def demo_report(run_dir: Path, rrd: Path | None, step_mps: float) -> tuple[dict[str, Any], str]:
    """The demo's results from its run folder: the ``--json`` object and the lines printed (onset and
    decay found or ``not detected``, the sensor check, where the files are)."""
    from flagtrack.daemon.sweep.runlog import read_run
    from flagtrack.daemon.sweep.summary import summary_points, transition_speeds

    points = summary_points(read_run(run_dir)) if (run_dir / "run.jsonl").exists() else []
    onset, decay = transition_speeds(points)
    sensor = sensor_check(points, run_dir)
    summary = {
        "onset_mps_simulated": ONSET_MPS,
        "decay_mps_simulated": DECAY_MPS,
        "onset_mps_detected": onset,
        "decay_mps_detected": decay,
        "step_mps": step_mps,
        "points": len(points),
        "summary_csv": str(run_dir / "summary.csv"),
        "log": str(run_dir / "run.jsonl"),
        "rrd": str(rrd) if rrd else None,
        "sensor_error_rms_over_l_max": sensor["worst"],
        "sensor_figure": sensor["figure"],
        "run_json": str(run_dir / "run.json"),
    }
    found = [
        f"  onset  {_detected(onset)} (points {step_mps:g} m/s apart; simulated {ONSET_MPS} m/s)",
        f"  decay  {_detected(decay)} (points {step_mps:g} m/s apart; simulated {DECAY_MPS} m/s)",
        f"  sensor {sensor['text']}",
    ]
    lines = [
        ("summary", f"{summary['summary_csv']}"),
        ("figure", f"{run_dir / 'amplitude.png'} (A/L against the speed: the paper's figure 5h)"),
    ]
    if sensor["figure"]:
        lines.append(("point", f"{sensor['figure']} (sensor and camera at the worst point: the paper's 5c-e)"))
    if (run_dir / "validation.png").exists():
        lines.append(("sensor", f"{run_dir / 'validation.png'} (e/L and Delta_RMS/L against the speed: 5g)"))
    lines.append(("log", summary["log"]))
    lines.append(("about", f"{run_dir / 'README.txt'} (what each file is; run.json for programs)"))
    if rrd:
        size = f"; {rrd.stat().st_size / 1e6:.1f} MB" if rrd.exists() else ""
        lines.append(("view", f"{rrd} (open with: rerun {rrd}{size})"))
    return summary, "\n".join([*found, *(f"  {label:<7} {text}" for label, text in lines)])


def _detected(speed_mps: float | None) -> str:
    """``detected 5.0 m/s``, or ``not detected`` (a sweep stopped before the transition)."""
    return "not detected" if speed_mps is None else f"detected {speed_mps:g} m/s"


def sensor_check(points: list[Any], run_dir: Path) -> dict[str, Any]:
    """The worst e/L RMS of the flapping points (``worst``, None if none has one), the figure of that
    point (``figure``, absolute path or None) and a line saying it (``text``)."""
    from flagtrack.daemon.sweep.quantities import show

    flapping = [p for p in points if p.state == "flapping" and p.status == "done"]
    checked = [p for p in flapping if math.isfinite(p.sensor_error_rms_over_l)]
    if not checked:
        statuses = sorted({str(p.sensor_status) for p in points})
        return {"worst": None, "figure": None, "text": f"no comparison at a flapping point ({', '.join(statuses)})"}
    worst = max(checked, key=lambda p: p.sensor_error_rms_over_l)
    figure = run_dir / worst.sensor_figure if worst.sensor_figure else None
    syncs = [p.sensor_sync for p in points if p.sensor_sync]
    synced = sum(s == "trigger" for s in syncs)
    within = "within" if worst.sensor_error_rms_over_l <= PAPER_ERROR_OVER_L else "OUTSIDE"
    return {
        "worst": worst.sensor_error_rms_over_l,
        "figure": str(figure) if figure is not None and figure.exists() else None,
        "text": (
            f"worst {show('sensor_error_rms_over_l', worst.sensor_error_rms_over_l)} of L over {len(checked)} "
            f"flapping points ({worst.point_id}; {within} the paper's 0-{100 * PAPER_ERROR_OVER_L:.1f} %), clocks "
            f"trigger-synchronised at {synced} of {len(points)} points"
        ),
    }
