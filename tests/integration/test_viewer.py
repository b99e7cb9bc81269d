"""The viewer bridges real bus messages into a Rerun .rrd file (headless sink)."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, EventRate
from flagtrack.daemon.services.viewer import RerunLogger, ViewerConfig, ViewerService, age_colours, open_recording
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats.packets import Packetizer
from flagtrack.drivers.sim.quickline import WavyFlag, line_events
from tests.fakes.helpers import wait_subscribed
from tests.integration.test_transport import free_port, wait_for


def test_viewer_logs_events_and_centrelines_to_rrd(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    rrd = tmp_path / "view.rrd"
    with (
        Bus(BusConfig(namespace="flagtrack/view", listen=(endpoint,))) as bus,
        Bus(BusConfig(namespace="flagtrack/view", connect=(endpoint,))) as source,
    ):
        viewer = ViewerService(
            bus, ViewerConfig(sink="rrd", rrd_path=rrd, update_rate_hz=None, geometry_rate_hz=1000.0)
        )
        viewer.start()
        stop = threading.Event()
        thread = threading.Thread(target=viewer.run, args=(stop,))
        thread.start()
        wait_subscribed(
            source, source.keys.camera_events("cam0"), source.keys.centrelines(), source.keys.event_rate("cam0")
        )
        events_pub = source.publisher(source.keys.camera_events("cam0"))
        lines_pub = source.publisher(source.keys.centrelines())
        rate_pub = source.publisher(source.keys.event_rate("cam0"))
        packetizer = Packetizer("evt3", 640, 480)
        seq = 0
        for chunk in line_events(WavyFlag(), 0, 50_000, 640, 480, chunk_us=1000):
            for p in packetizer.push(chunk):
                seq += 1
                events_pub.put(
                    EventPacket(
                        "cam0",
                        seq,
                        p.t_first_us,
                        p.t_last_us,
                        p.n_events,
                        640,
                        480,
                        "evt3",
                        time.time_ns(),
                        t_offset_us=p.t_offset_us,
                        data=p.data,
                    )
                )
            time.sleep(0.002)  # paced as a camera sends them
        n_t, n_s = 20, 51
        batch = CentrelineBatch(
            np.arange(n_t) * 1e-3,
            np.linspace(0, 200, n_s),
            np.zeros((n_t, n_s)),
            np.zeros((n_t, n_s)),
            np.zeros((n_t, 11)),
            np.zeros((n_t, 11)),
            np.ones(n_t),
            np.ones(n_t, dtype=np.int64),
        )
        lines_pub.put(
            CentrelineMessage.from_batch(
                batch, source="tracker", seq=0, units="px", source_ns=np.zeros(n_t, dtype=np.int64)
            )
        )
        rate_pub.put(EventRate("cam0", 50_000, 0.1, 1000, 1e4, 0.5))
        assert wait_for(lambda: viewer.updates == n_t and viewer.frames > 0)
        stop.set()
        thread.join(10)
    assert not thread.is_alive()
    assert rrd.stat().st_size > 10_000


def test_age_colours_run_from_bright_to_dark() -> None:
    colours = age_colours(np.array([0.0, 0.005, 0.01]), 0.01)
    assert colours.dtype == np.uint8 and colours.shape == (3, 3)
    assert colours[0].sum() > colours[1].sum() > colours[2].sum()


def test_the_rrd_holds_each_update_centreline_at_its_time(tmp_path: Path) -> None:
    """Read back from the .rrd file: one strip per update, its points the centreline's (x, y)."""
    from rerun.chunk import RrdReader

    rrd = tmp_path / "lines.rrd"
    cfg = ViewerConfig(sink="rrd", rrd_path=rrd, update_rate_hz=None, geometry_rate_hz=1000.0)
    rec, _ = open_recording(cfg)
    logger = RerunLogger(rec, cfg)
    n_t, n_s = 5, 7
    x = np.arange(n_t * n_s, dtype=float).reshape(n_t, n_s)
    batch = CentrelineBatch(
        1.0 + np.arange(n_t) * 1e-3,
        np.linspace(0, 200, n_s),
        x,
        -2 * x,
        np.zeros((n_t, 11)),
        np.zeros((n_t, 11)),
        np.ones(n_t),
        np.ones(n_t, dtype=np.int64),
    )
    logger.centrelines(
        CentrelineMessage.from_batch(
            batch, source="tracker", seq=0, units="px", source_ns=np.zeros(n_t, dtype=np.int64)
        )
    )
    assert logger.frame(0.0, force=True)
    rec.flush()
    rec.disconnect()
    rows = [chunk.to_record_batch() for chunk in RrdReader(rrd).stream() if chunk.entity_path == "/tracker/centreline"]
    strips = [strip for rows_ in rows for strip in rows_.column("LineStrips2D:strips").to_pylist()]
    assert len(strips) == n_t
    for k, strip in enumerate(strips):
        assert len(strip) == 1  # one strip per update
        np.testing.assert_allclose(np.array(strip[0]), np.stack([x[k], -2 * x[k]], axis=-1))


