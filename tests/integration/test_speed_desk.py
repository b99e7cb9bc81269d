"""The supervisor's speed desk on a real bus (loopback): of two requests from one identity taken
together, the older is answered as superseded and its refusal reaches the caller, so a control run
records it; a request sent again is answered again, not applied or recorded twice."""

from __future__ import annotations

from flagtrack.daemon.schema import SpeedReply, SpeedRequest
from flagtrack.daemon.services.supervisor.requests import Asked, SpeedDesk
from flagtrack.daemon.transport import Bus, BusConfig
from tests.fakes.helpers import wait_subscribed, wait_until
from tests.integration.test_transport import free_port


def test_a_superseded_request_is_answered_and_heard_by_the_caller() -> None:
    with Bus(BusConfig(namespace="flagtrack/desk", listen=(f"tcp/127.0.0.1:{free_port()}",))) as bus:
        desk = SpeedDesk(bus)
        desk.start()
        replies = bus.subscribe(bus.keys.speed_reply(), SpeedReply)
        key = bus.keys.speed_request("alice")
        wait_subscribed(bus, key)
        asking = bus.publisher(key)
        for speed, request_id in ((4.0, "first"), (5.0, "second"), (5.0, "second")):
            asking.put(SpeedRequest(speed, request_id, "alice"))
        (queue,) = (subscription.channel for subscription in desk._subscriptions)
        wait_until(lambda: len(queue) == 3, 10, "the three requests at the desk")  # (one take sees them all)
        refused: list[tuple[Asked, str]] = []
        taken = desk.take(lambda a, why: refused.append((a, why)))
        assert [a.request.request_id for a in taken] == ["second"]
        assert [(a.request.request_id, a.request.speed_mps, why) for a, why in refused] == [
            ("first", 4.0, "superseded by a newer request")
        ]
        reply = wait_until(lambda: replies.recv(timeout_s=0.1), 10, "the refusal's answer")
        assert reply.request_id == "first" and not reply.accepted and reply.requester == "alice"
        desk.answer(taken[0], True, 5.0)
        answered = wait_until(lambda: replies.recv(timeout_s=0.1), 10, "the answer")
        asking.put(SpeedRequest(5.0, "second", "alice"))  # sent again: answered again, not taken
        wait_until(lambda: len(queue) == 1, 10, "the request sent again at the desk")
        assert desk.take(lambda a, why: refused.append((a, why))) == [] and len(refused) == 1
        again = wait_until(lambda: replies.recv(timeout_s=0.1), 10, "the answer again")
        assert answered.request_id == again.request_id == "second" and answered.accepted and again.accepted
