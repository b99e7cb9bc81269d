"""The tracker service's packets to events: a run of consecutive packets decoded at once (packet by
packet when that fails), and a long run split between this thread and the chain's worker."""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.errors import FormatError
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import EventPacket
from flagtrack.daemon.tracking.pipeline import TrackerPipeline
from flagtrack.drivers.formats.packets import decode_packet

log = logging.getLogger("flagtrack.daemon.services.tracker")
PIPELINE_MIN_PACKETS = 8
"""Runs of at least this many packets (queued while the tracker worked) are tracked on two threads;
shorter ones, the usual case at a moderate rate, in this one (no hand-over between threads)."""
PIPELINE_GROUP_PACKETS = 4
"""Packets decoded and prepared together on the way to the chain's worker."""


def decode_run(run: list[EventPacket], problems: ProblemLog) -> tuple[list[np.ndarray], int]:
    """The events of a run: decoded at once, or packet by packet if that fails; and how many of its
    packets did not decode (each said in ``problems`` and left out)."""
    first = run[0]
    try:
        events, _ = decode_packet(
            first.encoding,
            b"".join(p.data for p in run),
            first.t_offset_us,
            source=f"packets {first.seq}-{run[-1].seq} of camera {first.camera_id}",
        )
        return [events], 0
    except FormatError:
        chunks, undecodable = [], 0
        for packet in run:
            source = f"packet {packet.seq} of camera {packet.camera_id}"
            try:
                chunks.append(decode_packet(packet.encoding, packet.data, packet.t_offset_us, source=source)[0])
            except FormatError as exc:
                undecodable += 1
                problems.add("undecodable packets", exc)
        return chunks, undecodable


def track_on_two_threads(
    pipeline: TrackerPipeline,
    run: list[EventPacket],
    decode: Callable[[list[EventPacket]], list[np.ndarray]],
    failed: Callable[[list[EventPacket], Exception], None],
    count: Callable[[int], None],
) -> list[CentrelineBatch]:
    """The updates of a long run, the work split: this thread decodes (``decode``), denoises and maps
    groups of :data:`PIPELINE_GROUP_PACKETS` packets while ``pipeline``'s worker updates the chain on
    the group before (the same updates as ``feed``). A group that does not decode goes to ``failed``;
    ``count`` is told the events of each group decoded. An error of the chain propagates."""
    batches: list[CentrelineBatch] = []
    pipeline.emit_to(batches)
    groups = [run[i : i + PIPELINE_GROUP_PACKETS] for i in range(0, len(run), PIPELINE_GROUP_PACKETS)]
    for g, group in enumerate(groups):
        try:
            chunks = decode(group)
        except Exception as exc:  # noqa: BLE001 - as a run tracked in one thread: counted, logged
            failed(group, exc)
            continue
        count(sum(len(c) for c in chunks))
        for i, events in enumerate(chunks):
            last = g == len(groups) - 1 and i == len(chunks) - 1
            pipeline.feed(events, run[-1].t_last_us if last else None)
    pipeline.drain()
    return batches


def say_failed(problems: ProblemLog, run: list[EventPacket], exc: Exception) -> None:
    """Say that the packets of ``run`` raised while decoded or tracked (a bug or data the core cannot
    take); the first such error is logged with its traceback at DEBUG."""
    log.debug("tracker: packets %d-%d failed", run[0].seq, run[-1].seq, exc_info=exc)
    problems.add(
        "packets that failed to track", f"packets {run[0].seq}-{run[-1].seq}: {type(exc).__name__}: {exc}", len(run)
    )


def say_dropped(problems: ProblemLog, dropped: int, said: int) -> int:
    """Say the packets the full queue dropped (``dropped`` in all) beyond the ``said`` already said;
    return how many are said now."""
    if dropped > said:
        problems.add(
            "packets dropped by the full queue",
            f"the queue dropped {dropped} packet(s) in all (the tracker falls behind the camera)",
            dropped - said,
        )
    return max(dropped, said)
