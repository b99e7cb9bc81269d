"""Writes the tracker's centrelines from the bus to one HDF5 file (DESIGN.md layout)."""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.formats.centreline import CentrelineWriter

log = logging.getLogger(__name__)


class CentrelineFileService:
    """Appends every centreline message to ``path``; with ``exit_after_final`` it ends with the stream.

    A message whose samples or joints differ from the file's (the first message sets them) cannot
    go in the file: it is counted (``rejected``) and logged as a rate-limited summary, and the
    service goes on.

    Args:
        bus: the bus.
        path: output HDF5 file.
        attrs: root attributes (processing parameters, input file); ``units`` comes from the messages.
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
        self.subscription = bus.subscribe(bus.keys.centrelines(), CentrelineMessage, capacity=1_000_000,
                                          max_bytes=512 << 20)  # a few minutes of kHz updates behind the disk

    def run(self, stop: threading.Event) -> None:
        writer: CentrelineWriter | None = None
        shape: tuple[int, int] | None = None  # (n_s, N_j + 1) of the file
        pending: list = []
        last_write = time.monotonic()
        try:
            while not stop.is_set():
                msg = self.subscription.recv(timeout_s=0.05)
                if msg is not None:
                    if writer is None:
                        self.path.parent.mkdir(parents=True, exist_ok=True)
                        shape = (len(msg.s), msg.joints_x.shape[1])
                        writer = CentrelineWriter(self.path, msg.s, shape[1] - 1, {**self.attrs, "units": msg.units})
                    if (len(msg.s), msg.joints_x.shape[1]) == shape:
                        pending.append(msg.batch())
                        self.updates += len(msg.t_s)
                    else:
                        self.rejected += 1
                        self.problems.add("messages not written", f"message {msg.seq} has {len(msg.s)} samples and "
                                          f"{msg.joints_x.shape[1]} joints, the file {shape[0]} and {shape[1]}")
                if pending and (time.monotonic() - last_write > self.write_interval_s or (msg is not None and msg.final)):
                    writer.append(CentrelineBatch.concatenate(pending))  # type: ignore[union-attr]
                    pending, last_write = [], time.monotonic()
                if msg is not None and msg.final and self.exit_after_final:
                    break
                self.problems.flush()
        finally:
            if writer is not None:
                if pending:
                    writer.append(CentrelineBatch.concatenate(pending))
                writer.close()
                log.info("centrelines: %d updates written to %s", self.updates, self.path)
            self.problems.flush(force=True)
