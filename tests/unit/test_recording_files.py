"""A live recording's files with no bus: parts, sidecars, roll-over to a new stream, a failed write
cut back to the last flush, the free-space guard; on real files (a real tmpfs for the full disk)."""

from __future__ import annotations

import dataclasses
import errno
import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.errors import FormatError
from flagtrack.daemon.schema import EventPacket
from flagtrack.drivers.formats import read_events
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.formats.packets import Packetizer, PacketParams
from flagtrack.drivers.formats.recording import FreeSpaceGuard, PartChain, RecordingPart, drop_summary
from flagtrack.drivers.formats.recording.chain import failed_write
from flagtrack.drivers.reserve import RESERVE_BYTES, DiskReserve
from flagtrack.drivers.sim.quickline import WavyFlag, line_events
from tests.integration.test_centreline_file_service import message


class Intervals:
    flush_interval_s = 0.0
    fsync_interval_s = 0.0


def camera(t_until_us: int = 40_000, width: int = 640, first_seq: int = 0) -> tuple[np.ndarray, list[EventPacket]]:
    """A flapping line's events and their EVT 3.0 packets (1 ms each) as the bus carries them."""
    events = np.concatenate(list(line_events(WavyFlag(), 0, t_until_us, width, 480)))
    packetizer = Packetizer("evt3", width, 480, PacketParams(packet_us=1000))
    packets = packetizer.push(events, None, t_until_us=t_until_us) + packetizer.flush()
    return events, [
        EventPacket(
            "cam0",
            first_seq + i,
            p.t_first_us,
            p.t_last_us,
            p.n_events,
            width,
            480,
            "evt3",
            1000 + i,
            p.t_offset_us,
            data=p.data,
        )
        for i, p in enumerate(packets)
    ]


def sidecar(path: Path) -> dict:
    return json.loads(path.read_text())


def test_a_part_reads_back_exactly_with_its_sidecar_and_no_other_file(tmp_path: Path) -> None:
    events, packets = camera()
    part = RecordingPart(base=tmp_path / "run", config={"camera": "cam0"})
    part.write_sidecar()
    for packet in packets:
        part.write_packet(packet)
    part.close()
    np.testing.assert_array_equal(read_events(tmp_path / "run.raw", strict=True).events, events)
    doc = sidecar(tmp_path / "run.json")
    assert doc["stopped"] and doc["packets"] == len(packets) and doc["events"] == len(events)
    assert doc["encoding"] == "evt3" and doc["width"] == 640 and doc["config"] == {"camera": "cam0"}
    assert doc["sequence_gaps"] == [] and doc["part"] == 1 and doc["centrelines_file"] is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.json", "run.raw"]


def test_a_gap_is_in_the_sidecar_and_the_file_reads_past_it(tmp_path: Path) -> None:
    _, packets = camera()
    kept = packets[:10] + packets[15:]
    part = RecordingPart(base=tmp_path / "g", config={})
    for packet in kept:
        part.write_packet(packet, gap_from=10 if packet.seq == 15 else None)
    part.close()
    doc = sidecar(tmp_path / "g.json")
    assert doc["sequence_gaps"] == [[10, 15]] and doc["missing_packets"] == 5
    assert doc["gaps"][0]["t_from_us"] == packets[9].t_last_us and doc["gaps"][0]["t_to_us"] == packets[15].t_first_us
    got = read_events(tmp_path / "g.raw", strict=True).events
    assert len(got) == sum(p.n_events for p in kept)


def test_a_packet_that_cannot_start_a_file_creates_nothing(tmp_path: Path) -> None:
    _, packets = camera(5_000)
    part = RecordingPart(base=tmp_path / "bad", config={})
    with pytest.raises(FormatError):
        part.write_packet(EventPacket(**{**packets[0].__dict__, "encoding": "evt9"}))
    assert not part.opened and list(tmp_path.iterdir()) == []


def test_another_geometry_is_a_format_change(tmp_path: Path) -> None:
    _, packets = camera(5_000)
    _, wide = camera(5_000, width=1280)
    part = RecordingPart(base=tmp_path / "f", config={})
    part.write_packet(packets[0])
    assert part.format_change(packets[1]) is None
    assert part.format_change(wide[1]) == "packet 1 is evt3 1280x480, the file evt3 640x480"
    part.close()


