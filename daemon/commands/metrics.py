"""``flagtrack metrics compare RECON.h5 TRUTH.h5``: accuracy of a reconstruction against the truth."""

from __future__ import annotations

import argparse
import json

COMMAND = "metrics"
HELP = "accuracy metrics of centreline files (compare a reconstruction with the ground truth)"
DESCRIPTION = """\
flagtrack metrics compare RECON.h5 TRUTH.h5 [--json]

Compares two centreline files (DESIGN.md HDF5 layout) on their common time span: the truth is
interpolated at the reconstruction's times and arc lengths. Prints, in this order:
  delta_rms_over_l     RMS tip distance / L
  max_eps_rms_over_l   maximum over time of the RMS distance along the arc length / L
  twi                  travelling-wave index of the reconstruction (complex orthogonal decomposition)
  twi_ref              travelling-wave index of the truth on the same times
then twi_abs_error, n_common, t_start_s, t_stop_s, length. L is the truth's `length` attribute
(else its arc-length span).
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``compare`` is the only action for now."""
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    compare = sub.add_parser("compare", help="compare RECON.h5 with TRUTH.h5")
    compare.add_argument("recon", help="reconstructed centreline file")
    compare.add_argument("truth", help="ground-truth centreline file")
    compare.add_argument("--json", action="store_true", help="print one JSON object")
    compare.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Print the comparison of ``args.recon`` with ``args.truth``."""
    from flagtrack.daemon.core.metrics import compare
    from flagtrack.daemon.errors import FormatError
    from flagtrack.drivers.formats.centreline import read_centrelines

    recon, _ = read_centrelines(args.recon)
    truth, truth_attrs = read_centrelines(args.truth)
    length = truth_attrs.get("length")
    try:
        result = compare(recon, truth, float(length) if length is not None else None)
    except ValueError as exc:
        raise FormatError(f"cannot compare with {args.truth}: {exc}", path=args.recon) from exc
    values = {
        "delta_rms_over_l": result.delta_rms_over_l,
        "max_eps_rms_over_l": result.max_eps_rms_over_l,
        "twi": result.twi,
        "twi_ref": result.twi_ref,
        "twi_abs_error": result.twi_abs_error,
        "n_common": result.n_common,
        "t_start_s": result.t_start_s,
        "t_stop_s": result.t_stop_s,
        "length": result.length,
    }
    if args.json:
        print(json.dumps(values))
    else:
        for key, value in values.items():
            print(f"{key:20s} {value:.6g}" if isinstance(value, float) else f"{key:20s} {value}")
    return 0
