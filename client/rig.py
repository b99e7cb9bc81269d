"""A rig as a notebook or a script sees it: its flag states, centrelines and event rates as they come
(iterate, or have a function called), and wind-speed requests to the tunnel's owner."""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from flagtrack.client.connect import client_bus, endpoint_bus, identity_of, rig_bus
from flagtrack.daemon.errors import FlagtrackError
from flagtrack.daemon.schema import CentrelineMessage, EventRate, FlagState, SpeedReply, SpeedRequest
from flagtrack.daemon.transport import Bus, BusConfig, Subscription

RESEND_S = 1.0
"""An unanswered request is sent again (same id: the supervisor answers it again, applies it once)."""


class NoAnswer(FlagtrackError):
    """The tunnel's owner did not answer a speed request in time (no supervisor, another mode's
    rig, or a bus that does not let this identity ask)."""


class Watch:
    """A function called with every message of one kind, in a thread of its own (:meth:`Rig.on_state`);
    :meth:`stop` it. An exception the function raises stops the watch and is kept in :attr:`error`."""

    def __init__(self, subscription: Subscription, function: Callable[[Any], object], name: str) -> None:
        self.subscription, self.function = subscription, function
        self.error: BaseException | None = None
        self.calls = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=f"flagtrack client {name}", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            message = self.subscription.recv(timeout_s=0.1)
            if message is None:
                continue
            try:
                self.function(message)
                self.calls += 1
            except Exception as exc:  # noqa: BLE001 - the caller's function: kept for the caller
                self.error = exc
                return

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop calling the function (waits for a call under way up to ``timeout_s``)."""
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)


class Rig:
    """A connection to a running rig (see the module); a context manager that closes it.

    Make one with :meth:`connect` (a rig file) or :meth:`at` (an endpoint). Live data comes through
    rings that keep the newest ``keep`` messages: a slow reader loses the oldest, never the newest.

    Args:
        bus: the client's bus (:func:`~flagtrack.client.connect.client_bus`).
        identity: the identity it asks for speeds in the name of (default: the one it presents).
        keep: messages of each kind kept for a reader, at most.
    """

    def __init__(self, bus: BusConfig, identity: str | None = None, keep: int = 1000) -> None:
        self.bus = Bus(bus)
        self.secured = bus.secured
        self.identity = identity or identity_of(bus)
        self.keep = keep
        self._subscriptions: dict[str, Subscription] = {}
        self._watches: list[Watch] = []
        self._lock = threading.Lock()
        self._replies: Subscription | None = None
        self._requests: Any = None

    @classmethod
    def connect(cls, rig_file: str | Path, identity: str | None = None, keep: int = 1000) -> Rig:
        """Join the bus of the rig of ``rig_file`` (where it listens, or its router), presenting
        ``identity`` on a secured bus (default: its ``bus.security.identity``)."""
        return cls(client_bus(rig_bus(rig_file), identity), identity, keep)

    @classmethod
    def at(cls, endpoint: str, namespace: str, *, identity: str | None = None, keep: int = 1000, **tls: Any) -> Rig:
        """Join the bus at ``endpoint`` (``tcp/HOST:PORT``; ``tls/HOST:PORT`` with ``ca=``, ``cert=``,
        ``key=`` files and ``identity=``) under ``namespace`` (``flagtrack/<rig>``)."""
        return cls(endpoint_bus(endpoint, namespace, identity=identity, **tls), identity, keep)

    # -- live data ---------------------------------------------------------------------------------

    def states(self, timeout_s: float | None = None) -> Iterator[FlagState]:
        """The flag's states as they come (:class:`~flagtrack.daemon.schema.FlagState`), until none
        has come for ``timeout_s`` (None: for ever)."""
        return self._iterate(self.bus.keys.flag_state(), FlagState, timeout_s)

    def centrelines(self, timeout_s: float | None = None) -> Iterator[CentrelineMessage]:
        """The tracker's centreline messages as they come (each a batch of updates)."""
        return self._iterate(self.bus.keys.centrelines(), CentrelineMessage, timeout_s)

    def rates(self, camera_id: str = "cam0", timeout_s: float | None = None) -> Iterator[EventRate]:
        """Camera ``camera_id``'s event rates as they come."""
        return self._iterate(self.bus.keys.event_rate(camera_id), EventRate, timeout_s)

    def next_state(self, timeout_s: float = 5.0) -> FlagState | None:
        """The next flag state to come (None if none within ``timeout_s``)."""
        return next(self.states(timeout_s), None)

    def on_state(self, function: Callable[[FlagState], object]) -> Watch:
        """Call ``function`` with every flag state, in a thread of its own, until the watch is stopped."""
        return self._watch(self.bus.keys.flag_state(), FlagState, function, "states")

    def on_centrelines(self, function: Callable[[CentrelineMessage], object]) -> Watch:
        """Call ``function`` with every centreline message, in a thread of its own."""
        return self._watch(self.bus.keys.centrelines(), CentrelineMessage, function, "centrelines")

    def on_rate(self, function: Callable[[EventRate], object], camera_id: str = "cam0") -> Watch:
        """Call ``function`` with every event rate of camera ``camera_id``, in a thread of its own."""
        return self._watch(self.bus.keys.event_rate(camera_id), EventRate, function, "rates")

    # -- the wind ----------------------------------------------------------------------------------

    def request_speed(self, speed_mps: float, timeout_s: float = 5.0, note: str = "") -> SpeedReply:
        """Ask the tunnel's owner (the supervisor, in mode ``control``) for ``speed_mps``; return its
        answer: ``accepted``, ``applied_mps`` (within ``tunnel.safety``), ``reason`` when they differ.

        Raises:
            NoAnswer: none within ``timeout_s``.
        """
        keys = self.bus.keys
        with self._lock:
            if self._replies is None:
                self._replies = self.bus.subscribe(keys.speed_reply(), SpeedReply, capacity=1024)
                self._requests = self.bus.publisher(keys.speed_request(self.identity), tag_source=True)
        request_id = uuid.uuid4().hex
        request = SpeedRequest(float(speed_mps), request_id, self.identity, note, time.time_ns())
        deadline = time.monotonic() + timeout_s
        self._wait_for_listener(self._requests, min(deadline, time.monotonic() + RESEND_S))
        while True:
            self._requests.put(request)  # again after a second unanswered: the first answer may have gone
            resend = time.monotonic() + RESEND_S  # before the supervisor heard of this subscription
            while (wait := min(resend, deadline) - time.monotonic()) > 0:
                reply = self._replies.recv(timeout_s=wait)
                if reply is not None and reply.request_id == request_id:
                    return reply
            if time.monotonic() >= deadline:
                break
        hint = (  # (a plain bus lets anyone ask: the identity is not why)
            f"is the supervisor in mode control, and is {self.identity!r} one of the rig's operators?"
            if self.secured
            else "is the rig running, with its supervisor in mode control, on this bus and namespace?"
        )
        raise NoAnswer(f"no answer to the request for {speed_mps:g} m/s within {timeout_s:g} s ({hint})")

    # -- the connection ----------------------------------------------------------------------------

    def close(self) -> None:
        """Stop the watches and leave the bus."""
        for watch in self._watches:
            watch.stop()
        self.bus.close()

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _subscription(self, key: str, kind: type) -> Subscription:
        with self._lock:
            if key not in self._subscriptions:
                self._subscriptions[key] = self.bus.subscribe(key, kind, capacity=self.keep, ring=True)
            return self._subscriptions[key]

    def _iterate(self, key: str, kind: type, timeout_s: float | None) -> Iterator[Any]:
        subscription = self._subscription(key, kind)
        while (message := subscription.recv(timeout_s=timeout_s)) is not None:
            yield message

    def _watch(self, key: str, kind: type, function: Callable[[Any], object], name: str) -> Watch:
        subscription = self.bus.subscribe(key, kind, capacity=self.keep, ring=True)  # its own: a reader apart
        watch = Watch(subscription, function, name)
        self._watches.append(watch)
        return watch

    @staticmethod
    def _wait_for_listener(publisher: Any, deadline: float) -> None:
        """Give the supervisor's subscription time to reach a fresh publisher (up to ``deadline``; through
        a router a peer may never hear of it, and its puts go through all the same)."""
        matching = getattr(getattr(publisher, "_publisher", None), "matching_status", None)
        while matching is not None and not matching.matching and time.monotonic() < deadline:
            time.sleep(0.01)
