"""``flagtrack metrics compare RECON.h5 TRUTH.h5``: accuracy of a reconstruction against the truth."""

from __future__ import annotations

import argparse
import json
import math
import sys

COMMAND = "metrics"
HELP = "accuracy metrics of centreline files (compare a reconstruction with the ground truth)"
DESCRIPTION = """\
`flagtrack metrics compare RECON.h5 TRUTH.h5`: the accuracy of a reconstruction against the truth on
their common time span (tip distance, arc-length distance, travelling-wave index, joint and
event-cloud distances, over L; % of L in the text, fractions in --json). More: docs/simulator.md,
docs/commands.md.
"""

#: The datasets of the truth each optional metric reads.
NEEDS = {"joint_rms_over_l": ("joints/x", "joints/y"), "cloud_distance_rms_ref_over_l": ("delta_rms",)}

#: Keys of the output before the tip error and the event-cloud distance got names of their own (old ->
#: new; the old are also the names of ``core.metrics.Comparison``); ``--json`` still gives them, with the
#: same values, for the programs that read them.
ALIASES = {
    "delta_rms_over_l": "tip_error_rms_over_l",
    "cloud_rms_over_l": "cloud_distance_rms_over_l",
    "cloud_rms_ref_over_l": "cloud_distance_rms_ref_over_l",
}

#: What each figure is, for the text output (a person reads percentages of L there).
MEANINGS = {
    "tip_error_rms_over_l": "RMS over time of the tip distance delta (the paper's delta)",
    "max_eps_rms_over_l": "maximum over time of the RMS distance along the arc length (eps_RMS)",
    "twi": "travelling-wave index of the reconstruction",
    "twi_ref": "travelling-wave index of the truth on the same times",
    "twi_abs_error": "|twi - twi_ref|",
    "n_common": "updates compared",
    "joint_rms_over_l": "RMS distance of the chain joints to the truth's",
    "cloud_distance_rms_over_l": "RMS over time of the reconstruction's event-cloud distance Delta_RMS",
    "cloud_distance_rms_ref_over_l": "the same of the truth (its /delta_rms)",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``compare`` is the only action for now."""
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    compare = sub.add_parser(
        "compare",
        help="compare RECON.h5 with TRUTH.h5",
        description="Compare a reconstructed centreline file with a ground truth (a simulated recording's) and "
        "print the errors between them (docs/simulator.md).",
    )
    compare.add_argument("recon", help="reconstructed centreline file")
    compare.add_argument("truth", help="ground-truth centreline file (at least /t, /s, /x, /y)")
    compare.add_argument("--json", action="store_true", help="print one JSON object")
    compare.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Print the comparison of ``args.recon`` with ``args.truth``."""
    import numpy as np

    from flagtrack.daemon.core.metrics import compare
    from flagtrack.daemon.errors import FormatError
    from flagtrack.drivers.formats.centreline import TRUTH_REQUIRED, read_centrelines, read_truth

    recon, recon_attrs = read_centrelines(args.recon)
    t_s = recon.t_s
    if len(t_s) and not (np.isfinite(t_s).all() and (np.diff(t_s) > 0).all()):  # (compared as if it were)
        raise FormatError("/t is not finite and increasing: not a reconstruction to compare", path=str(args.recon))
    truth, truth_attrs, present = read_truth(args.truth)
    length = truth_attrs.get("length")
    if length is not None and not _positive(length):  # (0 was a ZeroDivisionError, NaN NaN results)
        raise FormatError(
            f"ground truth: attribute 'length' must be a positive number, got {length!r}", path=args.truth
        )
    has_joints, has_delta = "joints/x" in present, "delta_rms" in present
    try:
        result = compare(
            recon,
            truth,
            float(length) if length is not None else None,
            truth_has_joints=has_joints,
            truth_has_delta_rms=has_delta,
        )
    except ValueError as exc:
        raise FormatError(f"cannot compare with {args.truth}: {exc}", path=args.recon) from exc
    used = [*TRUTH_REQUIRED, *(("joints/x", "joints/y") if has_joints else ()), *(("delta_rms",) if has_delta else ())]
    values: dict[str, float | int | None] = {
        "tip_error_rms_over_l": result.delta_rms_over_l,
        "max_eps_rms_over_l": result.max_eps_rms_over_l,
        "twi": result.twi,
        "twi_ref": result.twi_ref,
        "twi_abs_error": result.twi_abs_error,
        "n_common": result.n_common,
        "t_start_s": result.t_start_s,
        "t_stop_s": result.t_stop_s,
        "length": result.length,
        "joint_rms_over_l": result.joint_rms_over_l,
        "cloud_distance_rms_over_l": result.cloud_rms_over_l,
        "cloud_distance_rms_ref_over_l": result.cloud_rms_ref_over_l,
    }
    not_available = {ALIASES.get(name, name): reason for name, reason in result.not_available.items()}
    units = str(truth_attrs.get("units") or recon_attrs.get("units") or "")
    where = "its attribute 'length'" if length is not None else "the span of its /s"
    print(
        f"flagtrack metrics: truth {args.truth}: used {' '.join('/' + name for name in used)}; "
        f"L = {result.length:g} from {where}",
        file=sys.stderr,
    )
    for name, reason in not_available.items():
        values[name] = None
        lacks = [f"/{dataset}" for dataset in NEEDS.get(name, ()) if dataset not in present]
        print(
            f"flagtrack metrics: {name} not available: {reason}" + (f" ({', '.join(lacks)})" if lacks else ""),
            file=sys.stderr,
        )
    if args.json:
        aliases = {old: values[new] for old, new in ALIASES.items()}
        missing = {old: not_available[new] for old, new in ALIASES.items() if new in not_available}
        print(json.dumps({**values, **aliases, "truth_datasets": used, "not_available": {**not_available, **missing},
                          "aliases": ALIASES}))  # fmt: skip
    else:
        for key, value in values.items():
            print(_text_line(key, value, not_available.get(key, ""), units))
    return 0


def _text_line(key: str, value: float | int | None, reason: str, units: str) -> str:
    """``name value`` (a program splits on white space), then for a person: % of L, the unit, what it is."""
    if value is None:
        return f"{key:30s} n/a ({reason})"
    shown = f"{value:.6g}" if isinstance(value, float) else str(value)
    if key.endswith("_over_l") and math.isfinite(value):
        shown += f"  ({100 * value:.3g} % of L)"
    elif key in ("t_start_s", "t_stop_s"):
        shown += " s"
    elif key == "length":
        shown += f" {units}"
    meaning = MEANINGS.get(key)
    return f"{key:30s} {shown}" + (f"  {meaning}" if meaning else "")


def _positive(value: object) -> bool:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
    return math.isfinite(number) and number > 0