def test_a_failed_write_is_cut_back_to_the_last_flush(tmp_path: Path) -> None:
    events, packets = camera()
    chain_failures: list[str] = []
    chain = PartChain(on_failure=lambda part, message: chain_failures.append(message))
    chain.begin(RecordingPart(base=tmp_path / "cut", config={}))
    part = chain.current
    assert part is not None
    for packet in packets[:20]:
        part.write_packet(packet)
    part.sync(Intervals())  # flushed here
    flushed = part.flushed_at
    for packet in packets[20:25]:
        part.write_packet(packet)  # buffered, then closing flushes them: cut back
    chain.fail(OSError(errno.ENOSPC, "No space left on device"))
    assert chain.current is None and chain.finished == [tmp_path / "cut.raw"]
    assert chain_failures == [
        f"recording stopped: writing {tmp_path / 'cut.raw'} failed: No space left on device; the file is kept up "
        f"to its last flush ({flushed} bytes)"
    ]
    assert (tmp_path / "cut.raw").stat().st_size == flushed
    n = sum(p.n_events for p in packets[:20])
    np.testing.assert_array_equal(read_events(tmp_path / "cut.raw", strict=True).events, events[:n])
    assert sidecar(tmp_path / "cut.json")["stopped"]


def test_a_roll_over_links_the_parts_and_the_old_one_drains_its_centrelines(tmp_path: Path) -> None:
    """A new stream goes in ``BASE_stream2``; the old part takes the centrelines of packets sent
    before the new stream's first until the tracker's final message, which closes it."""
    _, packets = camera(10_000)
    chain = PartChain(on_failure=lambda part, message: pytest.fail(message))
    chain.begin(RecordingPart(base=tmp_path / "r", config={}, want_centrelines=True, centreline_attrs={"units": "px"}))
    assert chain.current is not None
    chain.current.write_packet(packets[0])
    old, new = chain.roll_over(first_sent_ns=5000)
    assert chain.current is new and chain.draining is old and new.base == tmp_path / "r_stream2"
    late = message(0, 4, 51)
    late.source_ns[:] = 4000  # from packets before the new stream's
    chain.take_centrelines(late)
    chain.take_centrelines(message(1, 2, 51, final=True))  # the final message: the old part is closed
    assert chain.draining is None and chain.finished == [tmp_path / "r.raw"]
    assert len(read_centrelines(tmp_path / "r_centrelines.h5")[0]) == 4
    new.write_packet(packets[1])
    assert chain.stop() is new and chain.finished == [tmp_path / "r.raw", tmp_path / "r_stream2.raw"]
    first, second = sidecar(tmp_path / "r.json"), sidecar(tmp_path / "r_stream2.json")
    assert first["continued_in"] == "r_stream2.raw" and second["continues"] == "r.raw" and second["part"] == 2


def test_the_free_space_guard_raises_enospc_below_its_floor_and_looks_at_most_every_interval(tmp_path: Path) -> None:
    free_mb = shutil.disk_usage(tmp_path).free / 1e6
    guard = FreeSpaceGuard(min_free_mb=free_mb * 2, every_s=0.25, setting="recorder.min_free_mb")
    with pytest.raises(OSError, match=r"No space left on device: .* MB free, below recorder.min_free_mb") as info:
        guard.check(tmp_path, now_s=10.0)
    assert info.value.errno == errno.ENOSPC
    guard.check(tmp_path, now_s=10.1)  # not looked at again yet
    with pytest.raises(OSError):
        guard.check(tmp_path, now_s=10.3)
    FreeSpaceGuard(min_free_mb=0.0).check(tmp_path, now_s=0.0)


FULL_DISK = """
import errno, json, sys
from pathlib import Path
from flagtrack.drivers.formats.recording import PartChain, RecordingPart
from tests.unit.test_recording_files import Intervals, camera

disk = Path(sys.argv[1])
events, packets = camera(400_000)
failures = []
chain = PartChain(on_failure=lambda part, message: failures.append(message))
chain.begin(RecordingPart(base=disk / "full", config={}))
for packet in packets:
    try:
        chain.current.write_packet(packet)
        chain.current.sync(Intervals())
    except OSError as exc:
        chain.fail(exc)
        break
print(json.dumps({"failures": failures, "size": (disk / "full.raw").stat().st_size, "current": chain.current is None}))
"""


