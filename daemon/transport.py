"""Zenoh transport: one session per process, publishers and subscribers of schema messages.

The only module that imports zenoh. Subscribers never do work in Zenoh's callback: samples go
into a channel (a bounded FIFO for commands and lossless data, a ring that keeps the newest for live
views) that the service reads from its own loop with a timeout.
"""

from __future__ import annotations

import collections
import json
import logging
import re
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Literal

import zenoh

from flagtrack.daemon.errors import ConfigError, SchemaError
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import Keys, decode, encode
from flagtrack.daemon.security.config import REDACTED, SecurityConfig, zenoh_security
from flagtrack.daemon.security.names import identifier_problem

log = logging.getLogger(__name__)

QUEUE_BYTES = 64 << 20
"""What a subscription holds at most when it names no bound (a forged flood of large messages must
not grow a queue without end)."""


@dataclass(frozen=True)
class BusConfig:
    """How this process joins the bus.

    Attributes:
        namespace: key prefix, ``flagtrack/<rig>``.
        mode: Zenoh mode: ``peer`` (embedded default), ``client`` (through a router) or ``router``.
        listen: endpoints to listen on, e.g. ``tcp/127.0.0.1:7447``.
        connect: endpoints to connect to (a router, or another peer).
        multicast_scouting: discover peers by UDP multicast (off by default: loopback only).
        shared_memory: let Zenoh pass large messages between processes of one host through shared
            memory (off by default: its set-up on the first large message from each peer stalls the
            receiver for 20-30 ms, see docs/live.md; off, every message goes through the socket).
        security: mutual TLS, user/password and access control (``bus.security``, see
            :mod:`flagtrack.daemon.security.config`); with ``tls``, every endpoint must be ``tls/``.
        access_control: the Zenoh access-control section enforced by this session, made from the
            rig by :func:`flagtrack.daemon.security.acl.access_control` when ``security.acl`` is on
            (not a key of the rig file).
        max_message_bytes: the largest message this session takes (Zenoh's default is 1 GiB, which a
            peer could make it allocate; the largest of flagtrack's are ~1 MB).
    """

    namespace: str = "flagtrack/default"
    mode: Literal["peer", "client", "router"] = "peer"
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    shared_memory: bool = False
    security: SecurityConfig | None = None
    access_control: dict[str, Any] | None = None
    max_message_bytes: int = 64 << 20

    def __post_init__(self) -> None:
        if not self.namespace or self.namespace != self.namespace.strip("/") or " " in self.namespace:
            raise ValueError(f"namespace {self.namespace!r} must be slash-separated words like 'flagtrack/rig1'")
        for word in self.namespace.split("/"):
            problem = identifier_problem(word, "a word of the namespace")
            if problem is not None:
                raise ConfigError(problem, key="bus.namespace")
        if self.max_message_bytes < 1 << 16:
            raise ConfigError(
                f"{self.max_message_bytes} bytes is too small for a camera packet", key="bus.max_message_bytes"
            )
        if self.security is not None and self.security.tls is not None:
            for name in ("listen", "connect"):
                for i, endpoint in enumerate(getattr(self, name)):
                    if not endpoint.startswith("tls/"):
                        raise ConfigError(
                            f"{endpoint!r}: a bus with bus.security.tls takes tls/ endpoints only "
                            f"(tls/HOST:PORT), so that every link is encrypted and authenticated",
                            key=f"bus.{name}[{i}]",
                        )

    @property
    def secured(self) -> bool:
        """Whether every link of this session is mutual TLS."""
        return self.security is not None and self.security.tls is not None


