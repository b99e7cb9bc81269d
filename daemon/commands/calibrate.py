"""``flagtrack calibrate``: pixel -> plane (metres) mapping from a recording of a blinking checkerboard."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

COMMAND = "calibrate"
HELP = "calibrate pixels -> plane metres from a blinking checkerboard recording; map pixel positions"
DESCRIPTION = """\
Calibrate pixels -> plane metres from a recording of a checkerboard blinking in the light-sheet
plane: finds the inner corners, puts the origin at --origin-corner, fits a polynomial of --degree,
writes the calibration YAML and a figure and prints the residuals. `flagtrack calibrate map CAL X Y
...` prints the plane coordinates of pixel positions. More: docs/calibration.md, docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Positional inputs (a recording, or ``map CAL X Y ...``) and the calibration options."""
    parser.add_argument(
        "inputs",
        nargs="+",
        metavar="REC | map CAL X Y",
        help="the recording of the blinking board, or: map CAL.yaml X Y [X Y ...]",
    )
    parser.add_argument("-o", "--output", type=Path, help="calibration file to write (YAML)")
    parser.add_argument("--board", help="inner corners NxM, e.g. 9x6 (a board of 10x7 squares)")
    parser.add_argument("--square-mm", type=float, help="side of one square on the plane, mm")
    parser.add_argument(
        "--origin-corner",
        default="top-left",
        help="corner at (0, 0): top-left, top-right, bottom-left, bottom-right or I,J (default top-left)",
    )
    parser.add_argument(
        "--x-axis",
        choices=("right", "left", "up", "down"),
        default="right",
        help="image direction of plane +x, downstream (default right)",
    )
    parser.add_argument(
        "--y-axis",
        choices=("right", "left", "up", "down"),
        help="image direction of plane +y (default: x turned counter-clockwise on the image)",
    )
    parser.add_argument(
        "--origin-offset-mm",
        type=float,
        nargs=2,
        metavar=("DX", "DY"),
        default=(0.0, 0.0),
        help="plane position of the origin corner relative to the root, mm (default 0 0)",
    )
    parser.add_argument("--degree", type=int, help="total degree of the polynomial (default 3)")
    parser.add_argument("--period-ms", type=float, help="blink period if known, ms (default: detected)")
    parser.add_argument("--min-period-ms", type=float, default=40.0, help="shortest period searched, ms (40)")
    parser.add_argument("--max-period-ms", type=float, default=5000.0, help="longest period searched, ms (5000)")
    parser.add_argument(
        "--max-seconds", type=float, default=10.0, help="use the first S seconds of the recording (default 10)"
    )
    parser.add_argument("--size", type=int, nargs=2, metavar=("W", "H"), help="sensor size if the file lacks it")
    parser.add_argument("--figure", type=Path, help="figure to write (default: OUTPUT with .png)")
    parser.add_argument("--no-figure", action="store_true", help="write no figure")
    parser.add_argument("--json", action="store_true", help="print JSON (map: a list of [x_m, y_m])")


def run(args: argparse.Namespace) -> int:
    """Calibrate, or map pixel positions with an existing calibration."""
    from flagtrack.daemon.errors import ConfigError

    if args.inputs[0] == "map":
        if len(args.inputs) == 1:  # (it said "calibrating needs --board, --square-mm, -o/--output")
            raise ConfigError(
                "map needs a calibration file and pixel positions: flagtrack calibrate map CAL.yaml X Y ..."
            )
        return _map(args.inputs[1:], args.json)

    if len(args.inputs) != 1:
        raise ConfigError(f"give one recording (or: map CAL.yaml X Y ...), got {' '.join(args.inputs)}")
    missing = [
        flag
        for flag, value in (("--board", args.board), ("--square-mm", args.square_mm), ("-o/--output", args.output))
        if value is None
    ]
    if missing:
        raise ConfigError(f"calibrating needs {', '.join(missing)}")
    return _calibrate(args)


def _parse_setup(args: argparse.Namespace) -> tuple:
    from flagtrack.calibration.fit import DEFAULT_DEGREE, BoardSpec
    from flagtrack.calibration.frame import Direction, GridFrame
    from flagtrack.calibration.pseudo_image import BlinkSearch
    from flagtrack.daemon.errors import ConfigError

    try:
        n, m = (int(v) for v in args.board.lower().split("x"))
    except ValueError as exc:
        raise ConfigError(f"--board must look like 9x6 (inner corners), got {args.board!r}", key="board") from exc
    _check_numbers(args, n, m)
    try:
        board = BoardSpec((n, m), args.square_mm * 1e-3)
        frame = GridFrame(
            args.origin_corner,
            Direction(args.x_axis),
            Direction(args.y_axis) if args.y_axis else None,
            (args.origin_offset_mm[0] * 1e-3, args.origin_offset_mm[1] * 1e-3),
        )
        search = BlinkSearch(
            min_period_us=int(args.min_period_ms * 1e3),
            max_period_us=int(args.max_period_ms * 1e3),
            period_us=args.period_ms * 1e3 if args.period_ms else None,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from exc
    degree = DEFAULT_DEGREE if args.degree is None else args.degree
    if degree < 1:
        raise ConfigError(f"--degree must be >= 1, got {degree}", key="degree")
    return board, frame, search, degree


_MAX_CORNERS = 100  # a side of the board, inner corners


def _check_numbers(args: argparse.Namespace, n: int, m: int) -> None:
    """Each number of the calibration's options in its range, named (before any work)."""
    from flagtrack.daemon.core.events import MAX_SENSOR_PX
    from flagtrack.daemon.errors import ConfigError

    if not (2 <= n <= _MAX_CORNERS and 2 <= m <= _MAX_CORNERS):
        raise ConfigError(f"--board: 2 to {_MAX_CORNERS} inner corners a side, got {args.board}")
    positive = {
        "--square-mm": args.square_mm,
        "--max-seconds": args.max_seconds,
        "--min-period-ms": args.min_period_ms,
        "--max-period-ms": args.max_period_ms,
        "--period-ms": args.period_ms,
    }
    for option, value in positive.items():
        if value is not None and not (math.isfinite(value) and 0 < value <= 1e6):
            raise ConfigError(f"{option}: must be a positive number up to 1e6, got {value}")
    if not all(math.isfinite(v) and abs(v) <= 1e6 for v in args.origin_offset_mm):
        raise ConfigError(f"--origin-offset-mm: must be two numbers up to 1e6 mm, got {args.origin_offset_mm}")
    if args.size is not None and not all(0 < v <= MAX_SENSOR_PX for v in args.size):
        raise ConfigError(f"--size: 1 to {MAX_SENSOR_PX} pixels a side, got {args.size[0]} {args.size[1]}")


