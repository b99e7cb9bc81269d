"""``flagtrack geometry``: the flag's root, rest direction and length from a short recording of it."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

COMMAND = "geometry"
HELP = "find the flag's root, rest direction and length from a short recording of it moving"
DESCRIPTION = """\
Find the flag's root, rest direction and length from a few seconds of it flapping (or tapped by
hand), in pixels or, with --calibration, the plane's units; prints the `flagtrack reconstruct`
options that use them, and -o writes the `tracker:` section. See docs/commands.md and
docs/first-day.md.
"""

DEFAULT_MAX_EVENTS = 4_000_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack geometry``."""
    parser.add_argument("file", type=Path, help="event file of the flag moving (.raw, .dat, .aedat4, .npy, .csv)")
    parser.add_argument(
        "--calibration", type=Path, metavar="CAL.yaml", help="pixel -> plane calibration: results in its units"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("-o", "--output", type=Path, metavar="TRACKER.yaml", help="write the `tracker:` section here")
    parser.add_argument(
        "--seconds", type=float, metavar="S", help="use the first S seconds (default: all, up to 4 M events)"
    )


def run(args: argparse.Namespace) -> int:
    """Find the geometry of the flag in ``args.file``; print it and write ``args.output``."""
    from flagtrack.daemon.core.geometry import NoFlagError, find_geometry
    from flagtrack.daemon.errors import ConfigError

    if args.seconds is not None and not args.seconds > 0:
        raise ConfigError(f"must be positive, got {args.seconds}", key="--seconds")
    if args.output is not None:
        from flagtrack.daemon.commands._outputs import check_output, only_yaml_sections

        inputs = (args.file, args.calibration)
        check_output(args.output, "-o", inputs, replaceable=only_yaml_sections("tracker"), holds="a tracker: section")
    mapping, units = _mapping(args.calibration)
    events, size = _read(args.file, args.seconds)
    if mapping is not None:
        from flagtrack.daemon.tracking.setup import calibration_misfit

        misfit = calibration_misfit(mapping, *size, str(args.file))
        if misfit is not None:
            raise ConfigError(f"{args.calibration}: {misfit}", key="--calibration")
    try:
        found = find_geometry(events, size, mapping)
    except NoFlagError as exc:
        print(f"flagtrack geometry: {args.file}: no flag found: {exc}", file=sys.stderr)
        return 2
    result = as_json(found, units)
    if args.output is not None:
        write_tracker_section(args.output, found, args.calibration)
    if args.json:
        print(json.dumps({**result, "recording": str(args.file), "tracker_yaml": _str(args.output)}))
    else:
        print(_plain(args.file, found, units, args.calibration, args.output))
    return 0


def _mapping(calibration: Path | None) -> tuple[Any, str]:
    if calibration is None:
        return None, "px"
    from flagtrack.calibration.calfile import load_mapping

    mapping = load_mapping(calibration)
    return mapping, str(getattr(mapping, "units", "m"))


def _read(path: Path, seconds: float | None) -> tuple[Any, tuple[int, int]]:
    """The first events of ``path`` (``seconds`` of them, at most DEFAULT_MAX_EVENTS) and the sensor size."""
    import numpy as np

    from flagtrack.drivers.formats import open_events

    parts: list[Any] = []
    n = 0
    with open_events(path) as reader:
        size = (reader.info.width or 0, reader.info.height or 0)
        for chunk in reader:
            events = chunk.events
            if seconds is not None and len(events):
                first = parts[0]["t"][0] if parts else events["t"][0]
                events = events[events["t"] < first + seconds * 1e6]
            parts.append(events[: DEFAULT_MAX_EVENTS - n])
            n += len(parts[-1])
            if n >= DEFAULT_MAX_EVENTS or len(events) < len(chunk.events):
                break
    events = np.concatenate(parts) if parts else np.empty(0, dtype=_event_dtype())
    return events, size


def _event_dtype() -> Any:
    from flagtrack.daemon.core.events import EVENT_DTYPE

    return EVENT_DTYPE


def _round(value: float) -> float:
    """Six significant digits (pixels to 1e-3 or better, metres to a micrometre or better)."""
    return float(f"{value:.6g}")


def as_json(found: Any, units: str) -> dict[str, Any]:
    """The JSON object of ``flagtrack geometry --json`` (the recording and output paths aside)."""
    return {
        "root": [_round(found.root[0]), _round(found.root[1])],
        "direction_deg": _round(found.direction_deg),
        "length": _round(found.length),
        "units": units,
        "root_gap": _round(found.root_gap),
        "length_spread": _round(found.length_spread),
        "direction_se_deg": _round(found.direction_se_deg),
        "amplitude": _round(found.amplitude),
        "frequency_hz": _round(found.frequency_hz),
        "periods": _round(found.periods),
        "events_used": found.events_used,
        "hot_pixels": [list(p) for p in found.hot_pixels],
        "at_edge": found.at_edge,
        "warnings": found.warnings(),
    }


def write_tracker_section(path: Path, found: Any, calibration: Path | None) -> None:
    """Write the ``tracker:`` section (root, length, direction_deg, calibration) and check that the
    tracker's own loader accepts it."""
    import yaml

    from flagtrack.daemon.tracking.setup import load_tracking_config_file, tracking_setup

    section: dict[str, Any] = {
        "root": [_round(found.root[0]), _round(found.root[1])],
        "length": _round(found.length),
        "direction_deg": _round(found.direction_deg),
    }
    if calibration is not None:
        section["calibration"] = _relative(calibration, path.parent)
    header = "# the flag's geometry, found by flagtrack geometry\n"
    path.write_text(header + yaml.safe_dump({"tracker": section}, sort_keys=False, default_flow_style=None))
    tracking_setup(load_tracking_config_file(path), path=str(path))


def _relative(target: Path, base: Path) -> str:
    """``target`` as the config's loader will find it from ``base`` (relative where it can be)."""
    import os

    try:
        return os.path.relpath(target.resolve(), base.resolve())
    except ValueError:  # another drive
        return str(target.resolve())


def _str(path: Path | None) -> str | None:
    return None if path is None else str(path)


def _plain(path: Path, found: Any, units: str, calibration: Path | None, output: Path | None) -> str:
    """A few lines a person reads, and the reconstruct options to use."""
    ratio = found.amplitude / found.length if found.length > 0 else math.nan
    motion = f"{found.frequency_hz:.1f} Hz over {found.periods:.1f} periods"
    lines = [
        f"flag in {path} ({units}):",
        f"  root       ({found.root[0]:.6g}, {found.root[1]:.6g})",
        f"  direction  {found.direction_deg:.2f} deg (from +x towards +y)",
        f"  length     {found.length:.6g}",
        f"  motion     {motion}, tip peak-to-peak {found.amplitude:.4g} (2A/L {ratio:.2f})",
    ]
    if found.hot_pixels:
        lines.append(f"  ignored    {len(found.hot_pixels)} hot pixel(s)")
    lines += [f"  unsure:    {w}" for w in found.warnings()]
    cal = f" --calibration {calibration}" if calibration is not None else ""
    lines.append("track it with:")
    if output is not None:
        lines.append(f"  flagtrack reconstruct RUN.raw -o RUN.h5 -c {output}")
    lines.append(
        f"  flagtrack reconstruct RUN.raw -o RUN.h5 --root {found.root[0]:.6g} {found.root[1]:.6g} "
        f"--length {found.length:.6g} --direction {found.direction_deg:.6g}{cal}"
    )
    return "\n".join(lines)
