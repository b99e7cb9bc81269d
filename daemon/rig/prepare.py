"""The slow one-off work of a rig's services, done before they start, while nothing runs in real time.

Each service's step is in the service table (:attr:`~flagtrack.daemon.rig.table.ServiceSpec.prepare`):

- compile (first run after installing: about a minute) or load the compiled kernels of the twin
  camera, the packets and the tracker: services that share a process would otherwise compile
  together, and the supervisor would not see the tracker come up within its start-up timeout;
  a hardware camera is not opened here, but its packets' kernels are loaded: the rig opens it
  next, and it streams into its host buffer from then on;
- a supervisor imports matplotlib (about a second, holding the GIL): drawing the summary figure at
  the end of a sweep would otherwise stall the twin camera of the same process;
- trigger events (a twin with a sync generator, a point sensor that reads the raw files' pulses)
  take kernels of their own: encoding them into packets and reading them back from a file
  (compiling those on a first run took 2 s, which the twin could not make up in real time).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from flagtrack.daemon.errors import FlagtrackError
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.rig.context import Preparation, warm_up_triggers
from flagtrack.daemon.rig.table import in_table_order
from flagtrack.daemon.tracking.setup import TrackingSetup

__all__ = ["Preparation", "prepare_services", "warm_up_triggers"]


def prepare_services(
    rig: RigConfig,
    names: Sequence[str],
    say: Callable[[str], None] = lambda text: None,
    *,
    tracker: TrackingSetup | None = None,
) -> None:
    """Do the slow one-off work of the services ``names`` before they start (``say`` tells the user when
    that includes loading or compiling kernels; ``tracker``: the rig's tracker setup, if the caller
    already made it).

    Raises:
        FlagtrackError: a step failed (a compile, an import): one line.
    """
    preparation = Preparation(rig, tuple(names), say, tracker)
    try:
        for spec in in_table_order(list(names)):
            if spec.prepare is not None:
                spec.prepare(preparation)
    except FlagtrackError:
        raise
    except Exception as exc:  # a failed compile or import: one line, as the services' own failures are
        raise FlagtrackError(f"preparing the services failed ({type(exc).__name__}: {exc})") from exc