def zenoh_settings(cfg: BusConfig, *, check_files: bool = True) -> dict[str, Any]:
    """The Zenoh settings of a :class:`BusConfig`, as config path -> value (what :func:`zenoh_config`
    inserts; ``flagtrack router --zenohd-config`` writes them as a zenohd config file, without
    ``check_files``: the files are the router host's).

    Raises:
        ConfigError: a secured bus whose identity or files are wrong (see
            :func:`flagtrack.daemon.security.config.zenoh_security`).
    """
    settings: dict[str, Any] = {
        "mode": cfg.mode,
        "scouting/multicast/enabled": cfg.multicast_scouting,
        "listen/endpoints": list(cfg.listen),
        "connect/endpoints": list(cfg.connect),
        "transport/shared_memory/enabled": cfg.shared_memory,
        "transport/link/rx/max_message_size": cfg.max_message_bytes,
    }
    if cfg.security is not None:
        listens = bool(cfg.listen) or cfg.mode == "router"
        settings.update(zenoh_security(cfg.security, listens=listens, check_files=check_files))
    if cfg.access_control is not None:
        settings["access_control"] = cfg.access_control
    return settings


def zenoh_config(cfg: BusConfig) -> zenoh.Config:
    """Translate a :class:`BusConfig` into a Zenoh configuration."""
    zcfg = zenoh.Config()
    for path, value in zenoh_settings(cfg).items():
        zcfg.insert_json5(path, json.dumps(value))
    return zcfg


def _without_secrets(text: str, cfg: BusConfig) -> str:
    """``text`` (an error of Zenoh's, which may quote its config) with the password redacted."""
    for secret in cfg.security.secrets() if cfg.security is not None else ():
        text = text.replace(secret, REDACTED)
    return text


def _open_error(text: str, cfg: BusConfig) -> str:
    """Zenoh's error on opening a session, for a person: no secret, none of the Rust source locations
    it appends (``at /root/.cargo/.../tcp.rs:61.``), and what a port in use most likely means."""
    text = re.sub(r"\s+at\s+\S+\.rs:\d+\.?", "", _without_secrets(text, cfg))
    if "Address already in use" in text:
        text += "; another router or rig listens there?"
    return text


class Channel:
    """A thread-safe queue filled by a Zenoh callback and read by a service loop.

    Args:
        capacity: maximum samples held.
        ring: when full, drop the oldest (live views); otherwise drop the newest and count it.
        max_bytes: maximum payload bytes held (None: no bound but ``capacity``); a sample that would
            go beyond is dropped (``ring``: the oldest make room), counted in ``dropped`` and
            ``dropped_bytes``. ``bytes`` is what it holds now.
        origins: also keep where each sample came from (:meth:`get_with_origin`; for commands).
    """

    def __init__(self, capacity: int, ring: bool, max_bytes: int | None = None, origins: bool = False) -> None:
        self._items: collections.deque[tuple[str, bytes]] = collections.deque()
        self._origins: collections.deque[str] | None = collections.deque() if origins else None
        self._capacity = capacity
        self._ring = ring
        self._max_bytes = max_bytes
        self._ready = threading.Condition()
        self.bytes = 0
        self.dropped = 0
        self.dropped_bytes = 0

    def _full(self, size: int) -> bool:
        return len(self._items) >= self._capacity or (
            self._max_bytes is not None and self.bytes + size > self._max_bytes
        )

    def push(self, key: str, payload: bytes, origin: str = "") -> None:
        """Called from Zenoh's thread: never blocks beyond a short lock. O(1) amortised."""
        size = len(payload)
        with self._ready:
            if self._full(size):
                if self._ring and (self._max_bytes is None or size <= self._max_bytes):
                    while self._items and self._full(size):
                        old = len(self._items.popleft()[1])
                        if self._origins is not None:
                            self._origins.popleft()
                        self.bytes -= old
                        self.dropped += 1
                        self.dropped_bytes += old
                else:  # a FIFO keeps what it holds; a ring too, for a sample larger than max_bytes alone
                    self.dropped += 1
                    self.dropped_bytes += size
                    return
            self._items.append((key, payload))
            if self._origins is not None:
                self._origins.append(origin)
            self.bytes += size
            self._ready.notify()

    def get(self, timeout_s: float | None = None) -> tuple[str, bytes] | None:
        """Return the oldest ``(key, payload)``, waiting up to ``timeout_s``; None on timeout."""
        item = self.get_with_origin(timeout_s)
        return None if item is None else (item[0], item[1])

    def get_with_origin(self, timeout_s: float | None = None) -> tuple[str, bytes, str] | None:
        """Return the oldest ``(key, payload, origin)`` (origin ``""`` when not kept or not known)."""
        with self._ready:
            if not self._items and not self._ready.wait_for(lambda: bool(self._items), timeout_s):
                return None
            key, payload = self._items.popleft()
            origin = self._origins.popleft() if self._origins is not None else ""
            self.bytes -= len(payload)
            return key, payload, origin

    def drain(self) -> list[tuple[str, bytes]]:
        """Return and remove everything queued."""
        with self._ready:
            items = list(self._items)
            self._items.clear()
            if self._origins is not None:
                self._origins.clear()
            self.bytes = 0
            return items

    def __len__(self) -> int:
        return len(self._items)


