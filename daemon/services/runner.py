"""Host services in threads of one process: startup -> main loop -> shutdown (uvicorn's shape).

A service (:class:`Service`) is built without opening anything, then ``start()`` opens what it needs
(subscriptions, publishers, devices, files) and ``run(stop)`` works until ``stop`` is set (or its own
work is done, e.g. a replay at end of file). The runner starts every service, in the given order,
before any runs; one that cannot start stops the group with one error (:class:`StartError`) after
those already started are closed. The first SIGINT/SIGTERM asks every service to stop; a second
one forces the process out. Shutdown waits at most ``shutdown_timeout_s`` and says which services
it abandoned.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Protocol, TextIO, runtime_checkable

from flagtrack.daemon.errors import FlagtrackError
from flagtrack.daemon.services import sd_notify

log = logging.getLogger(__name__)


class Service(Protocol):
    """A long-running part of the daemon. Its constructor stores its configuration and opens nothing."""

    name: str

    def start(self) -> None:
        """Open what :meth:`run` needs (subscriptions, publishers, devices, files); raise if it cannot,
        having released what it opened itself. Called once, before ``run``, by the runner."""
        ...

    def run(self, stop: threading.Event) -> None:
        """Work until ``stop`` is set or the work is done; release everything before returning."""
        ...


@runtime_checkable
class Closable(Protocol):
    """A service whose :meth:`Service.start` opens more than bus entities (a device, a file), which
    the bus does not close with itself: ``close()`` releases them when ``run`` will not come (another
    service failed to start). Closing twice, or after ``run``, does nothing."""

    def close(self) -> None: ...


class StartError(FlagtrackError):
    """A service could not start; the services started before it were closed and none ran.

    Args:
        service: the service's name.
        cause: what its ``start()`` raised.
    """

    def __init__(self, service: str, cause: BaseException) -> None:
        self.service = service
        what = str(cause).strip().splitlines()[0] if str(cause).strip() else type(cause).__name__
        if not isinstance(cause, FlagtrackError):
            what = f"{type(cause).__name__}: {what}"
        super().__init__(f"the {service} service could not start: {what}")


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

    def __init__(
        self,
        services: Sequence[Service],
        stop_when_any_finishes: Sequence[str] = (),
        on_service_end: Callable[[str], object] | None = None,
    ) -> None:
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
                sd_notify.retire(service.name)  # an ended service no longer holds back the watchdog
                self._ended(service)
        except BaseException as exc:
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
        """Start every service (``start()``, in the given order), then run each in its own thread.

        A stop requested while they start (a signal) closes those started and runs none.

        Raises:
            StartError: a service's ``start()`` failed; those started before it are closed, none runs.
        """
        started: list[Service] = []
        for service in self.services:
            if self.stop.is_set():
                break
            try:
                service.start()
            except Exception as exc:
                self._close(started)
                self.stop.request(f"the {service.name} service could not start: {exc}")
                raise StartError(service.name, exc) from exc
            except BaseException:
                self._close(started)
                raise
            started.append(service)
        if self.stop.is_set():
            self._close(started)
            return
        for service in self.services:
            thread = threading.Thread(target=self._run_one, args=(service,), name=f"svc-{service.name}", daemon=True)
            self._threads[service.name] = thread
            thread.start()

    @staticmethod
    def _close(started: Sequence[Service]) -> None:
        """Close services that started but will not run, the last started first."""
        for service in reversed(started):
            if not isinstance(service, Closable):
                continue
            try:
                service.close()
            except Exception as exc:  # noqa: BLE001 - the start failure is the error to report
                log.warning("closing service %s: %s", service.name, exc)

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


CLEAR_LINE = "\r\x1b[K"
"""Carriage return and erase-to-end-of-line: a line printed on a terminal over a status line drawn in place."""


def is_terminal(stream: TextIO) -> bool:
    """Whether ``stream`` is a terminal (False for a closed or odd stream)."""
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # a closed or odd stream
        return False


def _say(line: str) -> None:
    """Write a line to stderr from a signal handler: straight to the file descriptor, since the handler
    may interrupt the main thread in the middle of its own write to ``sys.stderr`` (a second write
    into the same buffered stream raises "reentrant call", in the main thread, and the line is lost).
    On a terminal the line first clears the one under the cursor (a status line redrawn in place)."""
    with contextlib.suppress(OSError):
        os.write(2, (CLEAR_LINE * os.isatty(2) + line + "\n").encode())


SAME_SIGNAL_S = 0.25
"""A signal that repeats the first within this long is the same request, not a second one: GNU
``timeout`` (and ``kill`` of a process group) delivers it to the process twice, microseconds apart,
which forced the exit and left the tunnel to its watchdog."""


@contextlib.contextmanager
def stop_on_signals(
    stop: StopEvent,
    on_force: Callable[[], str] | None = None,
    on_signal: Callable[[int], None] | None = None,
) -> Iterator[StopEvent]:
    """While inside: the first SIGINT/SIGTERM asks ``stop`` (the work under way, a compile included,
    is never interrupted in the middle), the second (not the first repeated within
    :data:`SAME_SIGNAL_S`) forces the process out (exit 130), after saying
    the line ``on_force`` gives (what is left undone; "" for nothing); ``on_signal`` gets the count
    so far. The previous handlers are restored on the way out
    (uvicorn's ``capture_signals``)."""
    count = 0
    first: tuple[int, float] = (0, 0.0)  # (the first signal, when it came, monotonic s)

    def handler(signum: int, _frame: object) -> None:
        nonlocal count, first
        now = time.monotonic()
        if count == 1 and signum == first[0] and now - first[1] < SAME_SIGNAL_S:
            return  # the same signal twice at once (`timeout` signals the process, then its group): one
        count += 1
        if count == 1:
            first = (signum, now)
        if on_signal is not None:
            on_signal(count)
        name = signal.Signals(signum).name
        if count == 1:
            stop.request(f"stopped by {name}")
            _say(f"flagtrack: {name} received, stopping (again to force)")
            return
        _say(f"flagtrack: second {name}, forcing exit")
        if on_force is not None:
            with contextlib.suppress(Exception):  # (the exit is what was asked: nothing may stop it)
                left = on_force()
                if left:
                    _say(left)
        os._exit(130)

    previous = {signum: signal.signal(signum, handler) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old)


def capture_signals(
    group: ServiceGroup, on_force: Callable[[], str] | None = None
) -> contextlib.AbstractContextManager[StopEvent]:
    """While inside: the first SIGINT/SIGTERM stops the group gracefully, the second forces the process
    out (exit 130); the signals are counted in the group's report (:func:`stop_on_signals`)."""

    def counted(count: int) -> None:
        group.report.signal_count = count

    return stop_on_signals(group.stop, on_force, counted)


def run_services(
    services: Sequence[Service],
    *,
    stop_when_any_finishes: Sequence[str] = (),
    shutdown_timeout_s: float = 10.0,
    handle_signals: bool = True,
    on_force: Callable[[], str] | None = None,
    on_service_end: Callable[[str], object] | None = None,
) -> RunReport:
    """Start the services (in order), run them until a signal, a failure, or a finishing service;
    then shut down.

    ``on_service_end``: see :class:`ServiceGroup` (``up`` passes the bus's ``undeclare_alive``).
    Under systemd (``$NOTIFY_SOCKET``), READY/WATCHDOG/STATUS follow the services' own
    :func:`sd_notify.beat` calls (:mod:`.sd_notify`).

    Raises:
        StartError: a service could not start (those started before it are closed; none ran).
    """
    group = ServiceGroup(services, stop_when_any_finishes, on_service_end)
    signals = handle_signals and threading.current_thread() is threading.main_thread()
    with (
        capture_signals(group, on_force) if signals else contextlib.nullcontext(),
        sd_notify.watching([s.name for s in services]) as watchdog,
    ):
        group.start()
        try:
            group.wait()
        finally:
            if watchdog is not None:
                watchdog.stopping()
            report = group.shutdown(shutdown_timeout_s)
    return report