def test_a_new_run_keeps_the_previous_runs_view(tmp_path: Path) -> None:
    """Every `up` and `sweep` of a rig writes the same `viewer.rrd_path`: the view already there is
    renamed beside it (it was overwritten)."""
    from flagtrack.daemon.services.viewer import close_recording

    rrd = tmp_path / "live.rrd"
    cfg = ViewerConfig(sink="rrd", rrd_path=rrd, update_rate_hz=None)
    rec, first = open_recording(cfg)
    assert "previous view" not in first
    close_recording(rec)
    earlier = rrd.read_bytes()
    assert earlier
    rec, second = open_recording(cfg)
    close_recording(rec)
    kept = [p for p in tmp_path.iterdir() if p != rrd]
    assert len(kept) == 1 and kept[0].name.startswith("live-") and kept[0].suffix == ".rrd"
    assert kept[0].read_bytes() == earlier and f"(the previous view kept as {kept[0].name})" in second
    rec, _ = open_recording(cfg)  # the same second: a name of its own, nothing overwritten
    close_recording(rec)
    assert len(list(tmp_path.iterdir())) == 3


def test_a_view_that_cannot_be_kept_is_one_error_naming_the_key(tmp_path: Path) -> None:
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.services.viewer import close_recording

    cfg = ViewerConfig(sink="rrd", rrd_path=tmp_path / "live.rrd", update_rate_hz=None)
    close_recording(open_recording(cfg)[0])
    tmp_path.chmod(0o500)
    try:
        if os.access(tmp_path, os.W_OK):
            pytest.skip("running as a user who writes to read-only folders (root)")
        with pytest.raises(ConfigError, match="cannot keep the previous view") as caught:
            open_recording(cfg)
        assert caught.value.key == "viewer.rrd_path"
    finally:
        tmp_path.chmod(0o700)


def centreline_batch(n_t: int, n_s: int, t0_s: float = 0.0) -> CentrelineBatch:
    x = np.arange(n_t * n_s, dtype=float).reshape(n_t, n_s)
    return CentrelineBatch(
        t0_s + np.arange(n_t) * 1e-3,
        np.linspace(0, 200, n_s),
        x,
        -x,
        np.zeros((n_t, 11)),
        np.zeros((n_t, 11)),
        np.ones(n_t),
        np.ones(n_t, dtype=np.int64),
    )


