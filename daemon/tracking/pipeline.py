"""A core tracker on two threads: decode, denoise and map in one, the chain update in the other.

:meth:`Tracker.prepare` (noise filter, mapping) and :meth:`Tracker.advance` (update clock, chain,
smoothing, Delta_RMS) touch disjoint state, and their compiled kernels release the GIL, so the
caller's thread decodes and prepares chunk k + 1 while a worker advances the chain on chunk k. The
results are those of ``Tracker.feed`` on the same chunks, in the same order (the updates of each
chunk go to ``emit`` in order, on the worker thread).
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.tracker import PreparedChunk, Tracker

_STOP = object()


class TrackerPipeline:
    """Feeds ``tracker`` on a worker thread; ``emit(batch, tag)`` receives each chunk's updates there.

    Use as a context manager; :meth:`finish` (or leaving the block) waits for the worker. An exception
    on the worker is raised again in the caller's thread at its next call.

    Args:
        tracker: the core tracker (only the worker calls its ``advance``; only the caller ``prepare``).
        emit: called on the worker with each chunk's updates and the tag given to :meth:`feed`.
        depth: prepared chunks waiting for the worker at most (bounds the memory).
        observe: called on the worker with each prepared chunk and the updates it completed, before
            ``emit`` (``reconstruct`` and the live tracker sample the chain's reach there).
    """

    def __init__(
        self,
        tracker: Tracker,
        emit: Callable[[CentrelineBatch, Any], None],
        depth: int = 4,
        observe: Callable[[PreparedChunk, CentrelineBatch], None] | None = None,
    ) -> None:
        self.tracker = tracker
        self._emit = emit
        self._observe = observe
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=depth)
        self._error: BaseException | None = None
        self._worker = threading.Thread(target=self._work, name="tracker-chain", daemon=True)
        self._worker.start()
        self._closed = False

    def feed(self, events: np.ndarray, complete_through_us: int | None = None, tag: Any = None) -> None:
        """Prepare ``events`` here and queue them for the chain update (blocks while ``depth`` wait)."""
        self._check()
        chunk = self.tracker.prepare(events)
        self._put((chunk, complete_through_us, tag))

    def emit_to(self, batches: list[CentrelineBatch]) -> None:
        """From now on, append the updates to ``batches`` (call between drains)."""
        self._emit = lambda batch, _tag: batches.append(batch)

    def abandon(self) -> None:
        """Stop the worker after what is queued, without raising its error (the tracker is dropped)."""
        if not self._closed:
            self._closed = True
            self._put(_STOP)
            self._worker.join()
        self._error = None

    def drain(self) -> None:
        """Wait until every chunk fed so far has been advanced and emitted; raise the worker's error."""
        self._queue.join()
        self._check()

    def finish(self, tag: Any = None) -> None:
        """End of stream: the worker emits the last updates (``Tracker.finish``) and stops."""
        self._put(("finish", None, tag))
        self.close()

    def close(self) -> None:
        """Stop the worker after the chunks queued (no ``finish``); raise its error, if any."""
        if not self._closed:
            self._closed = True
            self._put(_STOP)
            self._worker.join()
        self._check()

    def __enter__(self) -> TrackerPipeline:
        return self

    def __exit__(self, exc_type: object, *_: object) -> None:
        if exc_type is None:
            self.close()
        elif not self._closed:  # the caller failed: stop the worker, keep the caller's error
            self._closed = True
            self._put(_STOP)
            self._worker.join()

    def _put(self, item: Any) -> None:
        while self._worker.is_alive():
            try:
                self._queue.put(item, timeout=0.1)
                return
            except queue.Full:
                continue
        self._check()

    def _check(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def _work(self) -> None:
        tracker = self.tracker
        while True:
            item = self._queue.get()
            try:
                if item is _STOP:
                    return
                if self._error is not None:
                    continue  # drain: the caller sees the error at its next call
                chunk, complete_through_us, tag = item
                if isinstance(chunk, PreparedChunk):
                    batch = tracker.advance(chunk, complete_through_us)
                    if self._observe is not None:
                        self._observe(chunk, batch)
                else:
                    batch = tracker.finish()
                self._emit(batch, tag)
            except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
                self._error = exc
            finally:
                self._queue.task_done()
