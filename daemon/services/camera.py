"""The camera service: runs one camera adapter and publishes its stream on the bus.

Publishes self-contained native-encoding event packets (about ``packet_us`` of camera time each,
numbered): an adapter that hands over the device's bytes (``CameraData.raw``) has them cut on word
boundaries, untouched (:class:`~flagtrack.drivers.formats.native.NativeCutter`); decoded events (the
simulated camera, .dat/.npy/.aedat4 replays, iniVation) are encoded by the packetizer. It also
publishes event-rate statistics every ``rate_interval_s`` of camera time, and the camera status
(with settings read back); declares its liveliness as ``camera/<id>``.

What the device or its driver reports lost (``CameraData.drops``: a full host ring, a cleared
backlog, a simulated camera's skip ahead) goes on the next packet published (``EventPacket``'s
``device_drops``, ``drop_count``, ``drop_unit``, ``drop_reason``), into the log (counted, rarely) and
into a status message (at most one per ``DROP_STATUS_INTERVAL_S``), so a recording made meanwhile is
marked lossy with the reason.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from flagtrack.daemon.core.events import make_events
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CameraStatus, EventPacket, EventRate
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.transport import Bus, Publisher
from flagtrack.drivers.camera.base import Camera, CameraInfo, DeviceDrop, EndOfStream
from flagtrack.drivers.formats.native import NATIVE_ENCODINGS, NativeCutter
from flagtrack.drivers.formats.packets import Packet, Packetizer, PacketJoiner, PacketParams

log = logging.getLogger(__name__)

DROP_STATUS_INTERVAL_S = 1.0
"""At most one status message per this many seconds says the device dropped data."""


@dataclass(frozen=True)
class CameraStreamConfig:
    """How the stream is cut and counted.

    Attributes:
        id: camera name in key expressions.
        packet_us: camera time per packet.
        max_packet_events: packets are cut earlier when they reach this many events.
        min_packet_events: consecutive packets are joined while they hold fewer events than this,
            up to ``max_packet_us`` of camera time (a low rate: fewer, longer packets, each costing
            its consumers a message, a decode and a call); 0: never joined.
        max_packet_us: camera time of a joined packet, at most.
        rate_interval_s: camera time per event-rate statistic.
        read_timeout_s: how long one read of the adapter may wait.
    """

    id: str = "cam0"
    packet_us: int = 1000
    max_packet_events: int = 65_536
    min_packet_events: int = 4000
    max_packet_us: int = 4000
    rate_interval_s: float = 0.1
    read_timeout_s: float = 0.05


class RateCounter:
    """Events, ON events and bytes per interval of camera time (counts from the packets: for native
    bytes, from the cutter's word scan)."""

    def __init__(self, interval_us: int) -> None:
        self.interval_us = interval_us
        self._end_us: int | None = None
        self.events = self.on = self.bytes = 0

    def add(self, packet: Packet) -> list[tuple[int, int, int, int]]:
        """Count a packet; return ``(t_end_us, events, on, bytes)`` of every interval it closes."""
        if self._end_us is None and packet.n_events == 0:
            return []  # the first interval starts with the first event (not a stream's leading time words)
        if self._end_us is None or packet.t_first_us >= self._end_us + self.interval_us:
            # first packet, or the stream jumped (data dropped): no rate for the gap, start afresh
            self._end_us = (packet.t_first_us // self.interval_us + 1) * self.interval_us
            self.events = self.on = self.bytes = 0
        closed = []
        while packet.t_last_us >= self._end_us:
            closed.append((self._end_us, self.events, self.on, self.bytes))
            self.events = self.on = self.bytes = 0
            self._end_us += self.interval_us
        self.events += packet.n_events
        self.on += packet.n_on
        self.bytes += len(packet.data)
        return closed


def load_packet_kernels(encodings: Iterable[str] = NATIVE_ENCODINGS) -> None:
    """Compile (the first run after installing: seconds) or load the kernels that encode events into
    packets of ``encodings`` and cut a device's own words into them: before a hardware camera opens,
    so that its first reads do not wait on them (its host buffer would fill meanwhile)."""
    for encoding in encodings:
        Packetizer(encoding, 1, 1).push(
            make_events(np.array([0, 1]), np.array([0, 0]), np.array([0, 0]), np.array([1, 0])), t_until_us=5000
        )
        if encoding in NATIVE_ENCODINGS:
            NativeCutter(encoding).push(bytes(8))


class CameraService:
    """Publishes one camera's stream until stopped or until the stream ends.

    ``start()`` declares the publishers; the adapter opens as ``run`` begins (a hardware camera is
    opened ahead by the rig, so what the device refuses stops the rig before anything else opens)
    and ``run`` closes it, whatever happens.
    """

    def __init__(self, bus: Bus, cfg: CameraStreamConfig, camera: Camera) -> None:
        self.bus = bus
        self.cfg = cfg
        self.camera = camera
        self.name = f"camera/{cfg.id}"
        self.packets = 0
        self.events = 0
        self.stream_id = 0  # drawn when the stream starts (EventPacket.stream_id)
        self.reached_eof = False
        self.ended = threading.Event()
        self.device_drops = 0  # drops the adapter reported (each CameraData.drops entry)
        self.drop_reason = ""  # the latest's
        self._pending_drops: list[DeviceDrop] = []  # reported, not yet on a packet
        self._drop_status_s = -DROP_STATUS_INTERVAL_S
        self._problems = ProblemLog(log, f"camera {cfg.id}")
        self._publishers: tuple[Publisher, Publisher, Publisher] | None = None  # events, status, rate

    def start(self) -> None:
        """Declare the events, status and rate publishers."""
        keys = self.bus.keys
        self._publishers = (
            self.bus.publisher(keys.camera_events(self.cfg.id), block=True, express=True),
            self.bus.publisher(keys.camera_status(self.cfg.id)),
            self.bus.publisher(keys.event_rate(self.cfg.id)),
        )

    def close(self) -> None:
        """Close the adapter, for a camera service that will not run (it may have been opened ahead)."""
        if not self.ended.is_set():
            self.ended.set()
            self.camera.close()

    def run(self, stop: threading.Event) -> None:
        if self._publishers is None:
            raise RuntimeError(f"{self.name}: start() first")
        events_pub, status_pub, rate_pub = self._publishers
        self.bus.declare_alive(self.name)
        self.stream_id = time.time_ns()  # names this stream: a restarted camera is another one
        info: CameraInfo | None = None
        state, message = "stopped", ""
        try:  # from the open on: whatever fails, the camera is closed and the status says so
            info = self.camera.open()
            log.info("camera %s: %s %dx%d %s", self.cfg.id, info.adapter, info.width, info.height, info.encoding)
            status_pub.put(self._status(info, "streaming"))
            self._stream(info, stop, events_pub, rate_pub)
            state = "eof" if self.reached_eof else state
        except Exception as exc:
            state, message = "error", str(exc)
            raise
        finally:
            self.camera.close()
            self._problems.flush(force=True)
            if info is not None:
                status_pub.put(self._status(info, state, message))
            self.ended.set()
            log.info("camera %s %s after %d packets, %d events", self.cfg.id, state, self.packets, self.events)

    def _stream(self, info: CameraInfo, stop: threading.Event, events_pub: Any, rate_pub: Any) -> None:
        """Read, packetize and publish until stopped or the end of the recording (``reached_eof``)."""
        packetizer = Packetizer(
            info.encoding, info.width, info.height, PacketParams(self.cfg.packet_us, self.cfg.max_packet_events)
        )
        load_packet_kernels([info.encoding])  # (loaded already where the rig was prepared)
        rates = RateCounter(int(self.cfg.rate_interval_s * 1e6))
        joiner = PacketJoiner(self.cfg.min_packet_events, self.cfg.max_packet_us)
        cutter: NativeCutter | None = None  # made at the first native bytes the adapter did not cut
        native = False  # (the packets are the device's own words)
        precut_horizon = -1  # of the packets the adapter cut

        def send(packets: list[Packet], arrival_ns: int, own_words: bool, end_of_stream: bool = False) -> None:
            """Count the packets as cut, then publish what the joiner lets go (all of it at the end)."""
            self._count(packets, rates, rate_pub)
            joined = joiner.push(packets, arrival_ns) + (joiner.flush() if end_of_stream else [])
            self._publish(joined, info, events_pub, end_of_stream=end_of_stream, native=own_words)

        while not stop.is_set():
            beat(self.name, f"{self.packets} packets, {self.events} events sent")
            try:
                data = self.camera.read(self.cfg.read_timeout_s)
            except EndOfStream:
                last = (cutter.flush() if cutter is not None else []) + packetizer.flush()
                horizon = max(packetizer.horizon_us, cutter.horizon_us if cutter is not None else -1, precut_horizon)
                last = last or [Packet(b"", horizon, horizon, 0, 0, 0, 0)]
                native = cutter is not None or precut_horizon >= 0
                send(last, time.time_ns(), native, end_of_stream=True)
                self.reached_eof = True
                return
            if data is None:  # a silent camera: what is held goes out (it waited a read's timeout at most)
                self._publish(joiner.flush(), info, events_pub, native=native)
                continue
            if data.drops:  # the packets before the drop go out first: the drop is said with the next one
                self._publish(joiner.flush(), info, events_pub, native=native)
                self._note_drops(data.drops, info)
            if data.packets and cutter is None and self._fits(data.packets):  # cut by the adapter
                precut_horizon = max(precut_horizon, *(p.t_last_us for p in data.packets))
                native = True
                send(data.packets, data.arrival_ns, native)
            elif data.raw is not None or data.packets:  # the device's own words: cut, not decoded
                raw = (
                    data.raw
                    if data.raw is not None
                    else b"".join(p.data[p.preamble_bytes :] for p in data.packets or ())
                )
                if cutter is None:
                    params = PacketParams(self.cfg.packet_us, self.cfg.max_packet_events)
                    cutter = NativeCutter(info.encoding, params, info.t_offset_us)
                    if data.packets:  # after packets the adapter cut: their state words go first
                        raw = data.packets[0].data[: data.packets[0].preamble_bytes] + raw
                native = True
                send(cutter.push(raw), data.arrival_ns, native)
            else:
                send(packetizer.push(data.events, data.triggers, data.t_until_us), data.arrival_ns, False)
        self._publish(joiner.flush(), info, events_pub, native=native)  # stopped: what it held

    def _fits(self, packets: list[Packet]) -> bool:
        """Whether packets an adapter cut are within this service's packet size (time and events)."""
        return all(
            p.n_events <= self.cfg.max_packet_events and p.t_last_us - p.t_first_us < self.cfg.packet_us
            for p in packets
        )

    def _count(self, packets: list[Packet], rates: RateCounter, rate_pub: Publisher) -> None:
        """Count the packets as cut (before they are joined) and publish the rates of the intervals they close."""
        for packet in packets:
            for t_end_us, n, n_on, n_bytes in rates.add(packet):
                interval_s = rates.interval_us * 1e-6
                rate_pub.put(
                    EventRate(self.cfg.id, t_end_us, interval_s, n, n / interval_s, n_on / n if n else 0.0, n_bytes)
                )

    def _publish(
        self,
        packets: list[tuple[Packet, int]],
        info: CameraInfo,
        events_pub: Publisher,
        end_of_stream: bool = False,
        native: bool = False,
    ) -> None:
        """Publish ``packets``, each with the arrival of its first events at the adapter (0: now)."""
        drop = self._drop_fields() if packets and self._pending_drops else {}
        for i, (packet, arrival_ns) in enumerate(packets):
            events_pub.put(
                EventPacket(
                    camera_id=self.cfg.id,
                    seq=self.packets,
                    t_first_us=packet.t_first_us,
                    t_last_us=packet.t_last_us,
                    n_events=packet.n_events,
                    width=info.width,
                    height=info.height,
                    encoding=info.encoding,
                    sent_ns=arrival_ns or time.time_ns(),
                    t_offset_us=packet.t_offset_us,
                    n_triggers=packet.n_triggers,
                    end_of_stream=end_of_stream and i == len(packets) - 1,
                    stream_id=self.stream_id,
                    preamble_bytes=packet.preamble_bytes,
                    native=native,
                    data=packet.data,
                    device_drops=self.device_drops,
                    **(drop if i == 0 else {}),
                )
            )
            self._pending_drops.clear()
            self.packets += 1
            self.events += packet.n_events

    def _note_drops(self, drops: tuple[DeviceDrop, ...], info: CameraInfo) -> None:
        """Count what the adapter reports lost, log it (rarely) and say so in a status (at most one
        per ``DROP_STATUS_INTERVAL_S``); the next packet carries it."""
        self._pending_drops.extend(drops)
        self.device_drops += len(drops)
        self.drop_reason = drops[-1].reason
        for drop in drops:
            self._problems.add("device drops", drop_text(drop))
        now = time.monotonic()
        if now - self._drop_status_s >= DROP_STATUS_INTERVAL_S and self._publishers is not None:
            self._drop_status_s = now
            self._publishers[1].put(self._status(info, "streaming", f"the camera dropped data: {drop_text(drops[-1])}"))

    def _drop_fields(self) -> dict[str, Any]:
        """The drop fields of the packet that follows the drops reported since the last packet."""
        drops = self._pending_drops
        units = {d.unit for d in drops}
        same = len(units) == 1
        reasons = list(dict.fromkeys(d.reason if same else drop_text(d) for d in drops))
        return {
            "drop_count": sum(d.count for d in drops) if same else 0,
            "drop_unit": units.pop() if same else "",
            "drop_reason": "; ".join(reasons),
        }

    def _status(self, info: CameraInfo, state: str, message: str = "") -> CameraStatus:
        return CameraStatus(
            self.cfg.id,
            state,
            info.adapter,
            info.width,
            info.height,
            info.encoding,
            dict(info.settings),
            message,
            self.packets,
            self.events,
            self.device_drops,
            self.drop_reason,
        )


def drop_text(drop: DeviceDrop) -> str:
    """A drop in one line: its reason and how much was lost."""
    if not drop.count:
        return drop.reason
    amount = f"{drop.count * 1e-6:g} s" if drop.unit == "us" else f"{drop.count} {drop.unit.replace('_', ' ')}"
    return f"{drop.reason} ({amount})"