def test_messages_the_viewer_cannot_show_are_counted_and_it_goes_on(tmp_path: Path) -> None:
    """A centreline message with a 1-D joints_x (it decoded, then crashed the viewer's frame), a
    packet whose EVT bytes are corrupt, a wind speed at a time Rerun cannot place, and two tracker
    setups (51 and 7 samples) in one frame: the viewer counts what it cannot show and logs the rest."""
    import dataclasses

    from rerun.chunk import RrdReader

    from flagtrack.daemon.schema import TunnelState, encode

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    rrd = tmp_path / "bad.rrd"
    with (
        Bus(BusConfig(namespace="flagtrack/vbad", listen=(endpoint,))) as bus,
        Bus(BusConfig(namespace="flagtrack/vbad", connect=(endpoint,))) as source,
    ):
        viewer = ViewerService(bus, ViewerConfig(sink="rrd", rrd_path=rrd, update_rate_hz=None, geometry_rate_hz=5.0))
        viewer.start()
        stop = threading.Event()
        thread = threading.Thread(target=viewer.run, args=(stop,))
        thread.start()
        try:
            wait_subscribed(
                source, source.keys.camera_events("cam0"), source.keys.centrelines(), source.keys.tunnel_state()
            )
            events_pub = source.publisher(source.keys.camera_events("cam0"))
            lines_pub = source.publisher(source.keys.centrelines())
            tunnel_pub = source.publisher(source.keys.tunnel_state())
            corrupt = np.full(8, 0x9000, dtype="<u2").tobytes()  # a reserved EVT 3.0 word type
            events_pub.put(EventPacket("cam0", 0, 0, 999, 8, 640, 480, "evt3", time.time_ns(), data=corrupt))
            zeros = np.zeros(4, dtype=np.int64)
            good = CentrelineMessage.from_batch(
                centreline_batch(4, 51), source="tracker", seq=0, units="px", source_ns=zeros
            )
            lines_pub.put_bytes(encode(dataclasses.replace(good, joints_x=good.joints_x[:, 0])))
            assert wait_for(
                lambda: (
                    viewer.subs["centrelines"].malformed == 1  # taken in, and the packet's frame
                    and viewer.problems.totals.get("undecodable packets") == 1
                )
            )  # drawn
            frames = viewer.frames
            tunnel_pub.put(TunnelState(3.0, 3.0, "steady", t_wall_s=float("nan")))
            lines_pub.put(
                CentrelineMessage.from_batch(
                    centreline_batch(20, 51),
                    source="tracker",
                    seq=1,
                    units="px",
                    source_ns=np.zeros(20, dtype=np.int64),
                )
            )
            lines_pub.put(
                CentrelineMessage.from_batch(
                    centreline_batch(5, 7, 0.1),
                    source="tracker",
                    seq=2,
                    units="px",
                    source_ns=np.zeros(5, dtype=np.int64),
                )
            )
            assert wait_for(lambda: viewer.updates == 25 and viewer.unusable >= 1)
            assert wait_for(lambda: viewer.frames > frames)  # the frame that draws them
            assert thread.is_alive()
        finally:
            stop.set()
            thread.join(10)
    assert not thread.is_alive()
    assert viewer.subs["centrelines"].malformed == 1 and viewer.unusable == 1
    assert viewer.problems.totals == {"undecodable packets": 1, "messages that could not be shown": 1}
    strips = [
        strip
        for chunk in RrdReader(rrd).stream()
        if chunk.entity_path == "/tracker/centreline"
        for strip in chunk.to_record_batch().column("LineStrips2D:strips").to_pylist()
    ]
    assert sorted(len(strip[0]) for strip in strips) == [7] * 5 + [51] * 20


def test_the_view_keeps_one_update_per_slot_and_every_change_of_lost(tmp_path: Path) -> None:
    """1 kHz updates shown at 100 Hz: a strip, joints and scalars every 10 ms; a 3-update lost stretch
    between two shown updates still shows in plots/lost, its start and end at their times."""
    from rerun.chunk import RrdReader

    rrd = tmp_path / "slots.rrd"
    cfg = ViewerConfig(sink="rrd", rrd_path=rrd, update_rate_hz=100.0, geometry_rate_hz=1000.0)
    rec, _ = open_recording(cfg)
    logger = RerunLogger(rec, cfg)
    n_t, n_s = 200, 7
    t = 1.0 + np.arange(n_t) * 1e-3
    x = np.tile(np.linspace(0, 200, n_s), (n_t, 1))
    lost = np.zeros(n_t, dtype=np.uint8)
    lost[53:56] = 1  # t = 1.053 to 1.055 s, between the shown 1.050 and 1.060
    for part in np.split(np.arange(n_t), [17, 120]):  # in uneven messages
        m = len(part)
        piece = CentrelineBatch(t[part], np.linspace(0, 200, n_s), x[part], 0 * x[part], np.zeros((m, 3)),
                                np.zeros((m, 3)), np.ones(m), np.ones(m, dtype=np.int64), lost[part])  # fmt: skip
        message = CentrelineMessage.from_batch(piece, source="tracker", seq=0, units="px", source_ns=np.zeros(m, int))
        logger.centrelines(message)
    assert logger.frame(0.0, force=True)
    rec.flush()
    rec.disconnect()
    times: dict[str, list[float]] = {}
    values: dict[str, list] = {}
    for chunk in RrdReader(rrd).stream():
        batch_rows = chunk.to_record_batch()
        if chunk.entity_path in ("/tracker/centreline", "/plots/lost") and "camera" in batch_rows.schema.names:
            ns = batch_rows.column("camera").cast("int64").to_numpy()
            times.setdefault(chunk.entity_path, []).extend(ns * 1e-9)
            if chunk.entity_path == "/plots/lost":
                values.setdefault("lost", []).extend(v[0] for v in batch_rows.column("Scalars:scalars").to_pylist())
    np.testing.assert_allclose(times["/tracker/centreline"], 1.0 + np.arange(20) * 0.01, atol=1e-6)
    lost_at = dict(zip(np.round(times["/plots/lost"], 4), values["lost"], strict=True))
    assert lost_at[1.053] == 1 and lost_at[1.056] == 0 and lost_at[1.05] == 0 and lost_at[1.06] == 0
    assert len(lost_at) == 22  # 20 slots and the two changes
