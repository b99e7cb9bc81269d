"""``flagtrack events info|convert``: inspect and convert event files.

Formats by extension: .raw (Prophesee EVT 2.0 / 2.1 / 3.0), .dat, .aedat4, .npy, .csv (t,x,y,p).
``convert`` writes .raw (EVT 2.0 or 3.0), .npy, .csv or .dat, streaming in bounded memory.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flagtrack.drivers.formats.reader import EventChunk

COMMAND = "events"
HELP = "inspect (info) and convert event files: .raw EVT 2.0/2.1/3.0, .dat, .aedat4, .npy, .csv"
DESCRIPTION = __doc__
INFO_KEYS = ("format", "encoding", "width", "height", "events", "on", "off", "t_first_us", "t_last_us")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``info`` and ``convert`` actions."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    info = actions.add_parser(
        "info",
        help="format, size, event counts and time span of a file",
        description="Read an event file through and print its format, sensor size, event counts and time "
        "span (docs/formats.md).",
    )
    info.add_argument("file", type=Path, help="the event file")
    info.add_argument("--json", action="store_true", help="print one JSON object")
    convert = actions.add_parser(
        "convert",
        help="convert between formats (chosen by the extensions)",
        description="Stream an event file into another format, chosen by the output's extension (.raw EVT "
        "2.0/3.0, .dat, .npy, .csv); an existing output is refused, never replaced (docs/formats.md).",
    )
    convert.add_argument("input", type=Path, help="the event file to read")
    convert.add_argument("output", type=Path, help="the file to write (a new one)")
    convert.add_argument(
        "--encoding",
        choices=("evt2", "evt3"),
        help="EVT encoding of a .raw output (default: the input's if it is EVT 2.0/3.0, else evt3)",
    )
    convert.add_argument("--width", type=int, help="sensor width, when the input does not give it")
    convert.add_argument("--height", type=int, help="sensor height, when the input does not give it")
    for sub in (info, convert):
        sub.add_argument(
            "--strict", action="store_true", help="fail on a fault instead of keeping the events before it and warning"
        )
        sub.add_argument("--no-progress", action="store_true", help="no progress bar")


def _progress(total: int, description: str, disabled: bool):  # noqa: ANN202
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=description,
        unit="B",
        unit_scale=True,
        file=sys.stderr,
        leave=False,
        disable=disabled or not sys.stderr.isatty(),
    )


def _refuse_beyond_any_sensor(chunk: EventChunk, path: Path) -> None:
    """A pixel no sensor has (a random file read as a headerless DAT): the error ``reconstruct`` gives."""
    from flagtrack.daemon.core.events import MAX_SENSOR_PX, beyond_any_sensor
    from flagtrack.daemon.errors import FormatError

    if len(chunk.events):
        x, y = int(chunk.events["x"].max()), int(chunk.events["y"].max())
        if max(x, y) >= MAX_SENSOR_PX:
            raise FormatError(beyond_any_sensor(x, y), path=str(path), offset=chunk.byte_offset)


def file_summary(path: Path, *, strict: bool = False, progress: bool = False) -> dict:
    """The ``events info`` figures of a file, by one streaming pass (bounded memory)."""
    from flagtrack.drivers.formats import open_events

    with open_events(path, strict=strict) as reader, _progress(reader.size_bytes, path.name, not progress) as bar:
        info = reader.info
        events = on = triggers = 0
        t_first = t_last = None
        for chunk in reader:
            _refuse_beyond_any_sensor(chunk, path)
            n = len(chunk.events)
            if n:
                events += n
                on += int(chunk.events["p"].sum(dtype="int64"))
                t_first = int(chunk.events["t"][0]) if t_first is None else t_first
                t_last = int(chunk.events["t"][-1])
            triggers += len(chunk.triggers)
            bar.update(max(chunk.byte_offset - bar.n, 0))
    summary = {
        "format": info.format,
        "encoding": info.encoding,
        "width": info.width,
        "height": info.height,
        "events": events,
        "on": on,
        "off": events - on,
        "t_first_us": t_first,
        "t_last_us": t_last,
    }
    return {**summary, "triggers": triggers, "path": str(info.path)}


def run_info(args: argparse.Namespace) -> int:
    """Print the summary of one file."""
    summary = file_summary(args.file, strict=args.strict, progress=not args.no_progress)
    if args.json:
        print(json.dumps({key: summary[key] for key in INFO_KEYS}))
    else:
        for key in ("path", *INFO_KEYS, "triggers"):
            print(f"{key:11} {summary[key] if summary[key] is not None else '-'}")
    return 0


def run_convert(args: argparse.Namespace) -> int:
    """Stream ``input`` into ``output``."""
    from flagtrack.daemon.errors import ConfigError, FormatError
    from flagtrack.drivers.formats import file_format, open_events, open_writer

    if args.input.resolve() == args.output.resolve():
        raise FormatError("input and output are the same file", path=str(args.input))
    if os.path.lexists(args.output):  # (a recording made before, most likely; a link too: what it names)
        raise ConfigError(f"{args.output}: exists (it is left as is: give a new name, or delete it first)")
    out_kind = file_format(args.output, sniff=False)
    with open_events(args.input, strict=args.strict) as reader:
        info = reader.info
        width = args.width if args.width is not None else info.width
        height = args.height if args.height is not None else info.height
        encoding = None
        if out_kind == "raw":
            encoding = args.encoding or (info.encoding if info.encoding in ("evt2", "evt3") else "evt3")
            if width is None or height is None:
                raise FormatError(
                    "the input does not give the sensor size; pass --width and --height", path=str(args.input)
                )
        elif args.encoding:
            raise FormatError("--encoding applies to .raw outputs only", path=str(args.output))
        count = 0
        try:
            with (
                open_writer(args.output, width=width, height=height, encoding=encoding) as writer,
                _progress(reader.size_bytes, args.input.name, args.no_progress) as bar,
            ):
                for chunk in reader:
                    _refuse_beyond_any_sensor(chunk, args.input)
                    writer.write(chunk.events, chunk.triggers)
                    count += len(chunk.events)
                    bar.update(max(chunk.byte_offset - bar.n, 0))
        except BaseException:  # (Ctrl-C too) the part written is no file to keep: it would block a new try
            args.output.unlink(missing_ok=True)  # (a file this command made: nothing was there, above)
            raise
    print(f"{args.output}: {count} events", file=sys.stderr)
    return 0


def run(args: argparse.Namespace) -> int:
    """Run the chosen action; non-strict faults print as warnings (every one: none is deduplicated)."""
    action = run_info if args.action == "info" else run_convert
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        return action(args)
