"""The centreline file service: messages that do not fit the file are counted, and it goes on."""

from __future__ import annotations

import dataclasses
import threading
from pathlib import Path

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.schema import CentrelineMessage, encode
from flagtrack.daemon.services.centreline_file import CentrelineFileService
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats.centreline import read_centrelines
from tests.fakes.helpers import wait_subscribed
from tests.integration.test_transport import free_port


def message(seq: int, n_t: int, n_s: int, final: bool = False) -> CentrelineMessage:
    x = np.arange(n_t * n_s, dtype=float).reshape(n_t, n_s) + 1000 * seq
    batch = CentrelineBatch(seq + np.arange(n_t) * 1e-3, np.linspace(0, 200, n_s), x, -x, np.zeros((n_t, 11)),
                            np.zeros((n_t, 11)), np.ones(n_t), np.ones(n_t, dtype=np.int64))
    return CentrelineMessage.from_batch(batch, source="tracker", seq=seq, units="px",
                                        source_ns=np.zeros(n_t, dtype=np.int64), final=final)


def test_messages_that_do_not_fit_the_file_are_counted_and_the_stream_is_written(tmp_path: Path) -> None:
    """A message of another tracker setup (7 samples, the file has 51) and one whose joints_x is
    1-D (it decoded before, then failed) are counted; every other update is written, and the
    service still ends with the stream."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    path = tmp_path / "lines.h5"
    with Bus(BusConfig(namespace="flagtrack/cf", listen=(endpoint,))) as bus, \
            Bus(BusConfig(namespace="flagtrack/cf", connect=(endpoint,))) as source:
        service = CentrelineFileService(bus, path, {"length": 200.0}, exit_after_final=True)
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
