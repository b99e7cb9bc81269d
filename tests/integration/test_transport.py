"""Real Zenoh sessions on loopback (multicast scouting off, free ports): delivery, malformed counting, liveliness."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator

import pytest

from flagtrack.daemon.schema import EventPacket, TunnelCommand
from flagtrack.daemon.transport import Bus, BusConfig, Channel, zenoh_config
from tests.fakes.helpers import wait_subscribed  # (wait_for: imported from here too)
from tests.fakes.helpers import wait_until as wait_for


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.fixture()
def two_buses() -> Iterator[tuple[Bus, Bus]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/test", listen=(endpoint,))) as a,
        Bus(BusConfig(namespace="flagtrack/test", connect=(endpoint,))) as b,
    ):
        yield a, b


def received(sub, timeout_s: float = 1.0) -> list:
    """Every message ``sub`` gets until none comes for ``timeout_s``."""
    messages = []
    while (msg := sub.recv(timeout_s=timeout_s)) is not None:
        messages.append(msg)
    return messages


def received_to_final(sub, timeout_s: float = 30.0) -> list:
    """Every centreline message ``sub`` gets up to the one that ends the stream (``final``), within
    ``timeout_s`` in all (the tracker counts a stream ended before it publishes that message)."""
    messages: list = []
    deadline = time.monotonic() + timeout_s
    while not (messages and messages[-1].final):
        msg = sub.recv(timeout_s=max(deadline - time.monotonic(), 0.0))
        assert msg is not None, f"no final centreline message within {timeout_s:g} s ({len(messages)} before)"
        messages.append(msg)
    return messages


def test_packets_cross_sessions_in_order_and_malformed_are_counted(two_buses: tuple[Bus, Bus]) -> None:
    a, b = two_buses
    key = a.keys.camera_events("cam0")
    sub = b.subscribe(key, EventPacket)
    pub = a.publisher(key)
    wait_subscribed(a, key)  # a sample put before the subscription reaches a's session is not delivered
    for seq in range(200):
        if seq == 50:
            pub.put_bytes(b"garbage")
        pub.put(EventPacket("cam0", seq, seq, seq, 0, 640, 480, "evt3", 0, data=bytes(1000)))
    got = []
    while len(got) < 200:
        msg = sub.recv(timeout_s=5.0)
        assert msg is not None, f"only {len(got)} packets arrived"
        got.append(msg.seq)
    assert got == list(range(200))
    assert sub.malformed == 1


def test_liveliness_reports_a_service_going_away(two_buses: tuple[Bus, Bus]) -> None:
    a, b = two_buses
    watch = b.watch_liveliness()
    token = a.declare_alive("camera")
    key = a.keys.alive("camera")
    assert wait_for(lambda: watch.is_alive(key))
    token.undeclare()
    assert wait_for(lambda: not watch.is_alive(key) and key in watch.gone)


def test_undeclare_alive_withdraws_one_services_tokens_while_the_session_stays(two_buses: tuple[Bus, Bus]) -> None:
    a, b = two_buses
    watch = b.watch_liveliness()
    a.declare_alive("camera/cam0")
    a.declare_alive("tracker")
    camera, tracker = a.keys.alive("camera/cam0"), a.keys.alive("tracker")
    assert wait_for(lambda: watch.is_alive(camera) and watch.is_alive(tracker))
    assert a.undeclare_alive("camera/cam0") == 1
    assert wait_for(lambda: camera in watch.gone)
    assert not watch.is_alive(camera) and watch.is_alive(tracker) and not a.session.is_closed()
    assert a.undeclare_alive("camera/cam0") == 0  # ended already: nothing left to withdraw
    a.declare_alive("sentinel")  # a's liveliness changes arrive in order: what came before it has arrived
    assert wait_for(lambda: watch.is_alive(a.keys.alive("sentinel")))
    assert watch.is_alive(tracker) and watch.gone == [camera]


def test_ring_channel_keeps_newest_and_fifo_counts_drops() -> None:
    ring, fifo = Channel(3, ring=True), Channel(3, ring=False)
    for i in range(5):
        ring.push("k", bytes([i]))
        fifo.push("k", bytes([i]))
    assert [p for _, p in ring.drain()] == [b"\x02", b"\x03", b"\x04"] and ring.dropped == 2
    assert [p for _, p in fifo.drain()] == [b"\x00", b"\x01", b"\x02"] and fifo.dropped == 2
    assert fifo.get(timeout_s=0.01) is None


def test_commands_in_one_process_session(two_buses: tuple[Bus, Bus]) -> None:
    a, _ = two_buses
    sub = a.subscribe(a.keys.tunnel_command(), TunnelCommand)
    a.publisher(a.keys.tunnel_command()).put(TunnelCommand("set", 4.0))
    assert sub.recv(timeout_s=5.0) == TunnelCommand("set", 4.0)


@pytest.mark.parametrize("shared_memory", [False, True])
def test_large_packets_cross_with_and_without_shared_memory(shared_memory: bool) -> None:
    """Zenoh passes messages above ~3 KB through shared memory when both sessions allow it (it is off
    by default); either way a camera's 12 KB packets arrive whole and in order."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    cfg = {"namespace": "flagtrack/test", "shared_memory": shared_memory}
    assert zenoh_config(BusConfig(**cfg)).get_json("transport/shared_memory/enabled") == json.dumps(shared_memory)
    with Bus(BusConfig(listen=(endpoint,), **cfg)) as a, Bus(BusConfig(connect=(endpoint,), **cfg)) as b:
        key = a.keys.camera_events("cam0")
        sub = b.subscribe(key, EventPacket)
        pub = a.publisher(key)
        wait_subscribed(a, key)
        sent = [bytes([seq]) * 12_000 for seq in range(50)]
        for seq, data in enumerate(sent):
            pub.put(EventPacket("cam0", seq, seq, seq, 0, 640, 480, "evt3", 0, data=data))
        got = [sub.recv(timeout_s=5.0) for _ in sent]
        assert [msg.data for msg in got if msg is not None] == sent