class Subscription:
    """Messages of one key expression, decoded on :meth:`recv`; malformed ones are counted and skipped.

    ``origin`` says where the message :meth:`recv` returned last came from, when the subscription keeps
    origins: the key it came on and, if its publisher tagged it (``Bus.publisher(tag_source=True)``),
    the publishing session and entity. Zenoh gives no more: a sample does not carry the sender's
    certificate, and through a router the link it came on is the router's.
    """

    def __init__(self, subscriber: Any, channel: Channel, expected: type | None) -> None:
        self._subscriber = subscriber
        self.channel = channel
        self._expected = expected
        self.malformed = 0
        self.origin = ""
        self._problems = ProblemLog(log, "bus")

    def recv(self, timeout_s: float | None = None) -> Any | None:
        """The next well-formed message (or None on timeout); malformed ones are counted and skipped."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            item = self.channel.get_with_origin(remaining)
            if item is None:
                return None
            key, payload, origin = item
            try:
                message: Any = decode(payload, self._expected, key=key)
                self.origin = f"{key}{origin}"
                return message
            except SchemaError as exc:
                self.malformed += 1
                self._problems.add("malformed messages", exc)  # counted, logged rarely

    def recv_raw(self, timeout_s: float | None = None) -> tuple[str, bytes] | None:
        """The next ``(key, payload)`` undecoded (for recorders that store bytes as they came)."""
        return self.channel.get(timeout_s)

    def close(self) -> None:
        """Stop receiving."""
        self._subscriber.undeclare()


class Publisher:
    """Publishes schema messages on one key expression; ``tag_source``: each sample names this
    publisher (session and entity ids, a sequence number) for the receiver's logs."""

    def __init__(self, publisher: Any, key: str, tag_source: bool = False) -> None:
        self._publisher = publisher
        self.key = key
        self._tag_source = tag_source
        self._sent = 0

    def put(self, message: Any) -> None:
        """Encode and publish ``message``."""
        if self._tag_source:
            self._sent += 1
            self._publisher.put(encode(message), source_info=zenoh.SourceInfo(self._publisher.id, self._sent))
        else:
            self._publisher.put(encode(message))

    def put_bytes(self, payload: bytes) -> None:
        """Publish bytes already encoded (or deliberately malformed, in tests)."""
        self._publisher.put(payload)

    def close(self) -> None:
        """Stop publishing."""
        self._publisher.undeclare()


@dataclass
class Liveliness:
    """Which services are alive, from liveliness tokens (PUT = appeared, DELETE = gone)."""

    alive: set[str] = field(default_factory=set)
    gone: list[str] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def on_sample(self, sample: Any) -> None:
        key = str(sample.key_expr)
        with self._lock:
            if sample.kind == zenoh.SampleKind.DELETE:
                self.alive.discard(key)
                self.gone.append(key)
            else:
                self.alive.add(key)

    def is_alive(self, key: str) -> bool:
        with self._lock:
            return key in self.alive


