"""Host services in threads of one process: startup -> main loop -> shutdown (uvicorn's shape).

A service is any object with a ``name`` and ``run(stop: threading.Event) -> None`` that returns
when ``stop`` is set (or when its own work is done, e.g. a replay at end of file). The first
SIGINT/SIGTERM asks every service to stop; a second one forces the process out. Shutdown waits
at most ``shutdown_timeout_s`` and says which services it abandoned.
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

log = logging.getLogger(__name__)

_SWITCH_INTERVAL_S = 0.0005
# glibc mallopt parameters: M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD (the largest it takes, 32 MB)
_MALLOC_SETTINGS = ((-1, 256 << 20), (-2, 16 << 20), (-3, 32 << 20))


def keep_freed_memory() -> bool:
    """Ask glibc's allocator to keep freed memory for reuse rather than hand it back to the OS at once.

    Live services allocate and free the same few arrays for every packet. By default glibc returns
    memory once 128 KB lie free at the top of its heap, and maps arrays of growing sizes afresh, so
    the next packet's arrays page-fault again (3-4 faults per 1 ms packet in the replay camera, about
    3.7 µs each on the development VM). With these settings the heap keeps up to 256 MB free for
    reuse. Returns whether they took (False without glibc, or when the user set glibc's allocator
    through ``MALLOC_*`` or ``GLIBC_TUNABLES``: nothing changes).
    """
    if any(name.startswith("MALLOC_") for name in os.environ) or "glibc.malloc" in os.environ.get("GLIBC_TUNABLES", ""):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    return all(mallopt(param, value) == 1 for param, value in _MALLOC_SETTINGS)


class Service(Protocol):
    """A long-running part of the daemon."""

    name: str

    def run(self, stop: threading.Event) -> None:
        """Work until ``stop`` is set or the work is done; release everything before returning."""
        ...


class StopEvent(threading.Event):
    """The stop request shared by a group's services, with why it was made (``reason``)."""

    def __init__(self) -> None:
        super().__init__()
        self.reason = ""

    def request(self, reason: str) -> None:
        """Ask every service to stop, keeping the first reason given."""
        if not self.is_set():
            self.reason = reason
        self.set()


@dataclass
class RunReport:
    """How a group of services ended: ``errors`` by service name, ``abandoned`` still running at timeout."""

    finished: list[str] = field(default_factory=list)
    errors: dict[str, BaseException] = field(default_factory=dict)
    abandoned: list[str] = field(default_factory=list)
    signal_count: int = 0


class ServiceGroup:
    """Run services in threads; any service failing stops the others.

    Args:
        services: the services to run.
        stop_when_any_finishes: names of services whose normal end ends the group (e.g. a replay camera
            with ``--exit-at-eof``); by default the group runs until stopped.
        on_service_end: called with a service's name in its thread as soon as its ``run`` returns or
            raises, before the group reacts (the bus's ``undeclare_alive``: a service that ended is
            seen gone at once, not when the process's session closes).
    """

    def __init__(self, services: Sequence[Service], stop_when_any_finishes: Sequence[str] = (),
                 on_service_end: Callable[[str], object] | None = None) -> None:
        self.services = list(services)
        self.stop = StopEvent()
        self.report = RunReport()
        self._finishers = set(stop_when_any_finishes)
        self._on_end = on_service_end
        self._threads: dict[str, threading.Thread] = {}
        self._lock = threading.Lock()

    def _ended(self, service: Service) -> None:
        if self._on_end is None:
            return
        try:
            self._on_end(service.name)
        except Exception as exc:  # noqa: BLE001 - the service's own outcome matters more
            log.warning("after service %s ended: %s", service.name, exc)

    def _run_one(self, service: Service) -> None:
        try:
            try:
                service.run(self.stop)
            finally:
                self._ended(service)
        except BaseException as exc:  # noqa: BLE001 - reported, and every other service is stopped
            log.error("service %s failed: %s", service.name, exc, exc_info=log.isEnabledFor(logging.DEBUG))
            with self._lock:
                self.report.errors[service.name] = exc
            self.stop.request(f"the {service.name} service failed: {exc}")
            return
        with self._lock:
            self.report.finished.append(service.name)
        if service.name in self._finishers:
            log.info("service %s finished; stopping the others", service.name)
            self.stop.request(f"the {service.name} service finished")

    def start(self) -> None:
        """Start every service in its own thread (in the given order)."""
        for service in self.services:
            thread = threading.Thread(target=self._run_one, args=(service,), name=f"svc-{service.name}", daemon=True)
            self._threads[service.name] = thread
            thread.start()

    def wait(self, timeout_s: float | None = None) -> bool:
        """Wait until stop is requested or every service returned; True if all returned."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.stop.is_set():
            if all(not t.is_alive() for t in self._threads.values()):
                return True
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                return False
            self.stop.wait(0.05 if remaining is None else min(0.05, remaining))
        return all(not t.is_alive() for t in self._threads.values())

    def shutdown(self, timeout_s: float = 10.0) -> RunReport:
        """Ask every service to stop and join them; list those still running after ``timeout_s``."""
        self.stop.request("shutdown")
        deadline = time.monotonic() + timeout_s
        for name, thread in self._threads.items():
            thread.join(max(0.0, deadline - time.monotonic()))
            if thread.is_alive():
                self.report.abandoned.append(name)
        if self.report.abandoned:
            log.warning("shutdown timed out after %.1f s; abandoned: %s", timeout_s, ", ".join(self.report.abandoned))
        return self.report


def install_signal_handlers(group: ServiceGroup, on_force: Callable[[], None] | None = None) -> None:
    """First SIGINT/SIGTERM stops the group gracefully; the second forces the process out (exit 130)."""

    def handler(signum: int, _frame: object) -> None:
        group.report.signal_count += 1
        name = signal.Signals(signum).name
        if group.report.signal_count == 1:
            print(f"flagtrack: {name} received, stopping (again to force)", file=sys.stderr)
            group.stop.request(f"stopped by {name}")
            return
        print(f"flagtrack: second {name}, forcing exit", file=sys.stderr)
        if on_force is not None:
            on_force()
        os._exit(130)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def run_services(
    services: Sequence[Service],
    *,
    stop_when_any_finishes: Sequence[str] = (),
    shutdown_timeout_s: float = 10.0,
    handle_signals: bool = True,
    on_force: Callable[[], None] | None = None,
    on_service_end: Callable[[str], object] | None = None,
) -> RunReport:
    """Run services until a signal, a failure, or a finishing service; then shut down.

    ``on_service_end``: see :class:`ServiceGroup` (``up`` passes the bus's ``undeclare_alive``).
    """
    # Zenoh delivers on its own threads, which need the GIL to queue a message; with Python's default
    # 5 ms switch interval a busy service thread would hold messages back for up to 5 ms.
    sys.setswitchinterval(min(sys.getswitchinterval(), _SWITCH_INTERVAL_S))
    keep_freed_memory()
    group = ServiceGroup(services, stop_when_any_finishes, on_service_end)
    if handle_signals and threading.current_thread() is threading.main_thread():
        install_signal_handlers(group, on_force)
    group.start()
    try:
        group.wait()
    finally:
        report = group.shutdown(shutdown_timeout_s)
    return report
