"""What an operator sees, read back from the .rrd file with Rerun's reader: the layout (a blueprint)
in the file, A/L of a flapping tip, the supervisor's state and sweep log, lost flags when sent."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, SupervisorState
from flagtrack.daemon.services.viewer import RerunLogger, ViewerConfig, open_recording

L = 300.0


def columns(rrd: Path) -> dict[str, dict[str, list[Any]]]:
    """{entity: {column: values}} of the recording (times as int64 ns)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    out: dict[str, dict[str, list[Any]]] = {}
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            column = batch.column(name)
            if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
                column = column.cast(pa.int64())
            out.setdefault(chunk.entity_path, {}).setdefault(name, []).extend(column.to_pylist())
    return out


def blueprint_views(rrd: Path) -> dict[str, dict[str, Any]]:
    """{view name: {kind, origin, contents, time_ranges}} of the blueprint stored in ``rrd``."""
    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    assert len(reader.blueprints()) == 1, "no blueprint in the file"
    parts: dict[str, dict[str, Any]] = {}
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        view = chunk.entity_path.split("/")[2] if chunk.entity_path.startswith("/view/") else None
        if view is None:
            continue
        got = parts.setdefault(view, {})
        for name, key in (
            ("ViewBlueprint:display_name", "name"),
            ("ViewBlueprint:class_identifier", "kind"),
            ("ViewBlueprint:space_origin", "origin"),
            ("ViewContents:query", "contents"),
            ("VisibleTimeRanges:ranges", "time_ranges"),
        ):
            if name in batch.schema.names:
                value = batch.column(name).to_pylist()[-1]
                got[key] = value[0] if key in ("name", "kind", "origin") else value
    return {view.pop("name"): view for view in parts.values()}


def recorded(tmp_path: Path, feed: Any, **cfg: Any) -> Path:
    rrd = tmp_path / "view.rrd"
    config = ViewerConfig(sink="rrd", rrd_path=rrd, **cfg)
    rec, _ = open_recording(config)
    logger = RerunLogger(rec, config)
    feed(logger)
    logger.close()
    rec.flush()
    rec.disconnect()
    return rrd


def test_the_file_carries_the_layout(tmp_path: Path) -> None:
    views = blueprint_views(recorded(tmp_path, lambda logger: None))
    assert views["camera"]["kind"] == "2D"
    assert views["camera"]["contents"] == ["camera/events", "tracker/**"]
    series = {
        "tip y": "plots/tip_y",
        "A/L": "plots/amplitude_over_l",
        "event rate": "plots/event_rate_hz",
        "wind speed": "plots/wind_speed_mps",
        "Δ_RMS": "plots/delta_rms",
        "lost": "plots/lost",
        "shed": "plots/shed",
    }
    for name, origin in series.items():
        assert (views[name]["kind"], views[name]["origin"]) == ("TimeSeries", origin)
    assert views["tip y"]["time_ranges"][0]["timeline"] == "camera"  # the last seconds of a kHz series
    assert (views["supervisor"]["kind"], views["supervisor"]["origin"]) == ("TextDocument", "supervisor/state")
    assert (views["sweep log"]["kind"], views["sweep log"]["origin"]) == ("TextLog", "supervisor/log")


def flapping(seq: int, amplitude: float, direction_deg: float, n_t: int = 100, lost: bool = False) -> Any:
    """Updates at 1 kHz of a straight flag from (150, 240) along ``direction_deg`` whose tip swings
    +-``amplitude`` L at 5 Hz perpendicular to it."""
    t = (seq * n_t + np.arange(n_t)) * 1e-3
    s = np.linspace(0.0, L, 31)
    d = np.deg2rad(direction_deg)
    lateral = amplitude * L * np.sin(2 * np.pi * 5.0 * t)[:, None] * (s / L)[None, :]
    x = 150.0 + s[None, :] * np.cos(d) - lateral * np.sin(d)
    y = 240.0 + s[None, :] * np.sin(d) + lateral * np.cos(d)
    flags = (np.arange(n_t) % 10 == 0) if lost else None  # the tracker's /lost: every tenth update
    batch = CentrelineBatch(t, s, x, y, x[:, ::3], y[:, ::3], np.ones(n_t), np.ones(n_t, np.int64), lost=flags)
    return CentrelineMessage.from_batch(
        batch, source="tracker", seq=seq, units="px", source_ns=np.zeros(n_t, dtype=np.int64)
    )


def test_a_over_l_of_a_flapping_tip_in_a_tilted_frame(tmp_path: Path) -> None:
    def feed(logger: RerunLogger) -> None:
        for seq in range(20):  # 2 s of a 0.2 L tip amplitude, the flag at 30 degrees
            logger.centrelines(flapping(seq, 0.2, 30.0))
            logger.frame(seq * 0.125)  # frames due at 8 Hz: one after each message

    values = columns(recorded(tmp_path, feed, geometry_rate_hz=8.0, amplitude_window_s=1.0))["/plots/amplitude_over_l"]
    a_over_l = np.array([v[0] for v in values["Scalars:scalars"]])
    assert len(a_over_l) == 20
    np.testing.assert_allclose(a_over_l[10:], 0.2, atol=2e-3)  # once the window holds whole periods
    assert values["SeriesLines:names"] == [["A/L"]]