class Bus:
    """One Zenoh session; a context manager that closes everything it declared.

    Args:
        cfg: how to join the bus.
    """

    def __init__(self, cfg: BusConfig) -> None:
        self.cfg = cfg
        self.keys = Keys(cfg.namespace)
        try:
            self.session = zenoh.open(zenoh_config(cfg))
        except zenoh.ZError as exc:
            raise ConfigError(f"cannot open Zenoh session ({_open_error(str(exc), cfg)})", key="bus") from None
        self._declared: list[Any] = []
        self._alive: dict[str, list[Any]] = {}
        self._lock = threading.Lock()

    def _keep(self, entity: Any) -> None:
        """Remember a declared entity, to undeclare it on :meth:`close` (services declare from their threads)."""
        with self._lock:
            self._declared.append(entity)

    def publisher(self, key: str, *, block: bool = True, express: bool = False, tag_source: bool = False) -> Publisher:
        """Declare a publisher; ``block`` makes it wait for slow subscribers rather than drop;
        ``tag_source``: its samples name it (for commands, whose receivers log where they came from)."""
        congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        pub = self.session.declare_publisher(key, congestion_control=congestion, express=express)
        self._keep(pub)
        return Publisher(pub, key, tag_source)

    def subscribe(
        self,
        key: str,
        expected: type | None = None,
        *,
        capacity: int = 10_000,
        ring: bool = False,
        max_bytes: int | None = QUEUE_BYTES,
        origins: bool = False,
    ) -> Subscription:
        """Subscribe to ``key`` into a channel (FIFO by default, ring for live views; at most
        ``capacity`` samples and ``max_bytes`` payload bytes, see :class:`Channel`, by default
        :data:`QUEUE_BYTES`); ``origins``:
        keep where each came from (:attr:`Subscription.origin`)."""
        channel = Channel(capacity, ring, max_bytes, origins)

        def on_sample(sample: Any) -> None:
            channel.push(str(sample.key_expr), sample.payload.to_bytes())

        def on_sample_with_origin(sample: Any) -> None:
            info = sample.source_info
            origin = (
                f" from session {info.source_id.zid} publisher {info.source_id.eid} (its message {info.source_sn})"
                if info is not None
                else " (the sample names no sender: its publisher did not tag it)"
            )
            channel.push(str(sample.key_expr), sample.payload.to_bytes(), origin)

        sub = self.session.declare_subscriber(key, on_sample_with_origin if origins else on_sample)
        self._keep(sub)
        return Subscription(sub, channel, expected)

    def declare_alive(self, service: str) -> Any:
        """Declare ``service`` alive until :meth:`undeclare_alive` (the runner calls it when the
        service's loop ends, normally or not), the token is undeclared, or the session closes."""
        token = self.session.liveliness().declare_token(self.keys.alive(service))
        with self._lock:
            self._declared.append(token)
            self._alive.setdefault(service, []).append(token)
        return token

    def undeclare_alive(self, service: str) -> int:
        """Withdraw the liveliness tokens of ``service`` (it has ended; the session stays); return how many."""
        with self._lock:
            tokens = self._alive.pop(service, [])
            self._declared = [entity for entity in self._declared if not any(entity is t for t in tokens)]
        for token in tokens:
            try:
                token.undeclare()
            except Exception as exc:  # noqa: BLE001 - undeclared already (by its holder); nothing to do
                log.debug("liveliness token of %s: %s", service, exc)
        return len(tokens)

    def watch_liveliness(self) -> Liveliness:
        """Track the liveliness tokens of every service of the namespace (current ones included)."""
        state = Liveliness()
        sub = self.session.liveliness().declare_subscriber(self.keys.alive_all(), state.on_sample, history=True)
        self._keep(sub)
        return state

    def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        with self._lock:
            declared, self._declared = self._declared, []
            self._alive.clear()
        for entity in reversed(declared):
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 - already gone with the session; nothing to do
                pass
        if not self.session.is_closed():
            self.session.close()

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
