"""RAW headers: old and new styles, encodings, sensor size from the camera, garbage."""

from __future__ import annotations

import pytest

from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import parse_raw_header, raw_header
from flagtrack.drivers.formats.geometry import geometry_from_plugin, inferred_geometry
from flagtrack.drivers.formats.raw_header import parse_header_lines, raw_layout

OLD_EVT2 = (
    b"% Date 2020-09-14 09:03:25\n% firmware_version 2.0.2\n% integrator_name Prophesee\n"
    b"% plugin_name hal_plugin_gen3_fx3\n% serial_number 30384338\n% system_ID 21\n% evt 2.0\n"
)


def test_old_header_ends_at_the_first_line_without_percent() -> None:
    body = b"\x10\x00\x00\x80\n%\n%\x00\x11"  # binary data that holds b"\n%"
    fields, offset = parse_raw_header(OLD_EVT2 + body)
    assert offset == len(OLD_EVT2)
    assert fields["plugin_name"] == "hal_plugin_gen3_fx3" and fields["evt"] == "2.0"
    layout = raw_layout(*parse_header_lines(OLD_EVT2 + body)[::2])
    assert (layout.encoding, layout.width, layout.height, layout.t_offset_us) == ("evt2", 640, 480, 0)


def test_new_header_ends_at_end_line_and_allows_crlf() -> None:
    head = b"% format EVT3;height=720;width=1280\r\n% geometry 1280x720\r\n% end\r\n"
    fields, offset = parse_raw_header(head + b"%\x00\x80")  # the body may start with '%'
    assert offset == len(head)
    layout = raw_layout(fields, {})
    assert (layout.encoding, layout.width, layout.height) == ("evt3", 1280, 720)


@pytest.mark.parametrize(
    ("plugin", "size"),
    [
        ("hal_plugin_gen3_fx3", (640, 480)),
        ("hal_plugin_gen31_evk3", (640, 480)),
        ("evc3a_plugin_gen31", (640, 480)),
        ("hal_plugin_gen4_fx3", (1280, 720)),
        ("hal_plugin_gen41_evk3", (1280, 720)),
        ("hal_plugin_imx636_evk4", (1280, 720)),
        ("hal_plugin_genx320_evk3", (320, 320)),
        ("silky_plugin_unknown", None),
    ],
)
def test_geometry_from_plugin_name(plugin: str, size: tuple[int, int] | None) -> None:
    assert geometry_from_plugin(plugin) == size


@pytest.mark.parametrize(
    ("fields", "size"),
    [
        ({"system_ID": "48"}, (1280, 720)),  # EVK3 Gen4.1
        ({"system_ID": "0x15"}, (640, 480)),  # CCAM3 Gen3
        ({"system_ID": "48", "integrator_name": "CenturyArks"}, None),  # not Prophesee's id table
        ({"sensor_generation": "4.2"}, (1280, 720)),
        ({"serial_number": "1"}, None),
    ],
)
def test_geometry_inferred_from_camera_fields(fields: dict[str, str], size: tuple[int, int] | None) -> None:
    assert inferred_geometry(fields) == size


def test_unknown_geometry_is_reported_as_none() -> None:
    layout = raw_layout({"evt": "3.0", "plugin_name": "mystery"}, {})
    assert layout.width is None and layout.height is None


@pytest.mark.parametrize(
    ("head", "message", "offset"),
    [
        (b"% date today\n% format EVT9;height=1;width=1\n% end\n", "unknown encoding 'EVT9'", 13),
        (b"% evt 4.0\n% end\n", "unknown encoding 'evt 4.0'", 0),
        (b"% date today\n% end\n", "no encoding", 0),
    ],
)
def test_unknown_encoding_names_the_line(head: bytes, message: str, offset: int) -> None:
    fields, _, offsets = parse_header_lines(head)
    with pytest.raises(FormatError, match=message) as err:
        raw_layout(fields, offsets, "x.raw")
    assert err.value.offset == offset and err.value.path == "x.raw"


@pytest.mark.parametrize(
    ("data", "offset"),
    [
        (b"% evt 3.0\n%\xff\xfe\x00garbage\n", 11),  # not text
        (b"% evt 3.0\n% a\x01b\n", 10),  # control character
        (b"% evt 3.0\n% cut", 10),  # header line never ends
    ],
)
def test_garbage_header_names_the_byte(data: bytes, offset: int) -> None:
    with pytest.raises(FormatError, match="header") as err:
        parse_header_lines(data, "g.raw")
    assert err.value.offset == offset


def test_evt21_layout_from_format_options_or_old_systems() -> None:
    assert raw_layout({"format": "EVT21;endianness=legacy;width=1280;height=720"}, {}).endianness == "legacy"
    assert raw_layout({"format": "EVT21;width=320;height=320"}, {}).endianness == "little"
    old = {"evt": "2.1", "system_ID": "49", "integrator_name": "Prophesee"}
    assert raw_layout(old, {}).endianness == "legacy"


def test_written_header_reads_back_with_what_metavision_needs() -> None:
    head = raw_header("evt2", 640, 480, {"t_offset_us": 1 << 34, "serial_number": "sim"})
    text = head.decode()
    for line in (
        "% format EVT2;height=480;width=640",
        "% geometry 640x480",
        "% evt 2.0",
        "% plugin_integrator_name Prophesee",
        "% camera_integrator_name Prophesee",
    ):
        assert line in text.splitlines()
    assert text.endswith("% end\n")
    fields, offset = parse_raw_header(head + b"\x00\x00\x00\x80")
    assert offset == len(head)
    layout = raw_layout(fields, {})
    assert (layout.encoding, layout.width, layout.height, layout.t_offset_us) == ("evt2", 640, 480, 1 << 34)
    with pytest.raises(FormatError):
        raw_header("evt3", 1, 1, {"bad key": 1})


@pytest.mark.parametrize("offset_text", ["99999999999999999999999", "-99999999999999999999999", str((1 << 62) + 1)])
def test_a_time_offset_beyond_int64_times_is_a_format_error(offset_text: str) -> None:
    """It used to reach the compiled decoder and come out as a numba typing traceback."""
    head = f"% evt 3.0\n% format EVT3;height=480;width=640\n% t_offset_us {offset_text}\n% end\n".encode()
    fields, _, offsets = parse_header_lines(head)
    with pytest.raises(FormatError, match="t_offset_us .* is beyond") as err:
        raw_layout(fields, offsets, "x.raw")
    assert err.value.offset == offsets["t_offset_us"] and err.value.path == "x.raw"
    assert raw_layout({**fields, "t_offset_us": str(1 << 62)}, offsets).t_offset_us == 1 << 62
