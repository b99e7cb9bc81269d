"""A gap in what arrives (a cut link, a restarted router) is recorded explicitly: the recorder's sidecar
lists each gap's packets and camera/wall times, its centreline file and the centreline-file service's
carry ``gaps_t_s``; what came before and after is kept."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np

from flagtrack.daemon.services.centreline_file import CentrelineFileService
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats import read_events
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.sim.quickline import WavyFlag, line_events
from tests.fakes.helpers import wait_subscribed, wait_until
from tests.integration.test_centreline_file_service import message
from tests.integration.test_recorder import packets_of, publish
from tests.integration.test_transport import free_port


def test_the_recorder_records_each_gap_with_its_times(tmp_path: Path) -> None:
    events = np.concatenate(list(line_events(WavyFlag(), 0, 20_000, 640, 480)))
    packets = packets_of(events, 20_000)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with Bus(BusConfig(namespace="flagtrack/gap", listen=(endpoint,))) as bus:
        recorder = RecorderService(bus, RecorderConfig(directory=tmp_path, path="g", centrelines=True))
        recorder.start()
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,))
        thread.start()
        try:
            wait_subscribed(bus, bus.keys.camera_events("cam0"), bus.keys.centrelines())
            pub, lines = bus.publisher(bus.keys.camera_events("cam0")), bus.publisher(bus.keys.centrelines())
            publish(pub, packets[:5])
            lines.put(message(0, 4, 51))
            publish(pub, packets[8:], first_seq=8)  # packets 5-7 lost on the way
            lines.put(message(1, 4, 51))
            wait_until(lambda: recorder.current is not None and recorder.current.packets == len(packets) - 3)
        finally:
            stop.set()
            thread.join(10)
    sidecar = json.loads((tmp_path / "g.json").read_text())
    assert sidecar["sequence_gaps"] == [[5, 8]] and sidecar["missing_packets"] == 3
    (gap,) = sidecar["gaps"]
    assert gap["from_seq"] == 5 and gap["to_seq"] == 8 and gap["missing_packets"] == 3
    assert gap["t_from_us"] == packets[4].t_last_us and gap["t_to_us"] == packets[8].t_first_us
    assert 0 < gap["sent_from_ns"] <= gap["sent_to_ns"]
    kept = read_events(tmp_path / "g.raw", strict=True).events  # before and after the gap, nothing else lost
    lost = (events["t"] > packets[4].t_last_us) & (events["t"] < packets[8].t_first_us)
    np.testing.assert_array_equal(kept, events[~lost])
    _, attrs = read_centrelines(tmp_path / "g_centrelines.h5")
    np.testing.assert_allclose(attrs["gaps_t_s"], [[packets[4].t_last_us * 1e-6, packets[8].t_first_us * 1e-6]])


def test_the_centreline_file_records_missing_messages_as_a_gap(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    path = tmp_path / "lines.h5"
    with (
        Bus(BusConfig(namespace="flagtrack/cg", listen=(endpoint,))) as bus,
        Bus(BusConfig(namespace="flagtrack/cg", connect=(endpoint,))) as source,
    ):
        service = CentrelineFileService(bus, path, {"length": 200.0}, exit_after_final=True)
        service.start()
        thread = threading.Thread(target=service.run, args=(threading.Event(),))
        thread.start()
        wait_subscribed(source, source.keys.centrelines())
        pub = source.publisher(source.keys.centrelines())
        for seq in (0, 1, 4):  # messages 2 and 3 lost
            pub.put(message(seq, 3, 51, final=seq == 4))
        thread.join(20)
        assert not thread.is_alive()
    got, attrs = read_centrelines(path)
    assert service.updates == 9 and len(got.t_s) == 9  # everything that came is written
    np.testing.assert_allclose(attrs["gaps_t_s"], [[1.002, 4.0]])
