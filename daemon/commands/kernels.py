"""``flagtrack kernels``: build the compiled kernels ahead of time (a fast start), or show the build."""

from __future__ import annotations

import argparse
import json
import sys

COMMAND = "kernels"
HELP = "compile the tracking and codec kernels ahead of time (fast start), or show the build"
DESCRIPTION = """\
Every command that decodes or tracks runs numba-compiled kernels. Without a build, each process
imports numba and loads its cached kernels (~0.5 s of start-up); with one, the kernels load as a
plain extension module. `build` compiles them for this machine's CPU (about a minute, once per
install or upgrade) into $FLAGTRACK_KERNEL_CACHE (default ~/.cache/flagtrack/kernels). A build
whose sources differ from the installed ones is not used. FLAGTRACK_KERNELS=numba ignores builds.

  flagtrack kernels build
  flagtrack kernels status [--json]
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
