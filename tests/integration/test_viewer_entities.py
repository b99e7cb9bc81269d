"""Every entity the viewer promises, read back from a headless .rrd file: events, joints, tip trail,
Delta_RMS, events per update, event rate and wind speed, each on the camera clock."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, EventRate, TunnelState
from flagtrack.daemon.services.viewer import RerunLogger, ViewerConfig, open_recording
from flagtrack.drivers.formats.packets import Packetizer
from flagtrack.drivers.sim.quickline import WavyFlag, line_events

N_T, N_S, N_J = 6, 9, 10
SENT_NS = 1_000_000_000_000  # wall clock of the packets: 1000 s


def _columns(rrd: Path) -> dict[str, dict[str, list[Any]]]:
    """{entity path: {column: values}} of every chunk in the file (times as int64 ns)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    out: dict[str, dict[str, list[Any]]] = {}
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        columns = out.setdefault(chunk.entity_path, {})
        for name in batch.schema.names:
            column = batch.column(name)
            if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
                column = column.cast(pa.int64())
            columns.setdefault(name, []).extend(column.to_pylist())
    return out


@pytest.fixture(scope="module")
def logged(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, dict[str, list[Any]]], dict[str, Any]]:
    rrd = tmp_path_factory.mktemp("view") / "all.rrd"
    cfg = ViewerConfig(
        sink="rrd", rrd_path=rrd, update_rate_hz=None, geometry_rate_hz=1000.0, recent_events_ms=10.0, trail_s=1.0
    )
    rec, _ = open_recording(cfg)
    logger = RerunLogger(rec, cfg)
    packetizer = Packetizer("evt3", 640, 480)
    events = np.concatenate(list(line_events(WavyFlag(), 990_000, 1_010_000, 640, 480, chunk_us=1000)))
    for seq, p in enumerate(packetizer.push(events) + packetizer.flush()):
        logger.events(
            EventPacket(
                "cam0",
                seq,
                p.t_first_us,
                p.t_last_us,
                p.n_events,
                640,
                480,
                "evt3",
                SENT_NS + (p.t_last_us - 1_010_000) * 1000,
                t_offset_us=p.t_offset_us,
                data=p.data,
            )
        )
    t_s = 1.0 + np.arange(N_T) * 1e-3
    x = np.tile(np.linspace(100, 300, N_S), (N_T, 1))
    y = 240 + np.arange(N_T)[:, None] * np.linspace(0, 1, N_S)[None, :]
    joints = np.tile(np.linspace(100, 300, N_J + 1), (N_T, 1))
    delta, used = 0.5 + np.arange(N_T) * 0.1, 1000 + np.arange(N_T)
    logger.centrelines(
        CentrelineMessage.from_batch(
            CentrelineBatch(t_s, np.linspace(0, 200, N_S), x, y, joints, joints * 0 + 240, delta, used),
            source="tracker",
            seq=0,
            units="px",
            source_ns=np.zeros(N_T, dtype=np.int64),
        )
    )
    assert logger.frame(0.0, force=True)
    logger.rate(EventRate("cam0", 1_010_000, 0.1, 123, 4.5e6, 0.2))
    logger.tunnel(TunnelState(speed_mps=5.25, setpoint_mps=5.5, state="running", t_wall_s=SENT_NS * 1e-9))
    logger.close()  # queued rows are sent at the next due frame, or here
    rec.flush()
    rec.disconnect()
    truth = {"t_s": t_s, "tip_y": y[:, -1], "delta": delta, "used": used, "events": events}
    return _columns(rrd), truth


def test_joints_are_one_point_set_per_update(logged: tuple) -> None:
    columns, truth = logged
    joints = columns["/tracker/joints"]
    assert len(joints["Points2D:positions"]) == N_T
    assert all(len(points) == N_J + 1 for points in joints["Points2D:positions"])
    np.testing.assert_allclose(np.array(joints["camera"]) * 1e-9, truth["t_s"], atol=1e-9)


@pytest.mark.parametrize(
    ("entity", "key"), [("/plots/delta_rms", "delta"), ("/plots/events_per_update", "used"), ("/plots/tip_y", "tip_y")]
)
def test_per_update_scalars_hold_the_values(logged: tuple, entity: str, key: str) -> None:
    columns, truth = logged
    values = np.array([v[0] for v in columns[entity]["Scalars:scalars"]])
    np.testing.assert_allclose(values, truth[key])


def test_tip_trail_follows_the_tip(logged: tuple) -> None:
    columns, truth = logged
    strips = columns["/tracker/tip_trail"]["LineStrips2D:strips"]
    trail = np.array(strips[-1][0])
    assert trail.shape == (N_T, 2)
    np.testing.assert_allclose(trail[:, 1], truth["tip_y"], atol=1e-4)


def test_recent_events_are_drawn_with_age_colours(logged: tuple) -> None:
    columns, truth = logged
    positions = columns["/camera/events"]["Points2D:positions"][-1]
    events = truth["events"]
    recent = events[events["t"] >= events["t"].max() - 10_000]
    assert len(positions) == len(recent)  # under max_points: every recent event, none older
    assert len(columns["/camera/events"]["Points2D:colors"][-1]) == len(recent)


def test_event_rate_and_wind_speed_are_logged(logged: tuple) -> None:
    columns, _ = logged
    assert columns["/plots/event_rate_hz"]["Scalars:scalars"][-1][0] == pytest.approx(4.5e6)
    assert columns["/plots/wind_speed_mps"]["Scalars:scalars"][-1][0] == pytest.approx(5.25)
