"""``flagtrack batch reconstruct|validate``: many recordings or sweep runs at once, on this machine's cores
or on a Dask cluster; idempotent and resumable (docs/batch.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from flagtrack.daemon.commands._tracking_args import add_tracking_arguments

COMMAND = "batch"
HELP = "reconstruct many recordings, or revalidate many sweep runs, on local cores or a Dask cluster"
DESCRIPTION = """\
Process a campaign on this machine's cores (--jobs N) or on Dask (--scheduler local:N or
tcp://HOST:8786): `batch reconstruct` writes every recording's centreline file, `batch validate`
redoes every sweep run's sensor comparison. A rerun skips what is up to date and resumes an
interrupted batch. Exit status: 0 done, 1 some input failed, 2 bad options, 130 interrupted.
More: docs/batch.md, docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``reconstruct`` and ``validate`` actions."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    rec = actions.add_parser(
        "reconstruct",
        help="centrelines of many recordings, one OUT_DIR/<stem>_centrelines.h5 each",
        description=_RECONSTRUCT,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    rec.add_argument(
        "inputs",
        nargs="+",
        metavar="INPUT",
        help="recording, folder of recordings (.raw .dat .aedat4 .npy .csv inside it) or glob pattern ('**' recurses)",
    )
    rec.add_argument("-o", "--out-dir", type=Path, required=True, help="output folder (created)")
    rec.add_argument("-c", "--config", type=Path, help="YAML config with a `tracker:` section")
    add_tracking_arguments(rec)
    rec.add_argument(
        "--strict", action="store_true", help="a damaged recording fails (default: its corrupt stretches are skipped)"
    )
    _common(rec)
    val = actions.add_parser(
        "validate",
        help="sweep runs revalidated as `flagtrack validate --reconstruct` does, points spread over workers",
        description=_VALIDATE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    val.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="sweep run folder (or a glob pattern of them)")
    val.add_argument(
        "-o", "--out-dir", type=Path, help="folder for batch.csv, batch.json, campaign.png (default: the runs' parent)"
    )
    val.add_argument(
        "-c", "--config", type=Path, help="a YAML file whose tracker: section is used (default: the run's)"
    )
    add_tracking_arguments(val)
    _common(val)


_RECONSTRUCT = """\
One centreline file per recording, OUT_DIR/<stem>_centrelines.h5, as `flagtrack reconstruct` writes
it (with the batch's stamps); OUT_DIR gets batch.csv and batch.json. Exit status as `flagtrack batch`.
More: docs/batch.md, docs/commands.md.
"""

_VALIDATE = """\
For each RUN_DIR, what `flagtrack validate RUN_DIR --reconstruct` does, the points of every run spread
over the workers; OUT_DIR gets batch.csv, batch.json and campaign.png. Exit status as `flagtrack batch`.
More: docs/batch.md, docs/commands.md.
"""


def _common(parser: argparse.ArgumentParser) -> None:
    where = parser.add_mutually_exclusive_group()
    where.add_argument("-j", "--jobs", type=int, metavar="N", help="local worker processes (default: every core)")
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="Dask: local:N (a LocalCluster of N single-threaded worker processes here) or tcp://HOST:PORT",
    )
    parser.add_argument("--force", action="store_true", help="redo every input, even those up to date")
    parser.add_argument(
        "--checksum", action="store_true", help="compare the inputs' content digests even where size and time match"
    )
    parser.add_argument("--no-progress", action="store_true", help="plain lines even on a terminal")
    parser.add_argument("--json", action="store_true", help="print one JSON object of the results on stdout")


def run(args: argparse.Namespace) -> int:
    """Run the chosen action; 1 if any input failed."""
    return {"reconstruct": _reconstruct, "validate": _validate}[args.action](args)


def _executor_factory(args: argparse.Namespace) -> Any:
    """The executor factory of ``--jobs`` / ``--scheduler`` (Dask's presence checked now, before any work)."""
    from flagtrack.daemon.batch.executor import executor_spec, import_dask, open_executor

    spec = executor_spec(args.jobs, args.scheduler)
    if spec.kind != "pool":
        import_dask()
    return lambda tasks: open_executor(spec, tasks)


def _resolve_paths(args: argparse.Namespace) -> None:
    for name in ("config", "calibration", "out_dir"):
        if getattr(args, name, None) is not None:
            setattr(args, name, getattr(args, name).expanduser().resolve())