def _check_outputs(recording: Path, output: Path, figure: Path | None) -> None:
    """Refuse, before any work, outputs that cannot be written or would replace the recording, each
    other, or a file that is not an earlier calibration (a rig config given as ``-o``)."""
    from flagtrack.calibration.calfile import FORMAT
    from flagtrack.daemon.commands._outputs import check_output, check_picture, yaml_file_where
    from flagtrack.daemon.errors import ConfigError

    is_calibration = yaml_file_where(lambda data: isinstance(data, dict) and data.get("format") == FORMAT)
    check_output(output, "-o", (recording,), replaceable=is_calibration, holds="a calibration")
    if figure is not None:
        if figure.resolve() == output.resolve():
            raise ConfigError(f"--figure {figure}: is the calibration's own file (-o)")
        check_picture(figure, "--figure", (recording, output))


def _calibrate(args: argparse.Namespace) -> int:
    from flagtrack.calibration.calfile import save_calibration
    from flagtrack.calibration.corners import detect_corners
    from flagtrack.calibration.errors import CalibrationError
    from flagtrack.calibration.fit import Calibration, calibrate_corners
    from flagtrack.calibration.pseudo_image import detect_blink, pseudo_image
    from flagtrack.calibration.report import report_lines, save_figure, save_image
    from flagtrack.drivers.formats.excerpt import read_excerpt

    board, frame, search, degree = _parse_setup(args)
    path = Path(args.inputs[0])
    figure = None if args.no_figure else (args.figure or args.output.with_suffix(".png"))
    _check_outputs(path, args.output, figure)
    events, size = read_excerpt(path, args.max_seconds, tuple(args.size) if args.size else None)
    try:
        timing = detect_blink(events["t"], events["p"], search)
    except CalibrationError as exc:
        raise CalibrationError(str(exc), path=str(path)) from None
    image = pseudo_image(events, size[0], size[1], timing)
    try:
        grid = detect_corners(image, board.inner_corners)
        cal = calibrate_corners(grid, board, frame, degree, size)
    except CalibrationError as exc:
        hint = ""
        if figure is not None:
            save_image(figure, image)
            hint = f" (pseudo-image: {figure})"
        raise CalibrationError(f"{exc}{hint}", path=str(path)) from None
    cal = Calibration(**{**cal.__dict__, "blink": timing.to_attrs(), "source": str(path)})
    save_calibration(cal, args.output)
    if figure is not None:
        save_figure(figure, image, cal)
    if args.json:
        print(
            json.dumps(
                {
                    "output": str(args.output),
                    "figure": str(figure) if figure else None,
                    "residuals": cal.residuals.to_mapping(),
                    "blink": cal.blink,
                }
            )
        )
    else:
        for line in report_lines(cal):
            print(line)
        print(f"-> {args.output}" + (f", {figure}" if figure else ""))
    return 0


def _map(values: list[str], as_json: bool) -> int:
    import numpy as np

    from flagtrack.calibration import load_mapping
    from flagtrack.daemon.errors import ConfigError

    cal_path, coords = values[0], values[1:]
    if not coords or len(coords) % 2:
        raise ConfigError(
            f"map needs pixel positions as X Y pairs after the calibration file, got {len(coords)} numbers"
        )
    try:
        xy = np.array([float(v) for v in coords]).reshape(-1, 2)
    except ValueError as exc:
        raise ConfigError(f"map: not a number in {' '.join(coords)}") from exc
    if not np.isfinite(xy).all():  # (it printed "nan nan m")
        raise ConfigError(f"map: pixel positions must be finite, got {' '.join(coords)}")
    mapping = load_mapping(cal_path)
    x_m, y_m = mapping.map(xy[:, 0], xy[:, 1])
    if as_json:
        print(json.dumps([[float(a), float(b)] for a, b in zip(x_m, y_m, strict=True)]))
        return 0
    for (u, v), a, b in zip(xy, x_m, y_m, strict=True):
        sys.stdout.write(f"{u:g} {v:g} -> {a:.6f} {b:.6f} m\n")
    return 0