def test_shared_memory_is_off_unless_asked(tmp_path) -> None:
    from flagtrack.daemon.rig.config import load_rig

    assert zenoh_config(BusConfig()).get_json("transport/shared_memory/enabled") == "false"
    rig = tmp_path / "rig.yaml"
    rig.write_text("rig: r1\nbus: {shared_memory: true}\n")
    assert load_rig(rig).bus_config.shared_memory is True
    rig.write_text("rig: r1\n")
    assert load_rig(rig).bus_config.shared_memory is False


def test_channels_bounded_by_bytes_drop_and_count() -> None:
    """With max_bytes, a FIFO turns away what would go beyond it (a smaller sample may still fit
    later), and a ring drops the oldest to make room (but not for a sample larger than the bound
    alone); both count samples and bytes."""
    fifo, ring = Channel(1000, ring=False, max_bytes=10), Channel(1000, ring=True, max_bytes=10)
    for size in (4, 4, 4, 2, 20):
        fifo.push("k", bytes(size))
        ring.push("k", bytes(size))
    assert [len(p) for _, p in fifo.drain()] == [4, 4, 2] and (fifo.dropped, fifo.dropped_bytes) == (2, 24)
    assert fifo.bytes == 0
    assert [len(p) for _, p in ring.drain()] == [4, 4, 2] and (ring.dropped, ring.dropped_bytes) == (2, 24)
    ring.push("k", bytes(6))
    ring.push("k", bytes(6))
    assert ring.bytes == 6 and ring.get(timeout_s=0) is not None and ring.bytes == 0


def test_a_port_in_use_is_said_without_zenohs_source_locations() -> None:
    """Zenoh's text ended '... (os error 98) at /root/.cargo/git/checkouts/zenoh-.../tcp.rs:61.]'."""
    from flagtrack.daemon.errors import ConfigError

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ConfigError) as refused:
            Bus(BusConfig(namespace="flagtrack/busy", listen=(f"tcp/127.0.0.1:{port}",)))
    text = str(refused.value)
    assert "Address already in use" in text and "another router or rig listens there?" in text, text
    assert ".rs:" not in text and ".cargo" not in text, text