def test_lost_flags_are_a_series(tmp_path: Path) -> None:
    plain = columns(recorded(tmp_path, lambda logger: logger.centrelines(flapping(0, 0.1, 0.0)), update_rate_hz=None))
    found = np.array([v[0] for v in plain["/plots/lost"]["Scalars:scalars"]])
    assert "/plots/tip_y" in plain and len(found) == 100 and not found.any()
    (tmp_path / "view.rrd").unlink()
    flagged = columns(
        recorded(tmp_path, lambda logger: logger.centrelines(flapping(0, 0.1, 0.0, lost=True)), update_rate_hz=None)
    )
    lost = np.array([v[0] for v in flagged["/plots/lost"]["Scalars:scalars"]])
    np.testing.assert_array_equal(lost, (np.arange(100) % 10 == 0).astype(float))


def test_the_share_shed_is_a_series(tmp_path: Path) -> None:
    message = flapping(0, 0.1, 0.0)
    shed = np.where(np.arange(100) % 4 == 0, 0.75, 0.0).astype(np.float32)  # every fourth after a skip
    message = dataclasses.replace(message, shed=shed)
    got = columns(recorded(tmp_path, lambda logger: logger.centrelines(message), update_rate_hz=None))["/plots/shed"]
    np.testing.assert_allclose([v[0] for v in got["Scalars:scalars"]], shed)
    assert got["SeriesLines:names"] == [["shed"]]
    (tmp_path / "view.rrd").unlink()
    thinned = columns(recorded(tmp_path, lambda logger: logger.centrelines(message)))["/plots/shed"]
    values = np.array([v[0] for v in thinned["Scalars:scalars"]])
    assert len(values) < 100 and np.count_nonzero(values == np.float32(0.75)) == 25  # every update that shed shows


@dataclasses.dataclass(frozen=True)
class WithProgress(SupervisorState):
    """A SupervisorState with per-point fields, as the supervisor will publish them."""

    index: int = 0
    total: int = 0
    amplitude_over_l: float | None = None


def test_the_supervisor_state_is_a_document_and_its_changes_a_log(tmp_path: Path) -> None:
    wall0 = 1_000.0
    states = [
        SupervisorState("unknown", 0.0, "sweep"),  # before the camera clock is known: waits
        SupervisorState("still", 5e3, "sweep"),  # replaces it
        WithProgress("still", 5e3, "sweep", "000-up-4.20", "up", 4.2, index=1, total=5),
        WithProgress("still", 6e3, "sweep", "000-up-4.20", "up", 4.2, index=1, total=5),  # no new log line
        WithProgress("flapping", 9e4, "sweep", "001-up-4.70", "up", 4.7, index=2, total=5, amplitude_over_l=0.21),
        SupervisorState("still", 5e3, "safe", message="finished"),
    ]

    def feed(logger: RerunLogger) -> None:
        logger.supervisor(states[0], wall0)
        logger.supervisor(states[1], wall0 + 0.5)
        # camera time 10 s at wall 1001 s: the camera clock is wall - 991 s
        logger.events(EventPacket("cam0", 0, 9_999_000, 10_000_000, 0, 640, 480, "evt3", 1_001_000_000_000))
        for k, state in enumerate(states[2:]):
            logger.supervisor(state, wall0 + 2 + k)

    got = columns(recorded(tmp_path, feed))
    documents = got["/supervisor/state"]
    texts = [v[0] for v in documents["TextDocument:text"]]
    assert len(texts) == 5
    np.testing.assert_allclose(np.array(documents["camera"]) * 1e-9, [9.5, 11, 12, 13, 14])
    assert texts[0].startswith("**still** · sweep · 0.00 m/s")
    assert texts[1].startswith("**still** · sweep · point `000-up-4.20` (up) · 4.20 m/s · event rate 5e+03 ev/s")
    assert "| index | 1 |" in texts[1] and "| total | 5 |" in texts[1] and "amplitude_over_l" not in texts[1]
    assert "| amplitude_over_l | 0.21 |" in texts[3]
    assert texts[4].endswith("\n\nfinished")
    assert {v[0] for v in documents["TextDocument:media_type"]} == {"text/markdown"}
    log = [v[0] for v in got["/supervisor/log"]["TextLog:text"]]
    assert log == [
        "sweep: flag still",
        "sweep, point 000-up-4.20 (up): flag still",
        "sweep, point 001-up-4.70 (up): flag flapping",
        "safe: flag still; finished",
    ]


@pytest.mark.parametrize("t_wall_s", [float("nan"), float("inf")])
def test_a_state_at_a_time_rerun_cannot_place_is_refused_alone(tmp_path: Path, t_wall_s: float) -> None:
    def feed(logger: RerunLogger) -> None:
        logger.events(EventPacket("cam0", 0, 0, 1_000, 0, 640, 480, "evt3", 1_000_000_000))
        logger.supervisor(SupervisorState("still", 1.0, "sweep"), 5.0)
        with pytest.raises(ValueError, match="cannot place"):
            logger.supervisor(SupervisorState("flapping", 1.0, "sweep"), t_wall_s)
        logger.supervisor(SupervisorState("still", 1.0, "safe"), 6.0)

    texts = columns(recorded(tmp_path, feed))["/supervisor/state"]["TextDocument:text"]
    assert len(texts) == 2  # the two others, in one chunk, unharmed


def test_the_supervisor_document_shows_the_progress_fields_it_is_given() -> None:
    """The sweep's progress fields of SupervisorState appear when set, and not at their "not known" default."""
    from flagtrack.daemon.services.viewer.logger import supervisor_text

    text = supervisor_text(
        SupervisorState(
            "flapping",
            9e4,
            "sweep",
            "004-up-5.00",
            "up",
            5.0,
            point_index=5,
            points_total=17,
            amplitude_over_l=0.255,
            eta_s=59.0,
        )
    )
    assert "| point_index | 5 |" in text and "| points_total | 17 |" in text and "| amplitude_over_l | 0.255 |" in text
    assert "lost_fraction" not in text and "sensor_error_rms_over_l" not in text  # -1: not known
