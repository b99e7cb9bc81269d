"""What `flagtrack up` shows while it records: on a terminal one line redrawn in place (file, time,
size, rate, lost packets), elsewhere a line as a recording begins and one a minute, and a line per
closed file with its size, camera time and the packets its sidecar says were lost; on a real
recording part (real files, the bus's packets)."""

from __future__ import annotations

import io
import json
from pathlib import Path
from types import SimpleNamespace

from flagtrack.daemon.commands._recording_view import PLAIN_EVERY_S, RecordingView, recorded_line
from flagtrack.drivers.formats.recording import RecordingPart
from tests.unit.test_recording_files import camera


def recorder(part: RecordingPart | None) -> SimpleNamespace:
    """The recorder service's two attributes the view reads (``current``, ``finished``)."""
    return SimpleNamespace(name="recorder", current=part, finished=[])


def test_a_terminal_gets_one_line_redrawn_then_where_the_events_went(tmp_path: Path) -> None:
    _, packets = camera(t_until_us=40_000)
    part = RecordingPart(base=tmp_path / "test1", config={})
    service = recorder(part)
    out = io.StringIO()
    view = RecordingView(stream=out, terminal=True)
    view._recorder = service  # (what calling it with the rig's services does, without its watch thread)
    view.tick(0.0)
    assert out.getvalue() == ""  # no packet yet: the file is not open, nothing to show
    for packet in packets[:20]:
        part.write_packet(packet)
    view.tick(1.0)
    events_before = part.events
    for packet in packets[20:]:
        part.write_packet(packet)
    part.dropped = 3
    view.tick(3.0)
    drawn = out.getvalue().split("\r")
    assert f"recording {part.raw_path}  0:00  " in drawn[-1] and "Mev/s" not in out.getvalue().split("\r")[-2]
    rate = (part.events - events_before) / 2.0 / 1e6
    assert f"{rate:.1f} Mev/s  lost 3 packets" in drawn[-1] and "\n" not in out.getvalue()
    part.close()
    service.current, service.finished = None, [part.raw_path]
    view.tick(4.0)
    view.close()
    said = [line for line in out.getvalue().replace("\r", "\n").splitlines() if line.strip()]
    size_mb = part.raw_path.stat().st_size / 1e6
    assert said[-1] == (
        f"flagtrack up: recorded {part.raw_path}: {size_mb:.1f} MB, 0:00 of camera time, 3 packets lost (see test1.json)"
    )
    assert len([line for line in said if "recorded" in line]) == 1  # said once, not again at close


def test_elsewhere_a_line_as_it_begins_and_one_a_minute(tmp_path: Path) -> None:
    _, packets = camera(t_until_us=5_000)
    part = RecordingPart(base=tmp_path / "night", config={})
    for packet in packets:
        part.write_packet(packet)
    out = io.StringIO()
    view = RecordingView("sweep", stream=out, terminal=False)
    view._recorder = recorder(part)
    for now_s in (100.0, 101.0, 100.0 + PLAIN_EVERY_S - 1, 100.0 + PLAIN_EVERY_S):
        view.tick(now_s)
    part.close()
    lines = out.getvalue().splitlines()
    assert len(lines) == 2 and all(line.startswith(f"flagtrack sweep: recording {part.raw_path}  ") for line in lines)
    assert "\r" not in out.getvalue()


def test_the_closing_line_says_the_lost_packets_and_copes_without_a_sidecar(tmp_path: Path) -> None:
    _, packets = camera(t_until_us=30_000)
    part = RecordingPart(base=tmp_path / "gappy", config={})
    for packet in packets[:5] + packets[9:]:  # 4 packets missing
        part.write_packet(packet, gap_from=5 if packet.seq == 9 else None)
    part.close()
    line = recorded_line(part.raw_path)
    assert line.endswith(", 0:00 of camera time, 4 packets lost (see gappy.json)"), line
    doc = json.loads(part.sidecar_path.read_text())
    part.sidecar_path.write_text(json.dumps({**doc, "t_first_us": None}))  # a sidecar without its times
    assert recorded_line(part.raw_path) == f"recorded {part.raw_path}: {part.raw_path.stat().st_size / 1e6:.1f} MB"
    part.sidecar_path.unlink()
    assert recorded_line(part.raw_path).endswith(" MB")
    assert "size not known" in recorded_line(tmp_path / "gone.raw")