def test_a_part_on_a_full_disk_is_cut_back_and_reads_back_whole(tmp_path: Path) -> None:
    """A 256 KB tmpfs in a private mount namespace fills up: the write fails, the file is cut back to
    its last flush and reads back as a prefix of what the camera sent."""
    if shutil.which("unshare") is None:
        pytest.skip("no unshare(1)")
    disk = tmp_path / "disk"
    disk.mkdir()
    script = (
        f"mount -t tmpfs -o size=256k tmpfs {disk} || exit 77; "
        f"{sys.executable} -c {_quoted(textwrap.dedent(FULL_DISK))} {disk} && cp -a {disk}/. {tmp_path}/"
    )
    done = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, timeout=120)
    if done.returncode == 77 or "unshare failed" in done.stderr:
        pytest.skip(f"cannot mount a tmpfs in a mount namespace: {done.stderr.strip()}")
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout)
    assert len(result["failures"]) == 1 and "No space left on device" in result["failures"][0], result
    assert result["current"] and result["size"] > 0
    events, _ = camera(400_000)
    got = read_events(tmp_path / "full.raw", strict=True).events
    assert 0 < len(got) < len(events)
    np.testing.assert_array_equal(got, events[: len(got)])


def _quoted(text: str) -> str:
    return "'" + text.replace("'", "'\\''") + "'"


def test_the_drops_a_camera_reports_while_a_part_records_are_in_its_sidecar(tmp_path: Path) -> None:
    """The stream's running count of drops: what it was at the part's first packet is not the part's;
    each rise is an entry, with the packet's reason, or a plain one when the packet that said it was lost."""
    _, packets = camera()
    with_drops = lambda p, n, **drop: dataclasses.replace(p, device_drops=n, **drop)  # noqa: E731
    stream = [with_drops(p, 3) for p in packets[:10]]  # 3 drops before the recording began
    stream[0] = with_drops(packets[0], 3, drop_count=7, drop_unit="usb_packets", drop_reason="ring full")
    stream += [with_drops(packets[10], 4, drop_count=250_000, drop_unit="us", drop_reason="skipped ahead")]
    stream += [with_drops(p, 4) for p in packets[11:20]] + [with_drops(p, 6) for p in packets[22:30]]
    part = RecordingPart(base=tmp_path / "r", config={})
    for packet in stream:
        part.write_packet(packet, gap_from=20 if packet.seq == 22 else None)
    part.close()
    doc = sidecar(tmp_path / "r.json")
    assert doc["device_drop_reports"] == 3 and doc["missing_packets"] == 2
    first, second = doc["device_drops"]
    assert (first["seq"], first["reports"], first["count"], first["unit"], first["reason"]) == (
        10, 1, 250_000, "us", "skipped ahead"
    )  # fmt: skip
    assert (first["t_from_us"], first["t_to_us"]) == (packets[9].t_last_us, packets[10].t_first_us)
    assert (second["seq"], second["reports"], second["count"]) == (22, 2, 0)
    assert second["reason"].startswith("reported on packets missing from the recording")
    assert drop_summary(doc["device_drops"]) == (
        "skipped ahead (0.25 s); reported on packets missing from the recording (see its gaps) (2 times)"
    )