def _reconstruct(args: argparse.Namespace) -> int:
    from flagtrack.daemon.batch.campaign import jobs_for, reconstruct_campaign
    from flagtrack.daemon.batch.inputs import expand_inputs, output_paths
    from flagtrack.daemon.batch.rows import CSV_NAME
    from flagtrack.daemon.commands._tracking_args import apply_tracking_arguments
    from flagtrack.daemon.tracking.section import TrackingConfig
    from flagtrack.daemon.tracking.setup import load_tracking_config_file, tracking_setup

    _resolve_paths(args)
    factory = _executor_factory(args)
    config = load_tracking_config_file(args.config) if args.config else TrackingConfig()
    setup = tracking_setup(apply_tracking_arguments(config, args), path=str(args.config) if args.config else None)
    inputs = expand_inputs(args.inputs, exclude={args.out_dir / CSV_NAME})
    jobs = jobs_for(inputs, output_paths(args.out_dir, inputs))
    result = reconstruct_campaign(
        jobs, args.out_dir, setup, factory, force=args.force, checksum=args.checksum, bar=_bar(args), strict=args.strict
    )
    return _finish(args, result, "inputs")


def _validate(args: argparse.Namespace) -> int:
    import os

    from flagtrack.daemon.batch.campaign import plan_run, validate_campaign
    from flagtrack.daemon.commands._tracking_args import apply_tracking_arguments
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.tracking.setup import load_tracking_config_file, tracking_setup
    from flagtrack.daemon.validation.run import run_tracking_config

    _resolve_paths(args)
    factory = _executor_factory(args)
    runs = _run_dirs(args.run_dirs)
    if args.out_dir is None:
        common = Path(os.path.commonpath([str(r.parent) for r in runs]))
        if common == Path(common.anchor):
            raise ConfigError("the runs have no common parent folder: give one with -o", key="-o")
        args.out_dir = common
    if args.config is not None:
        load_tracking_config_file(args.config)  # a bad file is one line before anything runs

    def setup_for(record: Any) -> Any:  # the set-up `flagtrack validate RUN --reconstruct [-c] [flags]` uses
        config, where = run_tracking_config(record, args.config)
        return tracking_setup(apply_tracking_arguments(config, args), path=where)

    plans = [plan_run(run, setup_for) for run in runs]
    result = validate_campaign(plans, args.out_dir, factory, force=args.force, checksum=args.checksum, bar=_bar(args))
    return _finish(args, result, "runs")


def _run_dirs(items: list[str]) -> list[Path]:
    """The run folders named (resolved, each once; a glob pattern gives the run folders it matches).

    Raises:
        ConfigError: a folder without a run log, or a pattern matching none.
    """
    import glob

    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.sweep.runlog import RUN_LOG

    runs: dict[Path, None] = {}
    for item in items:
        if set("*?[") & set(item):
            matches = [Path(m).resolve() for m in sorted(glob.glob(str(Path(item).expanduser()), recursive=True))]
            found = [m for m in matches if (m / RUN_LOG).is_file()]
            if not found:
                raise ConfigError(f"the pattern {item!r} matches no run folder (with a {RUN_LOG})", key="RUN_DIR")
        else:
            path = Path(item).expanduser().resolve()
            if not (path / RUN_LOG).is_file():
                raise ConfigError(f"no run log in {path}", key="RUN_DIR")
            found = [path]
        runs.update(dict.fromkeys(found))
    return list(runs)


def _bar(args: argparse.Namespace) -> bool:
    return not args.no_progress and sys.stderr.isatty()


def _finish(args: argparse.Namespace, result: Any, noun: str) -> int:
    counts = result.counts
    events = sum(r.events or 0 for r in result.rows if r.status == "done")
    rate = f", {events / 1e6:.1f} M events at {events / result.seconds / 1e6:.2f} Mev/s" if events else ""
    print(
        f"flagtrack batch: {len(result.rows)} {noun}: {counts['done']} done, {counts['skipped']} skipped (up to date), "
        f"{counts['failed']} failed in {result.seconds:.1f} s{rate} -> {result.csv}",
        file=sys.stderr,
    )
    if args.json:
        print(json.dumps({"command": f"batch {args.action}", **result.summary()}, allow_nan=False))
    return 1 if counts["failed"] else 0
