"""Writes the tracker's centrelines from the bus to one HDF5 file (DESIGN.md layout)."""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any

from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.formats.centreline import CentrelineShapeError, CentrelineSink

log = logging.getLogger(__name__)


class CentrelineFileService:
    """Appends every centreline message to ``path``; with ``exit_after_final`` it ends with the stream.

    A message whose samples or joints differ from the file's (the first message sets them) cannot
    go in the file: it is counted (``rejected``) and logged as a rate-limited summary, and the
    service goes on.

    Args:
        bus: the bus.
        path: output HDF5 file.
        attrs: root attributes (processing parameters, calibration, input file); ``units`` and
            ``source`` come from the messages.
        exit_after_final: return after the message that ends the stream.
    """

    name = "centrelines"

    def __init__(self, bus: Bus, path: Path, attrs: dict[str, Any], exit_after_final: bool = False) -> None:
        self.bus = bus
        self.path = Path(path)
        self.attrs = attrs
        self.exit_after_final = exit_after_final
        self.write_interval_s = 0.5  # appends are batched: one HDF5 append per interval
        self.updates = 0
        self.rejected = 0
        self.problems = ProblemLog(log, "centrelines")
        self.subscription = bus.subscribe(
            bus.keys.centrelines(), CentrelineMessage, capacity=1_000_000, max_bytes=512 << 20
        )  # a few minutes of kHz updates behind the disk

    def run(self, stop: threading.Event) -> None:
        sink = CentrelineSink(self.path, self.attrs, flush_interval_s=self.write_interval_s)
        try:
            while not stop.is_set():
                beat(self.name, f"{self.updates} updates written, {self.rejected} rejected")
                msg = self.subscription.recv(timeout_s=0.05)
                if msg is not None:
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
            if sink.opened:
                log.info("centrelines: %d updates written to %s", self.updates, self.path)
            self.problems.flush(force=True)
