"""The centreline file service: messages that do not fit the file are counted, and it goes on."""

from __future__ import annotations

import dataclasses
import json
import threading
from pathlib import Path

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.schema import CentrelineMessage, encode
from flagtrack.daemon.services.centreline_file import CentrelineFileService
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats.centreline import read_centrelines
from tests.fakes.helpers import wait_subscribed, wait_until
from tests.integration.test_transport import free_port


def message(seq: int, n_t: int, n_s: int, final: bool = False) -> CentrelineMessage:
    x = np.arange(n_t * n_s, dtype=float).reshape(n_t, n_s) + 1000 * seq
    batch = CentrelineBatch(
        seq + np.arange(n_t) * 1e-3,
        np.linspace(0, 200, n_s),
        x,
        -x,
        np.zeros((n_t, 11)),
        np.zeros((n_t, 11)),
        np.ones(n_t),
        np.ones(n_t, dtype=np.int64),
    )
    return CentrelineMessage.from_batch(
        batch, source="tracker", seq=seq, units="px", source_ns=np.zeros(n_t, dtype=np.int64), final=final
    )


def test_messages_that_do_not_fit_the_file_are_counted_and_the_stream_is_written(tmp_path: Path) -> None:
    """A message of another tracker setup (7 samples, the file has 51) and one whose joints_x is
    1-D (it decoded before, then failed) are counted; every other update is written, and the
    service still ends with the stream."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    path = tmp_path / "lines.h5"
    with (
        Bus(BusConfig(namespace="flagtrack/cf", listen=(endpoint,))) as bus,
        Bus(BusConfig(namespace="flagtrack/cf", connect=(endpoint,))) as source,
    ):
        service = CentrelineFileService(bus, path, {"length": 200.0}, exit_after_final=True)
        service.start()
        thread = threading.Thread(target=service.run, args=(threading.Event(),))
        thread.start()
        wait_subscribed(source, source.keys.centrelines())
        pub = source.publisher(source.keys.centrelines())
        pub.put(message(0, 4, 51))
        pub.put(message(1, 5, 7))
        bad = message(2, 6, 51)
        pub.put_bytes(encode(dataclasses.replace(bad, joints_x=bad.joints_x[:, 0])))
        pub.put(message(3, 3, 51, final=True))
        thread.join(20)
        assert not thread.is_alive()  # ended with the final message, not by an error
    assert service.rejected == 1 and service.subscription.malformed == 1 and service.updates == 7
    got, attrs = read_centrelines(path)
    np.testing.assert_array_equal(got.t_s, np.r_[np.arange(4) * 1e-3, 3 + np.arange(3) * 1e-3])
    np.testing.assert_array_equal(got.x[4:], message(3, 3, 51).x)
    assert attrs["units"] == "px" and attrs["length"] == 200.0


def test_the_recorder_and_the_centreline_file_write_the_same_attributes(tmp_path: Path) -> None:
    """Given the same processing mapping (parameters and calibration), the recorder's file (as for
    a sweep point) and ``up --centrelines``'s carry the same attributes, values included, but for
    ``input_file`` (the recorder's is its .raw file); both refuse the same message and hold the same
    updates."""
    processing = {
        "length": 200.0,
        "alpha": 0.6,
        "root": [102.0, 240.0],
        "refine_deg": None,
        "schedule": [],
        "calibration_degree": 3,
        "calibration_yaml": "degree: 3\n",
    }
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/cs", listen=(endpoint,))) as bus,
        Bus(BusConfig(namespace="flagtrack/cs", connect=(endpoint,))) as source,
    ):
        service = CentrelineFileService(
            bus, tmp_path / "live.h5", {**processing, "input_file": "flag.raw"}, exit_after_final=True
        )
        service.start()
        recorder = RecorderService(
            bus, RecorderConfig(directory=tmp_path, path="point_003", centrelines=True), centreline_attrs=processing
        )
        recorder.start()
        stop = threading.Event()
        threads = [threading.Thread(target=s.run, args=(stop,)) for s in (service, recorder)]
        for thread in threads:
            thread.start()
        try:
            wait_subscribed(source, source.keys.centrelines())
            pub = source.publisher(source.keys.centrelines())
            for msg in (message(0, 4, 51), message(1, 5, 7), message(2, 3, 51, final=True)):
                pub.put(msg)
            threads[0].join(20)
            wait_until(lambda: recorder.current is not None, what="the recorder recording")  # its thread may lag
            sink = recorder.current.centrelines  # type: ignore[union-attr]
            wait_until(lambda: sink.n_updates + sink.n_pending == 7, what="7 updates in the sink")
        finally:
            stop.set()
            for thread in threads:
                thread.join(10)
        assert not any(thread.is_alive() for thread in threads)
    assert service.rejected == 1 and recorder.problems.totals["centreline messages not recorded"] == 1
    live, live_attrs = read_centrelines(tmp_path / "live.h5")
    point, point_attrs = read_centrelines(tmp_path / "point_003_centrelines.h5")
    for name in ("t_s", "s", "x", "y", "joints_x", "joints_y", "delta_rms", "n_events"):
        np.testing.assert_array_equal(getattr(point, name), getattr(live, name), err_msg=name)
    assert len(point) == 7
    layout = {"format", "format_version", "calibration_units"}  # named by the writer; refine_deg unset: absent
    every = {*processing, *layout, "units", "source", "input_file", "flagtrack_version"} - {"refine_deg"}
    assert set(point_attrs) == set(live_attrs) == every
    assert {k: v for k, v in point_attrs.items() if k not in ("input_file", "root")} == {
        k: v for k, v in live_attrs.items() if k not in ("input_file", "root")
    }
    assert list(point_attrs["root"]) == list(live_attrs["root"]) == [102.0, 240.0]
    assert point_attrs["units"] == "px" and point_attrs["source"] == "tracker" and point_attrs.get("refine_deg") is None
    assert point_attrs["calibration_yaml"] == "degree: 3\n"
    assert point_attrs["input_file"] == str(tmp_path / "point_003.raw") and live_attrs["input_file"] == "flag.raw"
    sidecar = json.loads((tmp_path / "point_003.json").read_text())
    assert sidecar["stopped"] and sidecar["centrelines_file"] == "point_003_centrelines.h5"