def test_a_failed_write_names_the_file_that_failed_in_one_line(tmp_path: Path) -> None:
    raw = tmp_path / "rec.raw"
    hdf5 = RuntimeError(  # h5py's text for a full disk under an HDF5 flush
        "Can't flush entry (file write failed: time = Sun Dec  6 16:39:28 2026\n, filename = "
        f"'{tmp_path / 'rec_centrelines.h5'}', file descriptor = 11, errno = 28, error message = 'No space left "
        "on device', buf = 0x7fc778401f68, total write size = 18592, bytes this sub-write = 18592, offset = 1142784)"
    )
    assert failed_write(hdf5, raw) == (tmp_path / "rec_centrelines.h5", "No space left on device")
    assert failed_write(RuntimeError("Can't close dataset (other)\nmore"), raw) == (raw, "Can't close dataset (other)")
    assert failed_write(OSError(errno.ENOSPC, "No space left on device", str(raw)), tmp_path / "x") == (
        raw,
        "No space left on device",
    )
    h5py_os = OSError(
        errno.ENOSPC, f"File write failed (time = x\n, filename = '{raw}', error message = 'No space left')"
    )
    assert failed_write(h5py_os, tmp_path / "x") == (raw, "No space left")
    assert failed_write(OSError(errno.ENOSPC, "File write failed (time = x\n, more)"), raw) == (
        raw,
        "File write failed (time = x",
    )


def test_the_room_kept_to_close_the_files_is_on_the_disk_and_never_follows_a_link(tmp_path: Path) -> None:
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    path = tmp_path / ".rec.reserve"
    path.symlink_to(target)  # planted where the reserve goes
    reserve = DiskReserve(path, 256 * 1024)
    reserve.take()
    assert target.read_text() == "keep me" and not path.is_symlink()
    assert path.stat().st_size == 256 * 1024 and path.stat().st_blocks * 512 >= 256 * 1024  # allocated, not sparse
    reserve.release()
    reserve.release()
    assert not path.exists() and target.read_text() == "keep me"


def test_a_part_holds_its_room_while_it_records_and_gives_it_back_when_it_closes(tmp_path: Path) -> None:
    _, packets = camera()
    part = RecordingPart(base=tmp_path / "rec", config={}, want_centrelines=True)
    part.write_packet(packets[0])
    assert (tmp_path / ".rec.reserve").stat().st_size == RESERVE_BYTES
    part.close()
    assert not (tmp_path / ".rec.reserve").exists()


HOLD_RESERVE = """
import os, signal, sys
from pathlib import Path
from flagtrack.drivers.reserve import DiskReserve
DiskReserve(Path(sys.argv[1]), 64 * 1024).take()
print("held", flush=True)
if sys.argv[2] == "killed":
    os.kill(os.getpid(), signal.SIGKILL)
sys.stdin.read()  # held until the test closes stdin
"""


def test_a_reserve_left_by_a_killed_process_goes_when_a_part_starts_there_one_held_stays(tmp_path: Path) -> None:
    killed, live = tmp_path / ".killed.reserve", tmp_path / ".live.reserve"
    subprocess.run([sys.executable, "-c", HOLD_RESERVE, str(killed), "killed"], capture_output=True, timeout=60)
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD_RESERVE, str(live), "live"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        assert killed.exists() and live.exists()
        _, packets = camera()
        part = RecordingPart(base=tmp_path / "rec", config={}, want_centrelines=False)
        part.write_packet(packets[0])
        assert not killed.exists() and live.exists() and (tmp_path / ".rec.reserve").exists()
        part.close()
        assert live.exists()
    finally:
        holder.communicate("", timeout=60)
    assert sorted(p.name for p in tmp_path.glob(".*.reserve")) == [".live.reserve"]  # its holder exited cleanly:
    # (no release ran, so the file stays; unlocked now, the next part started here removes it)
    second = RecordingPart(base=tmp_path / "rec2", config={}, want_centrelines=False)
    second.write_packet(packets[0])
    second.close()
    assert not live.exists()


def test_a_file_system_that_cannot_allocate_records_without_the_room_and_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def unsupported(fd: int, offset: int, size: int) -> None:
        raise OSError(errno.EOPNOTSUPP, "Operation not supported")

    monkeypatch.setattr("os.posix_fallocate", unsupported, raising=False)
    events, packets = camera()
    part = RecordingPart(base=tmp_path / "rec", config={}, want_centrelines=True)
    for packet in packets:
        part.write_packet(packet)
    part.close()
    np.testing.assert_array_equal(read_events(tmp_path / "rec.raw", strict=True).events, events)
    said = [r.getMessage() for r in caplog.records if "no room kept for closing its files" in r.getMessage()]
    assert len(said) == 1 and "Operation not supported" in said[0]
    assert not (tmp_path / ".rec.reserve").exists()
