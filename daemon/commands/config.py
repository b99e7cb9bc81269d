"""``flagtrack config check RIG.yaml``: a whole rig config checked, opening no device, and what it would run."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flagtrack.daemon.rig.report import RigReport

COMMAND = "config"
HELP = "check a rig config before the hardware is there: keys, values, files, tunnel bounds, sweep plan"
DESCRIPTION = """\
Check a whole rig config without opening any device: its keys, types and ranges, the files it names
(calibration, replay recording, certificates of a secured bus) and the folders it writes, the sweep
plan against the tunnel's bounds. Prints what would run (services, camera, tunnel, the plan's points,
duration and disk) and notes on what this host still lacks (a calibration not made yet, a device not
plugged in, an SDK not installed): exit 0. A mistake is one line naming the key and the file: exit 2.
Example: flagtrack config check deploy/rig-single-pc.yaml. More: docs/first-day.md, docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``check`` action and its options."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    check = actions.add_parser(
        "check",
        help="check a rig config and say what it would run",
        description="Check a whole rig config (or a part of one) without opening any device and say what it "
        "would run; what this host still lacks is listed under 'to do:' (docs/commands.md, docs/first-day.md).",
    )
    check.add_argument("config", type=Path, metavar="RIG.yaml", help="the rig config (or a part of one)")
    check.add_argument(
        "--services",
        metavar="S1,S2",
        help="the services this host runs (default: the file's, and the supervisor when it has a sweep plan)",
    )
    check.add_argument(
        "--no-files",
        action="store_true",
        help="check what the file says only, not this host's files, folders, ports and SDKs (a config for another host)",
    )
    check.add_argument("--strict", action="store_true", help="what this host lacks is an error too (exit 2)")
    check.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    """Check the file; print the summary and the notes."""
    from flagtrack.daemon.rig.report import check_rig_file

    services = [name.strip() for name in args.services.split(",") if name.strip()] if args.services else None
    report = check_rig_file(args.config, services=services, files=not args.no_files, strict=args.strict)
    print(json.dumps(report_json(report), indent=1) if args.json else report_text(report))
    return 0


def report_text(report: RigReport) -> str:
    """The summary for people: the verdict, what runs, one line per part, the notes."""
    what = "a rig" if report.kind == "rig" else "a part of a rig"
    looked = "" if report.files else "; this host's files, folders, ports and SDKs not looked at (--no-files)"
    lines = [f"{report.path}: {what}, checked without opening any device{looked}"]
    lines += [f"  {'runs' if i == 0 else '':10s} {text}" for i, text in enumerate(report.runs)]
    lines += [f"  {name:10s} {text}" for name, text in report.lines]
    lines += [f"{'to do' if note.pending else 'warning'}: {note}" for note in report.notes]
    return "\n".join(lines)


def report_json(report: RigReport) -> dict[str, Any]:
    """The summary for programs."""
    plan = report.plan
    return {
        "path": report.path,
        "kind": report.kind,
        "services": list(report.services),
        "runs": list(report.runs),
        "lines": dict(report.lines),
        "plan": None
        if plan is None
        else {
            "points": plan.points,
            "lowest_mps": plan.lowest_mps,
            "highest_mps": plan.highest_mps,
            "branches": list(plan.branches),
            "duration_s": round(plan.duration_s, 1),
            "disk_bytes": round(plan.disk_bytes),
        },
        "notes": [{"key": n.key, "text": n.text, "pending": n.pending} for n in report.notes],
        "files_checked": report.files,
    }
