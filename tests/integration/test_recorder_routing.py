"""The recorder files a centreline message only after the packets it comes from: a new stream's first
centrelines go to the new part even when they are read before the new stream's packets are written."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.sim.quickline import WavyFlag, line_events
from tests.fakes.helpers import wait_subscribed, wait_until
from tests.integration.test_centreline_file_service import message
from tests.integration.test_recorder import packets_of, publish
from tests.integration.test_transport import free_port


def test_centrelines_of_a_new_stream_read_before_its_packets_go_to_the_new_part(tmp_path: Path) -> None:
    """Stream 1 is written; stream 2's packets and then a centreline message from them are both queued
    when the recorder reads its centrelines (as when its thread was held between the two): the
    packets are written first, so the message lands in ``run_stream2``, not in the old part."""
    events = np.concatenate(list(line_events(WavyFlag(), 0, 20_000, 640, 480)))
    packets = packets_of(events, 20_000)[:10]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with Bus(BusConfig(namespace="flagtrack/rr", listen=(endpoint,))) as bus:
        recorder = RecorderService(bus, RecorderConfig(directory=tmp_path, centrelines=True))
        recorder.start()
        recorder.start_recording("run", centrelines=True)
        wait_subscribed(bus, bus.keys.camera_events("cam0"))
        wait_subscribed(bus, bus.keys.centrelines())
        cam, lines = bus.publisher(bus.keys.camera_events("cam0")), bus.publisher(bus.keys.centrelines())
        publish(cam, packets)
        wait_until(lambda: len(recorder._packets.channel) == len(packets), 10, "stream 1 queued")
        recorder._write_queued_packets()
        publish(cam, packets)  # the camera restarted: numbers from 0 again
        first = message(0, 4, 51)
        first.source_ns[:] = time.time_ns()  # from stream 2's packets, sent just before
        lines.put(first)
        wait_until(lambda: len(recorder._packets.channel) == len(packets), 10, "stream 2 queued")
        wait_until(lambda: len(recorder._lines.channel) == 1, 10, "the centreline message queued")
        recorder._take_lines(time.monotonic())
        assert recorder.current is not None and recorder.current.part == 2 and recorder.restarts == 1
        recorder.stop_recording()
    assert len(read_centrelines(tmp_path / "run_stream2_centrelines.h5")[0]) == 4
    assert not (tmp_path / "run_centrelines.h5").exists()  # the old part had no centreline
