"""A damaged AEDAT 4.0 IOHeader is refused before the ``aedat`` library reads it: with an info node
that is not UTF-8 text, aedat 2.3 raises, then aborts the whole process while cleaning up."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import open_events
from flagtrack.drivers.formats.aedat_file import MAGIC, io_header_problem

# an IOHeader as dv writes it: root offset, "IOHE", padding, the vtable (3 fields), the table
# (vtable offset, compression 1, the info node's offset, the data table's position), then the string
_LAYOUT = (
    b"\x18\x00\x00\x00IOHE" + bytes(6) + b"\n\x00\x14\x00\x04\x00\x0c\x00\x08\x00"
    b"\n\x00\x00\x00\x01\x00\x00\x00\x0c\x00\x00\x00" + struct.pack("<q", 945243)
)


def io_header(info: bytes) -> bytes:
    return _LAYOUT + struct.pack("<I", len(info)) + info + b"\x00"


def test_a_well_formed_header_has_no_problem() -> None:
    assert io_header_problem(io_header(b'<dv version="2.0"></dv>')) is None


@pytest.mark.parametrize(
    ("header", "problem"),
    [
        (io_header(b'<dv version="2.0">\xca\x22</dv>'), "not UTF-8 text: invalid continuation byte at byte 18"),
        (io_header(b"<dv/>")[:-4], "runs past its end"),
        (b"\xff\xff\x00\x00" + io_header(b"<dv/>")[4:], "point outside it"),
        (b"\x18\x00", "point outside it"),
        (_LAYOUT[:24] + struct.pack("<i", 40) + _LAYOUT[28:] + bytes(8), "point outside it"),  # vtable before 0
    ],
)
def test_a_damaged_header_says_what_is_wrong(header: bytes, problem: str) -> None:
    found = io_header_problem(header)
    assert found is not None and problem in found


def test_the_reader_refuses_it_naming_the_file(tmp_path: Path) -> None:
    header = io_header(b"<dv>\xff</dv>")
    path = tmp_path / "damaged.aedat4"
    path.write_bytes(MAGIC + struct.pack("<i", len(header)) + header + bytes(16))
    with pytest.raises(FormatError, match="garbage AEDAT 4.0 header .*not UTF-8") as caught:
        open_events(path)
    assert str(path) in str(caught.value)
