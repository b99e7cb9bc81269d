"""Speed requests from the bus, as the tunnel's owner takes them: who asks, whether they may, the answer.

A request comes on ``<ns>/tunnel/request/<identity>`` and its answer goes to ``<ns>/tunnel/reply``
(naming the request and the identity; declared from the start, so that no first answer is lost
while the bus learns of its listeners). On a secured bus (mutual TLS) the supervisor listens only on the
keys of the identities ``bus.security.operators`` names, and with access control only that identity
may publish on its key: the key says who asks. On a plain bus anyone may ask as anyone; the log says
so. Every request is logged with its identity, and every one is answered.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from flagtrack.daemon.schema import SpeedReply, SpeedRequest
from flagtrack.daemon.transport import Bus, Publisher, Subscription

log = logging.getLogger(__name__)

REMEMBERED = 256
"""Answers kept, by identity and request id: a request sent again is answered again, not applied again."""


@dataclass(frozen=True)
class Asked:
    """One request as taken: who asked (``identity``; ``unchecked`` says why the bus did not
    authenticate it, "" when its access control did), the request, and where it came from."""

    identity: str
    unchecked: str
    request: SpeedRequest
    origin: str = ""

    @property
    def who(self) -> str:
        """The identity as the log and the record say it."""
        return f"{self.identity} (not authenticated: {self.unchecked})" if self.unchecked else self.identity


class SpeedDesk:
    """The supervisor's side of speed requests (see the module).

    Args:
        bus: the bus.
    """

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        security = bus.cfg.security
        self.secured = bus.cfg.secured
        self.operators: tuple[str, ...] = security.operators if security is not None else ()
        acl = bool(security is not None and security.acl)
        self.unchecked = "" if self.secured and acl else ("no access control" if self.secured else "plain bus")
        self.answered = 0
        self.taking = False  # a control loop takes the requests (until then they are refused)
        self._subscriptions: list[Subscription] = []
        self._replies: Publisher | None = None
        self._answers: dict[tuple[str, str], SpeedReply] = {}  # (identity, request id) -> its answer

    def start(self) -> None:
        """Subscribe: on a secured bus to each operator's key, on a plain one to every identity's;
        declare the answers' publisher."""
        keys = self.bus.keys
        self._replies = self.bus.publisher(keys.speed_reply())
        wanted = [keys.speed_request(name) for name in self.operators] if self.secured else [keys.speed_requests()]
        self._subscriptions = [
            self.bus.subscribe(key, SpeedRequest, capacity=256, max_bytes=1 << 20, origins=True) for key in wanted
        ]

    def take(self, on_refused: Callable[[Asked, str], None] | None = None) -> list[Asked]:
        """The requests that came, the newest of each identity (the older ones are answered as
        superseded); every one is logged with who asked. ``on_refused`` hears of each request
        refused here (superseded, not an operator's), after its answer."""
        newest: dict[str, Asked] = {}
        for subscription in self._subscriptions:
            while (request := subscription.recv(timeout_s=0)) is not None:
                key = subscription.origin.split(" ", 1)[0]
                identity = key.rsplit("/", 1)[-1]
                asked = Asked(identity, self.unchecked, request, subscription.origin)
                log.info("speed request %s from %s: %g m/s", request.request_id or "-", asked.who, request.speed_mps)
                repeated = self._answers.get((identity, request.request_id))
                if repeated is not None:  # sent again (its answer was not heard): answered again, not applied
                    self._put(repeated)
                    continue
                refusal = ""
                if self.secured and identity not in self.operators:  # (a key no operator holds: not listened to)
                    refusal = f"{identity} is not an operator (bus.security.operators)"
                elif identity in newest and newest[identity].request.request_id == request.request_id:
                    continue  # the same request sent again before its answer: once
                elif identity in newest:  # the older one is refused
                    older, newest[identity] = newest[identity], asked
                    asked, refusal = older, "superseded by a newer request"
                else:
                    newest[identity] = asked
                if refusal:
                    self.answer(asked, False, -1.0, refusal)
                    if on_refused is not None:
                        on_refused(asked, refusal)
        return list(newest.values())

    def answer(
        self,
        asked: Asked,
        accepted: bool,
        applied_mps: float,
        reason: str = "",
        setpoint_mps: float = math.nan,
        speed_mps: float = math.nan,
    ) -> None:
        """Answer ``asked`` on its identity's reply key, and log the answer."""
        reply = SpeedReply(
            request_id=asked.request.request_id,
            requester=asked.identity,
            accepted=accepted,
            asked_mps=_known(asked.request.speed_mps),
            applied_mps=_known(applied_mps),
            reason=reason,
            setpoint_mps=_known(setpoint_mps),
            speed_mps=_known(speed_mps),
            t_wall_s=time.time(),
        )
        self._put(reply)
        if reply.request_id:
            self._answers[(asked.identity, reply.request_id)] = reply
            while len(self._answers) > REMEMBERED:
                del self._answers[next(iter(self._answers))]
        self.answered += 1
        verdict = f"applied {applied_mps:g} m/s" if accepted else "refused"
        log.info(
            "speed request %s from %s: %s%s", reply.request_id or "-", asked.who, verdict, f" ({reason})" * bool(reason)
        )

    def _put(self, reply: SpeedReply) -> None:
        if self._replies is None:
            raise RuntimeError("SpeedDesk: start() first")
        self._replies.put(reply)

    def refuse_all(self, reason: str) -> None:
        """Answer every request waiting as refused (the supervisor takes none in this mode)."""
        for asked in self.take():
            self.answer(asked, False, -1.0, reason)


def _known(value: float) -> float:
    """``value``, or -1.0 when it is not a finite number (the messages' "not known")."""
    return float(value) if math.isfinite(value) else -1.0
