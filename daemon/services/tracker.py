"""The tracker service: one camera's packets in, centrelines out, with the same core as ``reconstruct``.

Packets are decoded one by one (each is self-contained), fed in order to a
:class:`~flagtrack.daemon.core.tracker.Tracker` built from the same ``tracker:`` config as the
offline command, so a replayed file gives the same centrelines as ``flagtrack reconstruct``.
Completed updates are published in batches (``batch_updates``, or sooner after
``max_batch_delay_s``); sequence gaps and malformed packets are counted and reported in the
status (about once a second): events/s, updates/s, lag behind the newest event; repeated problems
are logged as rate-limited summaries, never one line per packet.

A new camera stream starts a fresh core tracker: after the end of stream, or when packets of another
stream come (a camera restarted while the tracker ran: another ``stream_id``, see
:mod:`.sequence`), which is logged and counted in the status (``restarts``); a duplicate or late
packet of the stream is dropped and counted (``late_packets``). No packet stops the service: one whose bytes do
not decode is counted as malformed, and one the core cannot track (an exception) is counted too and
a fresh core tracker takes over.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.events import empty_events
from flagtrack.daemon.core.tracker import PreparedChunk
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import EventPacket, TrackerStatus
from flagtrack.daemon.services.lost_count import LostCount
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.services.sequence import Arrival, PacketSequence, packet_problem
from flagtrack.daemon.services.tracker_budget import LatencyBudget, ShedSpans, gather
from flagtrack.daemon.services.tracker_decode import (
    PIPELINE_MIN_PACKETS,
    decode_run,
    say_dropped,
    say_failed,
    track_on_two_threads,
)
from flagtrack.daemon.services.tracker_outbox import CentrelineOutbox, updates_source_ns
from flagtrack.daemon.tracking.pipeline import TrackerPipeline
from flagtrack.daemon.tracking.reach import LiveReach
from flagtrack.daemon.transport import Bus, Publisher, Subscription
from flagtrack.drivers.formats.packets import decode_packet

log = logging.getLogger(__name__)

SHED = "packets shed"
"""The kind of the console line that says the live tracker skips packets (its problem log)."""
_NO_NS = np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class TrackerServiceConfig:
    """How the live tracker publishes.

    Attributes:
        camera_id: the camera tracked.
        batch_updates: updates per centreline message (at most).
        max_batch_delay_s: publish a smaller batch after this long (when no packet is waiting, the
            updates are published at once).
        status_interval_s: period of the status message.
        queue_packets: packets held while the tracker catches up (beyond: the oldest are dropped, counted).
        queue_bytes: bytes of packets held (beyond: the oldest are dropped, counted, and the tracker
            goes on from the newest). 256 MB is about 20 s of a 6 Mev/s camera (EVT 3.0 takes ~2
            bytes per event): a live tracker that far behind shows it in its status' lag; a long
            file replayed as fast as possible (``up --replay --speed 0``) into a tracker slower than
            the replay could go beyond it, and then loses packets (counted as dropped).
        exit_at_end_of_stream: stop after the camera's end of stream (a replayed file).
        max_coalesce: packets already queued are tracked together, up to this many.
        gather_ms: a call holding fewer than ``gather_events`` events and less than this much
            camera time waits for more packets until this long after its oldest packet reached
            the camera: at a low rate, packets are tracked and published a few together instead
            of one by one (the per-call work is most of the tracker's cost there); 0: every
            packet at once.
        gather_events: a call with this many events waits for no more.
        reserve_mev_s: the event rate (Mev/s) whose buffers each core tracker allocates before its
            stream (its windows and look-back, at most 65 536 events, with twice as much free room:
            29 MB at 20 Mev/s): growing them in the first
            windows of a fast stream costs those windows tens of milliseconds; 0: grow as events come.
    """

    camera_id: str = "cam0"
    batch_updates: int = 64
    max_batch_delay_s: float = 0.002
    status_interval_s: float = 1.0
    queue_packets: int = 1_000_000
    queue_bytes: int = 256 << 20
    exit_at_end_of_stream: bool = False
    max_coalesce: int = 64
    gather_ms: float = 4.0
    gather_events: int = 20_000
    reserve_mev_s: float = 20.0

    def __post_init__(self) -> None:
        if not 0 <= self.reserve_mev_s <= 1000:
            raise ValueError(f"reserve_mev_s must be from 0 to 1000 (Mev/s), got {self.reserve_mev_s}")


def warm_up_kernels(tracker_factory: Any) -> None:
    """Run the packetizer, the decoder and a core tracker once on a tiny synthetic stream, so that
    loading the compiled kernels (about a second; on a first run, compiling them: tens of seconds)
    happens before the first packet, not while packets queue up."""
    from flagtrack.daemon.core.events import make_events
    from flagtrack.drivers.formats.packets import Packetizer

    n = 400
    t = np.arange(n, dtype=np.int64) * 10
    events = make_events(t, 10 + (np.arange(n) % 20), 10 + (np.arange(n) // 20), np.arange(n) % 2)
    packetizer = Packetizer("evt3", 64, 64)
    for packet in packetizer.push(events) + packetizer.flush():
        decoded, _ = decode_packet("evt3", packet.data, packet.t_offset_us)
        tracker = tracker_factory()
        tracker.feed(decoded)
        tracker.finish()


class TrackerService:
    """Tracks one camera live. ``tracker_factory`` builds a fresh core Tracker (one per stream);
    ``max_lag_ms``: the latency budget (:mod:`.tracker_budget`), None to track every packet however late."""

    name = "tracker"
    packets_sub: Subscription  # (opened by start())
    _lines_pub: Publisher
    _status_pub: Publisher

    def __init__(
        self,
        bus: Bus,
        cfg: TrackerServiceConfig,
        tracker_factory: Any,
        units: str = "px",
        max_lag_ms: float | None = None,
    ) -> None:
        self.bus = bus
        self.cfg = cfg
        self.tracker_factory = tracker_factory
        self.units = units
        self.tracker = tracker_factory()
        self.packets = 0
        self.missing_packets = 0
        self.undecodable_packets = 0  # well-formed messages whose EVT bytes are corrupt
        self.updates = 0
        self.lost = LostCount()  # updates that did not find the flag, and their stretches
        self.events = 0
        self.streams_ended = 0
        self.restarts = 0  # new streams that began without the end of the last one
        self.stream = 0  # number of the stream being tracked (CentrelineMessage.stream)
        self.problems = ProblemLog(log, "tracker")
        self._drops_logged = 0
        self._sequence = PacketSequence()
        self.late_packets = 0  # duplicates and late packets of the stream, dropped
        self._outbox = CentrelineOutbox(self.name, units, cfg.batch_updates, cfg.max_batch_delay_s)
        self._pipeline: TrackerPipeline | None = None  # the chain's worker thread, made on first use
        self.budget = LatencyBudget(max_lag_ms) if max_lag_ms is not None else None
        self.shed = ShedSpans()  # packets skipped for the budget, and the camera time they held
        self._held: EventPacket | None = None  # received, left for the next call (no room in the budget)
        self._reach: LiveReach | None = None  # the chain's length against its events (made on first use)

    def start(self) -> None:
        """Subscribe to the camera's packets; declare the centreline and status publishers."""
        keys = self.bus.keys
        self.packets_sub = self.bus.subscribe(
            keys.camera_events(self.cfg.camera_id),
            EventPacket,
            capacity=self.cfg.queue_packets,
            max_bytes=self.cfg.queue_bytes,
            ring=True,
        )
        self._lines_pub = self.bus.publisher(keys.centrelines(), block=True, express=True)
        self._status_pub = self.bus.publisher(keys.tracker_status())

    def warm_up(self) -> None:
        """Load the compiled kernels and allocate the tracker's buffers before the first packet
        (see :func:`warm_up_kernels`, ``reserve_mev_s``)."""
        warm_up_kernels(self.tracker_factory)
        self._reserve(self.tracker)

    def _reserve(self, tracker: Any) -> Any:
        if self.cfg.reserve_mev_s > 0:
            tracker.preallocate(self.cfg.reserve_mev_s * 1e6)
        return tracker

    def _fresh_tracker(self, ended: Any = None) -> Any:
        """A new core tracker for the next stream, its buffers allocated: those of ``ended`` when
        given, a tracker whose stream ended and that no thread uses (memory already written, where
        fresh memory costs the new stream's first windows up to a few hundred ms)."""
        tracker = self.tracker_factory()
        if ended is not None:
            tracker.take_buffer_of(ended)
        return self._reserve(tracker)

    def run(self, stop: threading.Event) -> None:
        self.warm_up()
        if self.budget is not None:
            self.budget.ready_ns = time.time_ns()
        packets, status_pub = self.packets_sub, self._status_pub
        self.bus.declare_alive(self.name)
        last_status = time.monotonic()
        window = {"events": 0, "updates": 0, "shed_events": 0, "t": last_status}
        lag_s = 0.0
        # with updates pending, wake up in time to publish them; otherwise only for the status
        idle_wait_s = max(self.cfg.max_batch_delay_s, min(self.cfg.status_interval_s, 0.1))
        try:
            while not stop.is_set():
                beat(self.name, f"{self.events} events, {self.updates} updates, {self.missing_packets} packets missing")
                packet, self._held = self._held, None
                if packet is None:
                    packet = packets.recv(timeout_s=self.cfg.max_batch_delay_s if len(self._outbox) else idle_wait_s)
                if packet is not None:
                    batch, shed, self._held = gather(packet, packets.recv, self.budget, self.cfg)
                    start_ns, tracked = time.perf_counter_ns(), self.events  # (the work, not the wait)
                    lag_s = self.handle(batch, shed)
                    if batch[-1].end_of_stream and self.cfg.exit_at_end_of_stream:
                        break
                # nothing more queued: publish now (latency); under load, batches fill up instead
                self._publish_if_due(force=len(packets.channel) == 0 and self._held is None)
                if packet is not None and self.budget is not None:
                    self.budget.measured(self.events - tracked, time.perf_counter_ns() - start_ns)
                now = time.monotonic()
                if now - last_status >= self.cfg.status_interval_s:
                    status_pub.put(tracker_status(self, "tracking", window, now, lag_s))
                    window = {"events": self.events, "updates": self.updates, "shed_events": self.shed.events, "t": now}
                    last_status = now
                    self._count_drops()
                    self.problems.flush()
        finally:
            if self._pipeline is not None:
                self._pipeline.abandon()
            self._publish_if_due(force=True)
            status_pub.put(tracker_status(self, "stopped", window, time.monotonic(), lag_s))
            self._count_drops()
            self.problems.flush(force=True)

    def handle(self, packets: list[EventPacket], shed: Collection[int] = ()) -> float:
        """Decode and track packets (in order) but those at the indices ``shed`` (skipped: the latency budget);
        return the lag (s) from the last one's arrival at the camera. Packets that queued up are decoded
        and fed together (a stream's packets concatenate into one stream; the core's results do not
        depend on how it is cut), so the per-packet cost does not limit the rate."""
        run: list[EventPacket] = []
        for index, packet in enumerate(packets):
            previous = self._sequence.next_seq
            continues = self._sequence.classify(packet.seq, packet.stream_id)[0] is not Arrival.NEW_STREAM
            problem = packet_problem(packet, self._sequence.horizon_us if continues else None)
            if problem is not None and not packet.end_of_stream:  # left out: the stream is as if it never came
                self.undecodable_packets += 1
                self.problems.add("packets whose times cannot be placed", problem)
                continue
            arrival, missing = self._sequence.arrive(packet.seq, packet.stream_id)
            if arrival is Arrival.LATE:  # a duplicate, or a packet of this stream already passed
                self.late_packets += 1
                self.problems.add(
                    "late or duplicate packets", f"packet {packet.seq} came after {(previous or 0) - 1}: dropped", 1
                )
                continue
            if arrival is not Arrival.NEXT or problem is not None:
                self._track_run(run)  # a gap breaks the stream: what came before is decoded apart
                run = []
                if arrival is Arrival.NEW_STREAM:
                    self._new_stream(packet, previous)
                elif arrival is Arrival.GAP:
                    self.missing_packets += missing
                    self.problems.add(
                        "packets missing", f"{missing} packet(s) missing before seq {packet.seq}", missing
                    )
            if problem is not None:  # its times cannot be placed (hours off): its end of stream still counts
                self.undecodable_packets += 1
                self.problems.add("packets whose times cannot be placed", problem)
                horizon = self._sequence.horizon_us
                last_us = horizon if horizon is not None else packet.t_first_us
                packet = dataclasses.replace(packet, data=b"", n_events=0, t_last_us=last_us)
            self.packets += 1
            if index in shed and problem is None and not packet.end_of_stream:
                self._track_run(run)
                run = []
                self._skip(packet)
                continue
            self._sequence.follow_horizon(packet.t_last_us)
            if run and packet.encoding != run[0].encoding:
                self._track_run(run)
                run = []
            run.append(packet)
            if packet.end_of_stream:
                self._track_run(run, end_of_stream=True)
                run = []
        self._track_run(run)
        return max(0.0, time.time_ns() - packets[-1].sent_ns) * 1e-9

    def _skip(self, packet: EventPacket) -> None:
        """Shed ``packet`` undecoded: its camera time is a gap in the core's windows, and the updates
        after it say how much of their time it was."""
        horizon = self._sequence.horizon_us
        lo_us = horizon + 1 if horizon is not None else packet.t_first_us
        self._sequence.follow_horizon(packet.t_last_us)
        self.shed.add(lo_us, packet.t_last_us + 1, packet.n_events)
        self.problems.add(SHED, f"packet {packet.seq} ({packet.n_events} events) not tracked, to stay within the "
                          "latency budget (the recording keeps every packet)")  # fmt: skip
        try:
            self.tracker.skip_to(packet.t_last_us + 1)
        except Exception as exc:  # noqa: BLE001 - as any chunk the core cannot take: a fresh tracker goes on
            self._failed([packet], exc)
            self.tracker = self._fresh_tracker()

    def _new_stream(self, packet: EventPacket, previous_next_seq: int | None) -> None:
        """Another stream began (the camera restarted). The updates of the old stream are
        published, and a fresh core tracker takes the new one (the old one's unfinished windows,
        cut short by the restart, are dropped)."""
        self._publish_if_due(force=True)
        self.restarts += 1
        self.problems.add(
            "camera restarts",
            f"packet {packet.seq} of stream {packet.stream_id} after packet "
            f"{(previous_next_seq or 0) - 1}: a new stream of camera {packet.camera_id}, "
            "tracked afresh",
            1,
        )
        self.tracker = self._fresh_tracker(ended=self.tracker)  # (the runs before were tracked to the end)
        self.stream += 1
        self.shed.end_stream()

    def _track_run(self, run: list[EventPacket], end_of_stream: bool = False) -> None:
        """Decode consecutive packets as one stream (one by one if that fails) and track them."""
        if not run:
            return
        if len(run) >= PIPELINE_MIN_PACKETS:  # packets queued up (a busy camera): both cores at work
            self._track_run_on_two_threads(run, end_of_stream)
            return
        try:
            chunks = self._decode(run)
        except Exception as exc:  # noqa: BLE001 - a packet must not stop the service: counted, logged
            chunks = []
            self._failed(run, exc)
        self.events += sum(len(c) for c in chunks)
        self._track(chunks, run, end_of_stream)

    def _decode(self, run: list[EventPacket]) -> list[np.ndarray]:
        """The events of a run (:func:`.tracker_decode.decode_run`); packets that do not decode are counted."""
        chunks, undecodable = decode_run(run, self.problems)
        self.undecodable_packets += undecodable
        return chunks

    def _track_run_on_two_threads(self, run: list[EventPacket], end_of_stream: bool) -> None:
        """Track a long run as :meth:`_track_run` does, on two threads (:func:`.tracker_decode.track_on_two_threads`)."""
        try:
            batches = track_on_two_threads(
                self._pipeline_of(self.tracker), run, self._decode, self._failed, self._count
            )
        except Exception as exc:  # noqa: BLE001 - the core choked on this data: a fresh tracker goes on
            self._failed(run, exc)
            self.tracker = self._fresh_tracker()
            batches = []
        self._track(batches, run, end_of_stream, advanced=True)

    def _count(self, events: int) -> None:
        self.events += events

    def _pipeline_of(self, tracker: Any) -> TrackerPipeline:
        """The worker of ``tracker`` (a new tracker, after a restart or a failure, gets a new one)."""
        if self._pipeline is None or self._pipeline.tracker is not tracker:
            if self._pipeline is not None:
                self._pipeline.abandon()
            self._pipeline = TrackerPipeline(tracker, lambda batch, _tag: None, observe=self._judge_reach)
        return self._pipeline

    def _track(self, chunks: list, run: list[EventPacket], end_of_stream: bool, advanced: bool = False) -> None:
        """Feed the decoded chunks (the last with the run's horizon: the camera says every event up
        to it has come, so the windows ending there are complete now) and queue the updates;
        ``advanced``: ``chunks`` are the updates already (tracked on two threads)."""
        tracker = self.tracker
        batch: CentrelineBatch | None = None
        source_ns = _NO_NS
        try:
            batches = (
                chunks
                if advanced
                else [
                    self._feed(tracker, events, run[-1].t_last_us if i == len(chunks) - 1 else None)
                    for i, events in enumerate(chunks)
                ]
            )
            if end_of_stream:
                batches.append(tracker.finish())
            if batches:
                batch = batches[0] if len(batches) == 1 else CentrelineBatch.concatenate(batches)
                source_ns = updates_source_ns(batch, run, tracker.params.schedule)
        except Exception as exc:  # noqa: BLE001 - the core choked on this data: a fresh tracker goes on
            batch = None
            self._failed(run, exc)
            self.tracker = self._fresh_tracker()
        if end_of_stream:
            self.streams_ended += 1
            self.tracker = self._fresh_tracker(ended=self.tracker)
            self._sequence.restart()
        if batch is not None:
            self._add(batch, source_ns)
        if end_of_stream:
            self._publish_if_due(force=True, final=True)
            self.stream += 1
            self._live_reach().restart()
            self.lost.end_stream()
            self.shed.end_stream()

    def _feed(self, tracker: Any, events: np.ndarray, horizon_us: int | None) -> CentrelineBatch:
        """``tracker.feed``; a chunk the chain's reach samples is prepared apart (the same result)."""
        if len(events) == 0 or not self._live_reach().due(int(events["t"][-1])):
            return tracker.feed(events, horizon_us)
        prepared = tracker.prepare(events)
        batch = tracker.advance(prepared, horizon_us)
        self._judge_reach(prepared, batch)
        return batch

    def _judge_reach(self, chunk: PreparedChunk, batch: CentrelineBatch) -> None:
        """Sample the chain's reach; say, once a span, a chain off the flag's length."""
        reach = self._live_reach()
        misfit = reach.observe(chunk, batch)
        if misfit:
            span = f"{reach.span_s:g} s"
            log.warning("tracker: over the last %s, %s: check tracker.length (and the root)", span, misfit)

    @property
    def chain_reach(self) -> float:
        """The chain's reach over the last span judged (a fraction of L), NaN before the first
        (:attr:`.LiveReach.last`)."""
        return self._reach.last if self._reach is not None else math.nan

    def _live_reach(self) -> LiveReach:
        if self._reach is None:
            self._reach = LiveReach(self.tracker.params, self.units)
        return self._reach

    def _failed(self, run: list[EventPacket], exc: Exception) -> None:
        """Count the packets of a run that raised while decoded or tracked (:func:`.tracker_decode.say_failed`)."""
        self.undecodable_packets += len(run)
        say_failed(self.problems, run, exc)

    def _add(self, batch: CentrelineBatch, source_ns: np.ndarray) -> None:
        if len(batch) == 0:
            return
        shed = self.shed.fractions(batch.t_s, self.tracker.params.schedule.window_ends_us)
        if shed is not None:  # the first updates after skipped packets
            batch = dataclasses.replace(batch, shed=shed)
        self.updates += len(batch)
        self.lost.add(batch.lost)
        if self._outbox.add(batch, source_ns):
            self._publish_if_due(force=True)

    def _publish_if_due(self, force: bool, final: bool = False) -> None:
        """Publish the pending updates if the batch is full, old enough, or ``force``; ``final`` ends a stream."""
        if force or final or self._outbox.due():
            self._outbox.publish(self._lines_pub, self.stream, final, lambda: self.tracker.feed(empty_events()))

    @property
    def malformed_packets(self) -> int:
        """Packets dropped as malformed: bad messages and packets whose EVT bytes do not decode or track."""
        return self.packets_sub.malformed + self.undecodable_packets

    @property
    def dropped_packets(self) -> int:
        """Packets the full queue turned away (each also shows as a sequence gap)."""
        return self.packets_sub.channel.dropped

    def _count_drops(self) -> None:
        """Say the packets the queue dropped since the last call (a rate-limited summary)."""
        self._drops_logged = say_dropped(self.problems, self.dropped_packets, self._drops_logged)


def tracker_status(
    svc: TrackerService, state: str, window: dict[str, float], now: float, lag_s: float
) -> TrackerStatus:
    """The status message of ``svc``: its counters, and its rates over ``window`` (the counters then, and when)."""
    elapsed = max(now - window["t"], 1e-9)
    return TrackerStatus(
        source=svc.name,
        state=state,
        events_per_s=(svc.events - window["events"]) / elapsed,
        updates_per_s=(svc.updates - window["updates"]) / elapsed,
        lag_s=lag_s,
        packets=svc.packets,
        missing_packets=svc.missing_packets,
        malformed_packets=svc.malformed_packets,
        dropped_packets=svc.dropped_packets,
        restarts=svc.restarts,
        late_packets=svc.late_packets,
        lost_updates=svc.lost.updates,
        lost_stretches=svc.lost.stretches,
        shed_fraction=_fraction(svc.shed.events - window["shed_events"], svc.events - window["events"]),
        shed_packets=svc.shed.packets,
        shed_events=svc.shed.events,
        chain_reach=svc.chain_reach if math.isfinite(svc.chain_reach) else -1.0,
    )


def _fraction(shed: float, tracked: float) -> float:
    """The share of ``shed`` in ``shed + tracked`` (0 when both are 0)."""
    return shed / (shed + tracked) if shed > 0 else 0.0
