"""Schema versions: messages of versions 1 and 2 (older peers) still decode, scalar fields of a later
version are ignored."""

from __future__ import annotations

import dataclasses
import json
import struct

import numpy as np
import pytest

from flagtrack.daemon import schema
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.errors import SchemaError
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, TrackerStatus, decode, encode

_HEADER = struct.Struct("<2sBBI")


def _rewrite(data: bytes, version: int | None = None, edit=None) -> bytes:
    """The message with another version byte and/or an edited meta."""
    magic, old_version, type_id, meta_len = _HEADER.unpack_from(data)
    meta = json.loads(data[_HEADER.size : _HEADER.size + meta_len])
    if edit is not None:
        edit(meta)
    body = json.dumps(meta).encode()
    return (
        _HEADER.pack(magic, old_version if version is None else version, type_id, len(body))
        + body
        + data[_HEADER.size + meta_len :]
    )


def test_this_build_writes_version_3_and_reads_1_to_3() -> None:
    packet = EventPacket("cam0", 3, 10, 999, 5, 640, 480, "evt3", 123, stream_id=77, data=b"\x00\x80" * 4)
    data = encode(packet)
    assert data[2] == schema.VERSION == 3
    assert decode(data, EventPacket) == packet
    for version in (1, 2):
        assert decode(_rewrite(data, version=version), EventPacket) == packet
    with pytest.raises(SchemaError, match="unsupported schema version 4"):
        decode(_rewrite(data, version=4), EventPacket)


def _lines(n: int = 3) -> CentrelineMessage:
    batch = CentrelineBatch(
        t_s=np.arange(n) * 1e-3,
        s=np.linspace(0, 1, 4),
        x=np.zeros((n, 4)),
        y=np.zeros((n, 4)),
        joints_x=np.zeros((n, 3)),
        joints_y=np.zeros((n, 3)),
        delta_rms=np.zeros(n),
        n_events=np.zeros(n, dtype=np.int64),
        lost=np.array([0, 1, 0][:n], dtype=np.uint8),
        stale=np.array([1, 0, 0][:n], dtype=np.uint8),
    )
    return CentrelineMessage.from_batch(batch, source="tracker", seq=1, units="px", source_ns=np.zeros(n))


def test_stale_travels_and_a_message_of_before_it_decodes_as_all_0() -> None:
    message = _lines()
    back = decode(encode(message), CentrelineMessage)
    np.testing.assert_array_equal(back.stale, [1, 0, 0])
    np.testing.assert_array_equal(back.batch().stale, [1, 0, 0])
    np.testing.assert_array_equal(back.lost, [0, 1, 0])
    without = dataclasses.replace(message, stale=np.zeros(0, dtype=np.uint8), shed=np.zeros(0, dtype=np.float32))
    data = encode(without)
    for version in (1, 2):  # what an older tracker sends: no stale array
        old = decode(_rewrite(data, version=version), CentrelineMessage)
        assert old.stale.dtype == np.uint8 and old.stale.tolist() == [0, 0, 0]
        assert old.batch().stale.tolist() == [0, 0, 0]


def test_a_stale_array_of_another_length_is_refused_by_name() -> None:
    bad = dataclasses.replace(_lines(), stale=np.zeros(5, dtype=np.uint8))
    with pytest.raises(SchemaError, match="stale"):
        decode(encode(bad), CentrelineMessage)


def _shed_lines(n: int, shed: np.ndarray | None = None) -> CentrelineMessage:
    batch = CentrelineBatch(
        t_s=np.arange(n) * 2.5e-4,
        s=np.linspace(0, 1, 3),
        x=np.zeros((n, 3)),
        y=np.zeros((n, 3)),
        joints_x=np.zeros((n, 3)),
        joints_y=np.zeros((n, 3)),
        delta_rms=np.zeros(n),
        n_events=np.zeros(n, dtype=np.int64),
        shed=shed,
    )
    return CentrelineMessage.from_batch(batch, source="tracker", seq=0, units="px", source_ns=np.zeros(n))


