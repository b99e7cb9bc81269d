"""A recording streamed through a core tracker into a centreline file (``flagtrack reconstruct``)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flagtrack.daemon.core.chain_reach import ChainReach
from flagtrack.daemon.core.denoise import BeyondAnySensorError
from flagtrack.daemon.errors import FormatError
from flagtrack.daemon.tracking.pipeline import TrackerPipeline
from flagtrack.daemon.tracking.reach import ReachSampler
from flagtrack.daemon.tracking.setup import TrackingSetup
from flagtrack.drivers.formats import open_events
from flagtrack.drivers.formats.centreline import CentrelineSink

log = logging.getLogger(__name__)

CHUNK_BYTES = 1 << 20
"""Bytes read per chunk: a chunk's arrays stay in the caches while both threads work on them (8 MB
chunks made a 10 M-event reconstruction ~25 % slower; docs/tracking.md)."""


@dataclass(frozen=True)
class ReconstructSummary:
    """What one reconstruction did."""

    updates: int
    events_in: int
    events_kept: int
    first_t_us: int | None
    last_t_us: int | None
    skipped_bytes: tuple[tuple[int, int], ...] = ()
    events_lost_at_most: int = 0
    lost_updates: int = 0
    stale_updates: int = 0
    reach: ChainReach | None = None

    def as_dict(self) -> dict[str, int | None]:
        """The summary as plain values (``--json`` outputs, batch rows)."""
        return {
            "updates": self.updates,
            "events_in": self.events_in,
            "events_kept": self.events_kept,
            "first_t_us": self.first_t_us,
            "last_t_us": self.last_t_us,
            "lost_updates": self.lost_updates,
            "stale_updates": self.stale_updates,
        }

    def verdicts(self) -> str:
        """The shares of found, lost and stale updates, as one line's words."""
        if not self.updates:
            return "no updates"
        found = self.updates - self.lost_updates - self.stale_updates
        shares = (f"{100 * n / self.updates:.1f} % {name}" for n, name in (
            (found, "found"), (self.lost_updates, "lost"), (self.stale_updates, "stale")
        ))  # fmt: skip
        return f"{', '.join(shares)} of {self.updates} updates"

    @property
    def mostly_unmeasured(self) -> bool:
        """Whether most updates are lost or stale (no flag where the geometry says it is)."""
        return self.updates == 0 or 2 * (self.lost_updates + self.stale_updates) > self.updates


def reconstruct_file(
    path: Path,
    output: Path,
    setup: TrackingSetup,
    *,
    progress: Callable[[int], None] | None = None,
    atomic: bool = False,
    strict: bool = False,
    check_sensor: Callable[[int, int], None] | None = None,
) -> ReconstructSummary:
    """Stream the recording ``path`` through a fresh tracker of ``setup`` into ``output``.

    Memory is bounded by the reader's chunk and the tracker's pending windows, not by the recording.
    Two threads: this one reads and denoises, a worker updates the chain (:class:`.TrackerPipeline`).

    Args:
        path: the recording (any format :func:`~flagtrack.drivers.formats.open_events` reads).
        output: the centreline file to write (overwritten).
        setup: the tracking set-up; its ``attrs`` go into the file with the input's name and format.
        progress: called with the bytes of ``path`` read so far.
        atomic: write ``output`` under a temporary name in its folder and rename it at the end, so
            ``output`` is a whole file or absent (``flagtrack batch``); a failure removes the temporary file.
        strict: refuse a damaged recording; by default a corrupt stretch is skipped (see
            :mod:`~flagtrack.drivers.formats.reader`) and the file's attributes ``input_skipped_bytes``
            ((n, 2) byte ranges) and ``input_events_lost_at_most`` say what was lost.
        check_sensor: called with the recording's sensor width and height (pixels) when its header
            gives them, before any event is read (it raises to refuse the set-up).

    Raises:
        FormatError: the recording cannot be read.
    """
    with open_events(path, chunk_bytes=CHUNK_BYTES, strict=strict) as reader:
        info = reader.info
        if check_sensor is not None and info.width and info.height:
            check_sensor(info.width, info.height)
        tracker = setup.new_tracker((info.width or 0, info.height or 0))
        attrs = {**setup.attrs, "input_file": str(Path(path).resolve()), "input_format": info.format,
                 "sensor_width_px": info.width, "sensor_height_px": info.height}  # fmt: skip
        with CentrelineSink(output, attrs, s=tracker.s, n_joints=setup.params.chain.n_joints, atomic=atomic) as sink:
            # this thread reads, decodes, denoises and maps; the pipeline's worker updates the chain
            # and writes the updates (the same results as tracker.feed on each chunk)
            sampler = ReachSampler(setup.params)
            with TrackerPipeline(tracker, lambda batch, _tag: sink.add(batch), observe=sampler.observe) as pipeline:
                for chunk in reader:
                    try:
                        pipeline.feed(chunk.events)
                    except BeyondAnySensorError as exc:
                        raise FormatError(str(exc), path=str(path), offset=chunk.byte_offset) from None
                    if progress is not None:
                        progress(chunk.byte_offset)
                if progress is not None:
                    progress(Path(path).stat().st_size)
                pipeline.finish()
            stats, reach = tracker.stats, sampler.reach()
            skipped = tuple((r.start, r.end) for r in reader.skipped)
            sink.set_attrs(
                {
                    "events_in": stats.events_in,
                    "events_kept": stats.events_kept,
                    "input_skipped_bytes": np.array(skipped, dtype=np.int64).reshape(-1, 2),
                    "input_events_lost_at_most": reader.events_lost_at_most,
                    "chain_reach": reach.reach if reach is not None else np.nan,
                }
            )
    if stats.events_out_of_order:
        log.warning("%d events were out of time order", stats.events_out_of_order)
    return ReconstructSummary(
        stats.updates,
        stats.events_in,
        stats.events_kept,
        stats.first_t_us,
        stats.last_t_us,
        skipped,
        reader.events_lost_at_most,
        stats.lost_updates,
        stats.stale_updates,
        reach,
    )
