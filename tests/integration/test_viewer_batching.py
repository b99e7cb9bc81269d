"""The viewer's rows reach the .rrd file in few chunks (read back with Rerun's own reader), and a live
viewer gets them within ``flush_s``."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.schema import CentrelineMessage
from flagtrack.daemon.services.viewer import RerunLogger, ViewerConfig, open_recording

N_S = 51


def message(seq: int, n_t: int = 10) -> CentrelineMessage:
    t = (seq * n_t + np.arange(n_t)) * 1e-3
    x = np.tile(np.linspace(100.0, 300.0, N_S), (n_t, 1))
    y = 240.0 + np.sin(t)[:, None] * np.linspace(0.0, 1.0, N_S)[None, :]
    batch = CentrelineBatch(
        t, np.linspace(0.0, 200.0, N_S), x, y, x[:, ::5], y[:, ::5], np.full(n_t, 0.7), np.full(n_t, 50, np.int64)
    )
    return CentrelineMessage.from_batch(
        batch, source="tracker", seq=seq, units="px", source_ns=np.zeros(n_t, dtype=np.int64)
    )


def chunks(rrd: Path) -> tuple[Counter, dict[str, list[int]]]:
    """Chunks per entity, and each entity's times (ns) in file order."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    count: Counter = Counter()
    times: dict[str, list[int]] = {}
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        if "camera" in batch.schema.names:  # static chunks (series names, radii) have no time
            count[chunk.entity_path] += 1
            times.setdefault(chunk.entity_path, []).extend(batch.column("camera").cast(pa.int64()).to_pylist())
    return count, times


def test_a_file_gets_busy_entities_in_chunks_of_chunk_bytes_and_quiet_ones_in_one(tmp_path: Path) -> None:
    """1000 updates over 1 s of frames at 30 Hz: before, every frame sent a chunk per entity (30 each);
    now the centrelines (416 bytes an update) and joints (100) go in chunks of 20 000 bytes and the
    scalars (16 bytes an update) wait for rrd_flush_s or the end: one chunk each."""
    rrd = tmp_path / "batched.rrd"
    cfg = ViewerConfig(sink="rrd", rrd_path=rrd, update_rate_hz=None, chunk_bytes=20_000, rrd_flush_s=30.0)
    rec, _ = open_recording(cfg)
    logger = RerunLogger(rec, cfg)
    for seq in range(100):
        logger.centrelines(message(seq))
        logger.frame(seq * 0.01)
    logger.close()
    rec.flush()
    rec.disconnect()
    count, times = chunks(rrd)
    assert count["/tracker/centreline"] == 20  # 5 messages of 10 x 416 bytes pass 20 000
    assert count["/tracker/joints"] == 5  # 11 joints: 20 messages of 10 x 100 bytes
    assert count["/plots/tip_y"] == 1 and count["/plots/delta_rms"] == 1
    assert count["/plots/amplitude_over_l"] == 1  # a value per frame (30)
    assert count["/tracker/tip_trail"] <= 5  # a strip of up to 500 tips (4 kB) per frame
    expected = np.round((np.arange(1000) * 1e-3) * 1e9).astype(np.int64)
    for entity in ("/tracker/centreline", "/tracker/joints", "/plots/tip_y"):
        np.testing.assert_array_equal(times[entity], expected)


def test_a_live_viewer_gets_queued_rows_within_flush_s(tmp_path: Path) -> None:
    cfg = ViewerConfig(sink="rrd", rrd_path=tmp_path / "live.rrd", update_rate_hz=None, flush_s=0.25)
    rec, _ = open_recording(cfg)
    logger = RerunLogger(rec, cfg, live=True)
    queue = logger.queues.get
    logger.centrelines(message(0))
    assert logger.frame(100.0)  # a frame is drawn (trail, ...), the rows wait: 0 s old
    assert queue("tracker/centreline").n_rows == 10
    logger.centrelines(message(1))
    logger.frame(100.2)
    assert queue("tracker/centreline").n_rows == 20  # the oldest has waited 0.2 s
    logger.frame(100.25)
    assert queue("tracker/centreline").n_rows == 0 and queue("plots/tip_y").n_rows == 0
    logger.centrelines(message(2))
    logger.frame(100.3)
    logger.frame(100.55)
    assert queue("tracker/centreline").n_rows == 0
    rec.flush()
    rec.disconnect()
    count, times = chunks(tmp_path / "live.rrd")
    assert count["/tracker/centreline"] == 2 and count["/plots/tip_y"] == 2
    assert len(times["/plots/tip_y"]) == 30


def test_a_file_gets_quiet_entities_every_rrd_flush_s(tmp_path: Path) -> None:
    rrd = tmp_path / "periodic.rrd"
    cfg = ViewerConfig(sink="rrd", rrd_path=rrd, update_rate_hz=None, rrd_flush_s=5.0)
    rec, _ = open_recording(cfg)
    logger = RerunLogger(rec, cfg)
    for seq in range(12):  # a message a second for 12 s: sent at 5 s, 10 s and the end
        logger.centrelines(message(seq))
        logger.frame(float(seq))
    logger.close()
    rec.flush()
    rec.disconnect()
    count, _ = chunks(rrd)
    assert count["/plots/tip_y"] == 3 and count["/tracker/centreline"] == 3