def test_shed_travels_and_a_message_without_it_decodes_as_nothing_shed() -> None:
    shed = np.array([0.0, 0.5, 1.0, 0.25], dtype=np.float32)
    got = decode(encode(_shed_lines(4, shed)), CentrelineMessage)
    np.testing.assert_array_equal(got.shed, shed)
    np.testing.assert_array_equal(got.batch().shed, shed)

    def without_shed(meta: dict) -> None:
        meta["_blobs"] = [blob for blob in meta["_blobs"] if blob[0] != "shed"]

    data = encode(_shed_lines(4, shed))
    old = _rewrite(data[: len(data) - shed.nbytes], version=2, edit=without_shed)  # (shed is the last blob)
    got = decode(old, CentrelineMessage)
    assert got.shed.dtype == np.float32
    np.testing.assert_array_equal(got.shed, np.zeros(4))
    assert (decode(encode(_shed_lines(0)), CentrelineMessage).shed.shape) == (0,)


def test_a_status_of_an_older_tracker_says_nothing_shed() -> None:
    status = TrackerStatus("tracker", "tracking", 1e6, 4000.0, 0.001, 10, 0, 0, shed_fraction=0.25, shed_packets=3)
    assert decode(encode(status), TrackerStatus) == status
    older = _rewrite(encode(status), version=2, edit=lambda meta: [meta.pop("shed_fraction"), meta.pop("shed_packets")])
    got = decode(older, TrackerStatus)
    assert (got.shed_fraction, got.shed_packets) == (0.0, 0)


def test_a_version_1_packet_without_stream_id_decodes_with_its_default() -> None:
    packet = EventPacket("cam0", 3, 10, 999, 5, 640, 480, "evt3", 123, data=b"")
    old = _rewrite(encode(packet), version=1, edit=lambda meta: meta.pop("stream_id"))
    assert decode(old, EventPacket).stream_id == 0


def test_scalar_fields_of_a_later_version_are_ignored() -> None:
    status = TrackerStatus("tracker", "tracking", 1e6, 4000.0, 0.001, 10, 0, 0, late_packets=2)
    newer = _rewrite(encode(status), edit=lambda meta: meta.update(frames_per_fortnight=7))
    assert decode(newer, TrackerStatus) == status


def test_a_missing_required_field_is_still_an_error() -> None:
    status = TrackerStatus("tracker", "tracking", 1e6, 4000.0, 0.001, 10, 0, 0)
    broken = _rewrite(encode(status), edit=lambda meta: meta.pop("packets"))
    with pytest.raises(SchemaError, match="packets"):
        decode(broken, TrackerStatus)


def test_native_packets_carry_their_preamble_and_older_packets_decode_as_re_encoded() -> None:
    packet = EventPacket(
        "cam0", 3, 10, 999, 5, 640, 480, "evt3", 123, preamble_bytes=4, native=True, data=b"\x00\x80" * 4
    )
    assert decode(encode(packet), EventPacket) == packet
    older = _rewrite(encode(packet), edit=lambda meta: [meta.pop("preamble_bytes"), meta.pop("native")])
    got = decode(older, EventPacket)  # a peer of before native packets: every byte is the packet's own
    assert (got.preamble_bytes, got.native, got.data) == (0, False, packet.data)


def test_drop_fields_travel_and_messages_of_older_peers_decode_as_no_drops() -> None:
    packet = EventPacket(
        "cam0", 3, 10, 999, 5, 640, 480, "evt3", 123, device_drops=2, drop_count=250_000, drop_unit="us",
        drop_reason="simulated camera: skipped ahead",
    )  # fmt: skip
    assert decode(encode(packet), EventPacket) == packet
    drop_fields = ("device_drops", "drop_count", "drop_unit", "drop_reason")
    old = _rewrite(encode(packet), edit=lambda meta: [meta.pop(name) for name in drop_fields])
    assert decode(old, EventPacket) == EventPacket("cam0", 3, 10, 999, 5, 640, 480, "evt3", 123)
    status = schema.RecorderStatus("idle", device_drops=1, device_drop_reason="backlog cleared")
    older = _rewrite(encode(status), edit=lambda meta: [meta.pop("device_drops"), meta.pop("device_drop_reason")])
    assert decode(older, schema.RecorderStatus) == schema.RecorderStatus("idle")
    camera = schema.CameraStatus("cam0", "streaming", "simulated", 640, 480, "evt3", device_drops=4, drop_reason="x")
    oldest = _rewrite(encode(camera), version=1, edit=lambda meta: [meta.pop("device_drops"), meta.pop("drop_reason")])
    assert decode(oldest, schema.CameraStatus).device_drops == 0
