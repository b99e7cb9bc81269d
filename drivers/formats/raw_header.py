"""Prophesee RAW file headers: ``% key value`` text lines before the binary EVT stream.

Current headers end with ``% end``. Older ones have no end line: the header then ends at the
first line that does not start with ``%`` (the binary data may contain the bytes ``\\n%``, so the
scan stops at the first line that does not start with ``%``, never searches for the next one).
The encoding comes from ``% format EVT3;height=720;width=1280`` or the older ``% evt 3.0``; the
size from the format options, ``% geometry 1280x720`` or, failing both, the camera
(:mod:`flagtrack.drivers.formats.geometry`).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from dataclasses import dataclass

from flagtrack.daemon import __version__
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats.geometry import inferred_geometry
from flagtrack.drivers.formats.reader import check_sensor_size

MAX_HEADER_BYTES = 1 << 20
_FORMAT_NAMES = {"EVT2": "evt2", "EVT21": "evt21", "EVT3": "evt3"}
_EVT_VERSIONS = {"2.0": "evt2", "2.1": "evt21", "3.0": "evt3"}
_FORMAT_OUT = {"evt2": "EVT2", "evt21": "EVT21", "evt3": "EVT3"}
_EVT_OUT = {"evt2": "2.0", "evt21": "2.1", "evt3": "3.0"}


MAX_T_OFFSET_US = 1 << 62
"""The largest ``% t_offset_us`` (either sign) a header may give: event times (int64 µs) must still fit after it."""


PROPHESEE_FIELDS = {
    "camera_integrator_name": "Prophesee",
    "integrator_name": "Prophesee",
    "plugin_integrator_name": "Prophesee",
    "plugin_name": "hal_plugin_prophesee",
}
"""Who made the camera and which OpenEB plugin reads it, in the header of a camera's stream."""
SIMULATED_FIELDS = {
    "camera_integrator_name": "flagtrack",
    "integrator_name": "flagtrack",
    "simulator": f"flagtrack {__version__}",
}
"""The same for a stream flagtrack simulated: no camera maker, no plugin."""


@dataclass(frozen=True)
class RawLayout:
    """What a RAW header says about its stream.

    Attributes:
        encoding: ``"evt2"``, ``"evt21"`` or ``"evt3"``.
        endianness: EVT 2.1 layout, ``"little"`` or ``"legacy"``.
        width, height: sensor size, or None if neither the header nor the camera gives it.
        t_offset_us: time offset written by flagtrack's encoder (0 for camera recordings).
    """

    encoding: str
    endianness: str
    width: int | None
    height: int | None
    t_offset_us: int


def parse_header_lines(data: bytes, path: str | None = None) -> tuple[dict[str, str], int, dict[str, int]]:
    """Parse the ``%`` lines at the start of ``data``.

    Returns:
        (fields, body offset, byte offset of each field's line). ``data`` must hold the whole
        header; a line cut by the end of ``data`` is reported as a truncated header.
    """
    fields: dict[str, str] = {}
    offsets: dict[str, int] = {}
    pos = 0
    while pos < len(data) and data[pos] == 0x25:  # '%'
        end = data.find(b"\n", pos, pos + MAX_HEADER_BYTES)
        if end < 0:
            raise FormatError("header line has no end (truncated or garbage header)", path=path, offset=pos)
        raw = data[pos + 1 : end].rstrip(b"\r")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FormatError(
                "garbage header: a '%' line that is not text", path=path, offset=pos + 1 + exc.start
            ) from None
        if any(ord(c) < 32 and c != "\t" for c in text):
            raise FormatError("garbage header: control characters in a '%' line", path=path, offset=pos)
        line_offset, pos = pos, end + 1
        text = text.strip()
        if text == "end":
            break
        key, _, value = text.partition(" ")
        if key:
            fields[key] = value.strip()
            offsets[key] = line_offset
    return fields, pos, offsets


def parse_raw_header(data: bytes) -> tuple[dict[str, str], int]:
    """Parse a RAW header at the start of ``data``; return (fields, byte offset of the body)."""
    fields, body, _ = parse_header_lines(data)
    return fields, body


def _format_options(value: str) -> tuple[str, dict[str, str]]:
    name, *options = value.split(";")
    parsed = {}
    for option in options:
        key, _, val = option.partition("=")
        parsed[key.strip()] = val.strip()
    return name.strip(), parsed


