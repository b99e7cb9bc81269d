"""A run log's point records name files (`flagtrack validate`, `sweep --resume`): a point id that is not
one word, or a file path that leaves the run folder, is a format error naming the record, not a path."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from flagtrack.daemon.errors import FormatError
from flagtrack.daemon.sweep.plan import SpeedRange, SweepConfig, plan_points
from flagtrack.daemon.sweep.runlog import PointResult, RunLog, point_paths, read_run


def logged(tmp_path: Path, **changes: object) -> Path:
    point = plan_points(SweepConfig(range=SpeedRange(3.0, 3.5, 0.5), settle_s=1, record_s=1))[0]
    raw, lines = point_paths(point.point_id)
    with RunLog.create(tmp_path / "run", run_id="run", config={}, plan=[point]) as log:
        log.point(PointResult.planned(point, raw_file=raw, centreline_file=lines))
    path = tmp_path / "run" / "run.jsonl"
    records = [json.loads(line) for line in path.read_text().splitlines()]
    records[1].update(changes)
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    return tmp_path / "run"


def test_a_planned_point_reads_back(tmp_path: Path) -> None:
    (point,) = read_run(logged(tmp_path)).points
    assert point.point_id == "000-up-3.00" and point.raw_file == "points/000-up-3.00.raw"


@pytest.mark.parametrize(
    ("changes", "words"),
    [
        ({"point_id": "../../evil"}, "point_id '../../evil'"),
        ({"point_id": "a/b"}, "point_id 'a/b'"),
        ({"raw_file": "/etc/passwd"}, "raw_file '/etc/passwd' is not a path inside"),
        ({"centreline_file": "points/../../x.h5"}, "centreline_file"),
        ({"raw_file": "~root/x.raw"}, "raw_file"),
    ],
)
def test_a_point_record_that_names_files_outside_is_a_format_error(tmp_path: Path, changes: dict, words: str) -> None:
    run_dir = logged(tmp_path, **changes)
    with pytest.raises(FormatError, match="point record") as info:
        read_run(run_dir)
    assert words in str(info.value) and info.value.offset is not None
