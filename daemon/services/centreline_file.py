"""Writes the tracker's centrelines from the bus to one HDF5 file (the layout of docs/tracking.md)."""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.transport import Bus, Subscription
from flagtrack.drivers.formats.centreline import CentrelineShapeError, CentrelineSink

log = logging.getLogger(__name__)


class CentrelineFileService:
    """Appends every centreline message to ``path``; with ``exit_after_final`` it ends with the stream.

    A message whose samples or joints differ from the file's (the first message sets them) cannot
    go in the file: it is counted (``rejected``) and logged as a rate-limited summary, and the
    service goes on. Messages missing from the tracker's sequence (a link cut, a router restart) are
    recorded as gaps: the file's attribute ``gaps_t_s`` ((n, 2) s, the last update before and the
    first after each).

    Args:
        bus: the bus.
        path: output HDF5 file.
        attrs: root attributes (processing parameters, calibration, input file); ``units`` and
            ``source`` come from the messages.
        exit_after_final: return after the message that ends the stream.
    """

    name = "centrelines"
    subscription: Subscription  # (opened by start())

    def __init__(self, bus: Bus, path: Path, attrs: dict[str, Any], exit_after_final: bool = False) -> None:
        self.bus = bus
        self.path = Path(path)
        self.attrs = attrs
        self.exit_after_final = exit_after_final
        self.write_interval_s = 0.5  # appends are batched: one HDF5 append per interval
        self.updates = 0
        self.rejected = 0
        self.gaps: list[list[float]] = []
        self._last: tuple[int, float | None] | None = None  # (seq, t_s of its last update) of the last message
        self.problems = ProblemLog(log, "centrelines")
        self._sink: CentrelineSink | None = None

    def start(self) -> None:
        """Subscribe to the centrelines; make the file's sink (the file is created at the first update)."""
        self.subscription = self.bus.subscribe(
            self.bus.keys.centrelines(), CentrelineMessage, capacity=1_000_000, max_bytes=512 << 20
        )  # a few minutes of kHz updates behind the disk
        self._sink = CentrelineSink(self.path, self.attrs, flush_interval_s=self.write_interval_s)

    def close(self) -> None:
        """Close the sink, for a service that will not run (it leaves no file: nothing came)."""
        if self._sink is not None:
            self._sink.close()

    def run(self, stop: threading.Event) -> None:
        sink = self._sink
        if sink is None:
            raise RuntimeError(f"{self.name}: start() first")
        try:
            while not stop.is_set():
                beat(self.name, f"{self.updates} updates written, {self.rejected} rejected")
                msg = self.subscription.recv(timeout_s=0.05)
                if msg is not None:
                    self._note_gap(msg, sink)
                    try:
                        sink.add(msg.batch(), units=msg.units, source=msg.source)
                        self.updates += len(msg.t_s)
                    except CentrelineShapeError as exc:
                        self.rejected += 1
                        self.problems.add(
                            "messages not written",
                            f"message {msg.seq} has {exc.got[0]} samples and "
                            f"{exc.got[1]} joints, the file {exc.want[0]} and {exc.want[1]}",
                        )
                    if msg.final:
                        sink.flush()
                        if self.exit_after_final:
                            break
                sink.flush_if_due()
                self.problems.flush()
        finally:
            sink.close()
            if self.gaps:
                log.warning("centrelines: %d gap(s) in the tracker's messages: %s s", len(self.gaps), self.gaps)
            if sink.opened:
                log.info("centrelines: %d updates written to %s", self.updates, self.path)
            self.problems.flush(force=True)

    def _note_gap(self, msg: CentrelineMessage, sink: CentrelineSink) -> None:
        """Record a gap when messages of the tracker's sequence are missing before ``msg``."""
        last = self._last
        t = [float(x) for x in msg.t_s[[0, -1]]] if len(msg.t_s) else None
        if last is not None and msg.seq > last[0] + 1:
            self.gaps.append([last[1] if last[1] is not None else float("nan"), t[0] if t else float("nan")])
            self.problems.add("gaps in the tracker's messages", f"messages {last[0] + 1}-{msg.seq - 1} missing")
            sink.set_attrs({"gaps_t_s": np.array(self.gaps, dtype=np.float64)})
        self._last = (msg.seq, t[1] if t else (last[1] if last else None))
