"""``flagtrack demo --feedback``: the twin's flag held at a target amplitude through a step of the
set-point, by a law of a few lines in the output folder, on the whole simulated rig in one process."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

TARGETS = (0.22, 0.26)
STEP_AFTER_S, AFTER_S, SETTLE_S = 25.0, 25.0, 6.0


def feedback_rig(out: Path) -> dict[str, Any]:
    """The rig of the feedback demo (the sections a user writes in YAML): a light twin, the tracker, the
    flag state, the recorder, and the supervisor running ``out/law.py`` for 50 s."""
    from flagtrack.daemon.rig.twin import simulated_tunnel

    return {
        "rig": f"fbdemo{int(time.time() * 1000) % 100000}",
        "camera": {
            "id": "cam0",
            "adapter": "simulated",
            "packet_us": 4000,  # a light twin: the whole rig shares one Python process
            "simulated": {
                "events_per_px2": 0.6,
                "noise_rate_hz": 5000,
                "max_lag_s": 1.0,
                "flutter": {"onset_speed_mps": 4.9, "decay_speed_mps": 4.4, "tau_amp_s": 0.3},
            },
        },
        "tracker": {"root": [150, 240], "length": 300, "direction_deg": 0, "tau_s": 0.001},
        "tracker_service": {"max_batch_delay_s": 0.005},
        "recorder": {"directory": str(out / "recordings")},
        "tunnel": simulated_tunnel(timeout_s=2.0),
        "supervisor": {
            "runs_dir": str(out),
            "run_name": "control",
            "onset": {"learn_s": 1.0},
            "control": {
                "period_s": 0.05,
                "duration_s": STEP_AFTER_S + AFTER_S,
                "start_speed_mps": 5.3,
                "settle_s": 3.0,
            },
        },
        "services": ["camera", "tracker", "recorder"],
    }


def run_feedback_demo(args: argparse.Namespace) -> int:
    """Run the feedback demo into ``args.out``; say how well the flag was held and where the figure is."""
    from flagtrack.daemon.bench.control import LAW, figures
    from flagtrack.daemon.rig.config import RigConfig
    from flagtrack.daemon.rig.control import control_rig
    from flagtrack.daemon.rig.run import prepare_services, run_rig
    from flagtrack.daemon.typed_yaml import from_mapping

    def say(text: str) -> None:
        if not args.quiet:
            print(f"flagtrack demo: {text}", file=sys.stderr)

    out = (args.out or Path(f"flagtrack-feedback-{time.strftime('%Y%m%d-%H%M%S')}")).expanduser().resolve()
    if (out / "control").exists():
        print(f"flagtrack demo: error: {out / 'control'} exists already; choose another --out", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    law = out / "law.py"
    law.write_text(LAW.format(targets=TARGETS, step_after=STEP_AFTER_S, gain=1.0).lstrip())
    rig = from_mapping(RigConfig, feedback_rig(out), key="demo")
    rig, names = control_rig(rig, f"{law}:law")
    say(
        f"holding the twin's A/L at {TARGETS[0]}, then {TARGETS[1]} from {STEP_AFTER_S:g} s on, with the law "
        f"{law} (about a minute and a half) into {out}"
    )
    prepare_services(rig, names, lambda text: say(f"{text} ..."))
    started = time.monotonic()
    result = run_rig(rig, names, shutdown_timeout_s=30.0, quiet=True, prepared=True, command="demo")
    supervisor = result.service("supervisor")
    run_dir = out / "control"
    found = figures(run_dir, list(TARGETS), SETTLE_S)
    reason = supervisor.stop_reason if supervisor is not None else "not run"

    def num(value: float | None, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    print(
        f"flagtrack demo: {reason} after {time.monotonic() - started:.0f} s, {found['steps']} control steps\n"
        f"  held    A/L error RMS {num(found['amplitude_error_rms_over_l_before_step'], '.4f')} at {TARGETS[0]}, "
        f"{num(found['amplitude_error_rms_over_l'], '.4f')} at {TARGETS[1]} (from {SETTLE_S:g} s after each step)\n"
        f"  latency p50 {num(found['loop_latency_p50_ms'], '.1f')} ms, p99 {num(found['loop_latency_p99_ms'], '.1f')} "
        f"ms (camera packet received -> speed command written)\n"
        f"  figure  {run_dir / 'control.png'} (A/L, f and speed against time, with the set-point)\n"
        f"  law     {law}\n"
        f"  log     {run_dir / 'control.jsonl'}\n"
        f"  about   {run_dir / 'README.txt'} (what each file is; run.json for programs)",
        file=sys.stderr,
    )
    if args.json:
        print(json.dumps({**found, "run_dir": str(run_dir), "figure": str(run_dir / "control.png")}))
    return result.code or (0 if reason == "finished" else 1)
