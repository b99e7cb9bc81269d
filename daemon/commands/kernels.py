"""``flagtrack kernels``: build the compiled kernels ahead of time (a fast start), or show the build."""

from __future__ import annotations

import argparse
import json
import sys

COMMAND = "kernels"
HELP = "compile the tracking and codec kernels ahead of time (fast start), or show the build"
DESCRIPTION = """\
Compile the numba kernels of decoding and tracking for this machine ahead of time (`build`, about a
minute), so that each command loads them at once instead of ~0.5 s; `status` shows the build.
More: docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack kernels``."""
    parser.add_argument("action", choices=("build", "status"), help="build the kernels, or show the build")
    parser.add_argument("--json", action="store_true", help="status as JSON")


def run(args: argparse.Namespace) -> int:
    """Build or describe the ahead-of-time kernels."""
    from flagtrack.daemon.aot import cache

    if args.action == "build":
        from flagtrack.daemon.aot.build import build

        result = build(progress=lambda msg: print(msg, file=sys.stderr))
        print(
            f"{result.exports} signatures of {result.kernels} kernels in {result.folder} "
            f"(workload {result.workload_s:.1f} s, compile {result.compile_s:.1f} s)"
        )
        return 0
    manifest = cache.read_manifest(cache.build_dir())
    status = {
        "folder": str(cache.build_dir()),
        "usable": manifest is not None,
        "exports": len(manifest["exports"]) if manifest else 0,
    }
    if args.json:
        print(json.dumps(status))
    else:
        state = f"usable, {status['exports']} signatures" if manifest else "none or stale (numba compiles the kernels)"
        print(f"{status['folder']}: {state}")
    return 0