def _int_or_none(value: str | None) -> int | None:
    try:
        return int(value) if value else None
    except ValueError:
        return None


def raw_layout(fields: Mapping[str, str], offsets: Mapping[str, int], path: str | None = None) -> RawLayout:
    """Encoding, EVT 2.1 layout, size and time offset of a parsed RAW header."""
    options: dict[str, str] = {}
    if "format" in fields:
        name, options = _format_options(fields["format"])
        encoding = _FORMAT_NAMES.get(name.upper())
        if encoding is None:
            raise FormatError(f"unknown encoding {name!r} in '% format'", path=path, offset=offsets.get("format"))
    elif "evt" in fields:
        encoding = _EVT_VERSIONS.get(fields["evt"])
        if encoding is None:
            raise FormatError(f"unknown encoding 'evt {fields['evt']}'", path=path, offset=offsets.get("evt"))
    else:
        raise FormatError("no encoding in the header (neither '% format' nor '% evt')", path=path, offset=0)
    width, height = _int_or_none(options.get("width")), _int_or_none(options.get("height"))
    if (width is None or height is None) and "geometry" in fields:
        w, _, h = fields["geometry"].partition("x")
        width, height = _int_or_none(w), _int_or_none(h)
    if width is None or height is None:
        width, height = inferred_geometry(fields) or (None, None)
    if width is not None and height is not None:
        check_sensor_size(width, height, path=path, offset=offsets.get("format", offsets.get("geometry")))
    endianness = options.get("endianness") or fields.get("endianness") or ""
    if not endianness:
        system_id = _int_or_none(fields.get("system_ID"))
        prophesee = (fields.get("camera_integrator_name") or fields.get("integrator_name")) == "Prophesee"
        endianness = "legacy" if encoding == "evt21" and prophesee and system_id and system_id < 0x37 else "little"
    if endianness not in ("little", "legacy"):
        raise FormatError(f"unknown EVT 2.1 endianness {endianness!r}", path=path, offset=offsets.get("format"))
    try:
        t_offset = int(fields.get("t_offset_us", "0"))
    except ValueError:
        raise FormatError("t_offset_us is not an integer", path=path, offset=offsets.get("t_offset_us")) from None
    if abs(t_offset) > MAX_T_OFFSET_US:  # event times are int64 us: an offset past this cannot be added
        raise FormatError(
            f"t_offset_us {t_offset} is beyond +-{MAX_T_OFFSET_US} (about 146 000 years)",
            path=path,
            offset=offsets.get("t_offset_us"),
        )
    return RawLayout(encoding, endianness, width, height, t_offset)


def raw_header(
    encoding: str, width: int, height: int, extra: Mapping[str, object] | None = None, *, simulated: bool = False
) -> bytes:
    """A RAW header that Metavision/OpenEB opens, for an EVT stream of ``encoding``.

    It has the current ``% format`` and ``% geometry`` lines, the older ``% evt`` line, the
    integrator fields with which OpenEB picks its Prophesee plugin, ``extra`` fields, and ``% end``.
    A ``simulated`` stream names flagtrack as its camera's integrator, and its simulator, instead
    (OpenEB then opens it with any plugin that reads the format).
    """
    if encoding not in _FORMAT_OUT:
        raise FormatError(f"unknown encoding {encoding!r} (known: evt2, evt21, evt3)")
    check_sensor_size(int(width), int(height))  # (what the readers would refuse)
    maker = SIMULATED_FIELDS if simulated else PROPHESEE_FIELDS
    known: dict[str, object] = {
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M:%S"),
        "evt": _EVT_OUT[encoding],
        "format": f"{_FORMAT_OUT[encoding]};height={int(height)};width={int(width)}",
        "generator": f"flagtrack {__version__}",
        "geometry": f"{int(width)}x{int(height)}",
        **maker,
    }
    fields = dict(sorted(known.items()))
    fields.update(extra or {})
    lines = []
    for key, value in fields.items():
        text = f"% {key} {value}"
        if " " in key or not key or "\n" in text or "\r" in text:
            raise FormatError(f"header field {key!r} cannot be written")
        lines.append(text)
    return ("\n".join(lines) + "\n% end\n").encode("utf-8")
