"""A run folder explains itself: README.txt and run.json written with the summary, brought up to date when a run
is resumed, and `flagtrack runs list` over finished, interrupted, corrupt and foreign folders."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from flagtrack import daemon
from flagtrack.daemon import __version__
from flagtrack.daemon.cli import main
from flagtrack.daemon.sweep import summary
from flagtrack.daemon.sweep.plan import SpeedRange, SweepConfig, plan_points
from flagtrack.daemon.sweep.runfiles import README, RUN_JSON, command_line, run_status
from flagtrack.daemon.sweep.runlog import PointResult, RunLog, point_paths, read_run
from flagtrack.daemon.sweep.summary import summary_points, transition_speeds, write_summary
from flagtrack.daemon.typed_yaml import to_mapping

CFG = SweepConfig(range=SpeedRange(4.0, 5.0, 0.5), settle_s=1, record_s=2)  # up 4, 4.5, 5; down 4.5, 4
PLAN = plan_points(CFG)
FLAPPING = {"001-up-4.50": False, "002-up-5.00": True, "003-down-4.50": True}


def result(point, **changes) -> PointResult:
    flapping = FLAPPING.get(point.point_id, False)
    raw, lines = point_paths(point.point_id)
    values = dict(
        state="flapping" if flapping else "still",
        amplitude_over_l=0.25 if flapping else 0.001,
        frequency_hz=11.0 if flapping else math.nan,
        event_rate_mev_s=0.3 if flapping else 0.007,
        cloud_distance_mean_over_l=0.004,
        raw_file=raw,
        centreline_file=lines,
        sensor_status="ok",
        sensor_error_rms_over_l=0.004 if flapping else 0.002,
    )
    return PointResult.planned(point, **{**values, **changes})


def start_run(run_dir: Path, upto: int, stop: str | None, command: str = "flagtrack sweep -c rig.yaml") -> None:
    with RunLog.create(
        run_dir,
        run_id=run_dir.name,
        config={"rig": "lab", "sweep": to_mapping(CFG)},
        plan=PLAN,
        command=command,
        t_unix=1_790_000_000.0,
    ) as log:
        for point in PLAN[:upto]:
            (run_dir / point_paths(point.point_id)[0]).write_bytes(b"\x00" * 64)  # the point's raw file
            log.point(result(point))
        if stop is not None:
            log.stop(stop, error="OSError: serial port gone" if stop == "error" else None, t_unix=1_790_000_100.0)


def test_the_summary_writes_a_readme_and_a_run_json_that_describe_the_folder(tmp_path: Path) -> None:
    run_dir = tmp_path / "run-a"
    start_run(run_dir, upto=len(PLAN), stop="finished")
    write_summary(run_dir)
    run = json.loads((run_dir / RUN_JSON).read_text())
    points = summary_points(read_run(run_dir))
    assert run["format"] == "flagtrack-sweep-run" and run["format_version"] == 1 and run["written_by"] == __version__
    assert run["command"] == "flagtrack sweep -c rig.yaml" and run["status"] == "finished"
    assert (run["onset_mps"], run["decay_mps"]) == transition_speeds(points) == (5.0, 4.0)
    assert run["counts"] == {"planned": 5, "done": 5, "failed": 0, "lossy": 0}
    assert (
        [p["point_id"] for p in run["points"]]
        == [p.point_id for p in PLAN]
        == [p["point_id"] for p in run["plan"]["points"]]
    )
    assert run["plan"]["sweep"]["range"] == {"start": 4.0, "stop": 5.0, "step": 0.5} and run["rig"] == {"rig": "lab"}
    flapping = run["points"][2]
    assert flapping["amplitude_over_l"] == 0.25 and flapping["frequency_hz"] == 11.0
    assert flapping["sensor_error_rms_over_l"] == 0.004 and run["points"][0]["frequency_hz"] is None  # NaN: null
    listed = {f["path"]: f for f in run["files"]}
    for name in ("README.txt", "run.json", "run.jsonl", "summary.csv", "amplitude.png", "points/000-up-4.00.raw"):
        assert name in listed and (run_dir / name).is_file(), name
    assert listed["points/000-up-4.00.raw"]["bytes"] == 64 and "events" in listed["points/000-up-4.00.raw"]["what"]
    assert not [f for f in listed if not (run_dir / f).is_file()]
    readme = (run_dir / README).read_text()
    for part in (
        "flagtrack sweep -c rig.yaml",
        f"flagtrack {__version__}",
        "finished; 5 of 5 points done",
        "Onset      5 m/s",
        "Decay      4 m/s",
        "run.jsonl",
        "summary.csv",
        "amplitude.png",
        "points/*.raw  (5 files)",
        "002-up-5.00",
        "flagtrack sweep --resume",
    ):
        assert part in readme, part
    assert "validation.png" in readme and "_sensor.png" not in readme  # a kind of file is listed only when there


def test_a_resumed_run_gets_its_files_brought_up_to_date(tmp_path: Path) -> None:
    run_dir = tmp_path / "run-b"
    start_run(run_dir, upto=2, stop="SIGTERM")
    write_summary(run_dir)  # as the supervisor's safe state does at the end of each session
    first = json.loads((run_dir / RUN_JSON).read_text())
    assert first["status"] == "stopped" and first["status_detail"] == "SIGTERM" and first["counts"]["done"] == 2
    assert first["onset_mps"] is None and "stopped (SIGTERM); 2 of 5 points done" in (run_dir / README).read_text()
    log, _ = RunLog.resume(run_dir, command=f"flagtrack sweep --resume {run_dir}", t_unix=1_790_000_200.0)
    with log:
        for point in PLAN[2:]:
            log.point(result(point))
        log.stop("finished", t_unix=1_790_000_300.0)
    write_summary(run_dir)
    second = json.loads((run_dir / RUN_JSON).read_text())
    assert second["status"] == "finished" and second["counts"]["done"] == 5 and second["onset_mps"] == 5.0
    assert [r["command"] for r in second["resumes"]] == [f"flagtrack sweep --resume {run_dir}"]
    assert "Resumed    " in (readme := (run_dir / README).read_text()) and "5 of 5 points done" in readme


def test_the_folder_describes_itself_even_when_a_figure_fails(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    start_run(tmp_path, upto=3, stop="finished")

    def broken(*args, **kwargs):
        raise ValueError("Data cannot be log-scaled")

    monkeypatch.setattr(summary, "plot_amplitude", broken)
    with pytest.raises(ValueError, match="log-scaled"):  # the supervisor logs it ("summary failed")
        write_summary(tmp_path)
    assert json.loads((tmp_path / RUN_JSON).read_text())["counts"]["done"] == 3 and (tmp_path / README).is_file()


def test_the_status_says_whether_the_last_session_ended(tmp_path: Path) -> None:
    start_run(tmp_path / "killed", upto=1, stop=None)
    assert run_status(read_run(tmp_path / "killed"))[0] == "incomplete"
    start_run(tmp_path / "failed", upto=1, stop="error")
    assert run_status(read_run(tmp_path / "failed")) == ("error", "OSError: serial port gone")
    log, _ = RunLog.resume(tmp_path / "failed", t_unix=1_790_000_200.0)  # resumed, then killed: no stop after it
    log.close()
    assert run_status(read_run(tmp_path / "failed"))[0] == "incomplete"


def test_the_command_line_is_written_as_a_user_types_it() -> None:
    assert command_line(["/venv/bin/flagtrack", "sweep", "-c", "my rig.yaml"]) == "flagtrack sweep -c 'my rig.yaml'"
    module = str(Path(daemon.__file__).parent / "__main__.py")  # python -m flagtrack.daemon (an editable install)
    assert command_line([module, "demo", "--quick"]) == "flagtrack demo --quick"
    assert command_line(["/elsewhere/__main__.py", "x"]) == "/elsewhere/__main__.py x"
    assert command_line(["/usr/bin/pytest", "-q"]) == "/usr/bin/pytest -q"


def make_runs(runs: Path) -> None:
    start_run(runs / "a-finished", upto=len(PLAN), stop="finished")
    start_run(runs / "b-killed", upto=3, stop=None)
    start_run(runs / "c-corrupt", upto=3, stop="finished")
    log_path = runs / "c-corrupt" / "run.jsonl"
    lines = log_path.read_text().splitlines(keepends=True)
    log_path.write_text("".join([lines[0], '{"type": "point", "v": 1, "point_id": \n', *lines[2:]]))  # a torn middle
    (runs / "d-foreign").mkdir()
    (runs / "d-foreign" / "notes.txt").write_text("not a run")
    (runs / "e-empty-log").mkdir()
    (runs / "e-empty-log" / "run.jsonl").write_bytes(b"")
    (runs / "stray-file.txt").write_text("a file, not a folder: not listed")


def test_runs_list_shows_each_folder_with_its_status_or_why_it_is_not_a_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    make_runs(tmp_path)
    assert main(["runs", "list", str(tmp_path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["run", "started", "points", "onset", "m/s", "decay", "m/s", "status"]
    rows = {line.split()[0]: line for line in out[1:]}
    assert list(rows) == ["a-finished", "b-killed", "c-corrupt", "d-foreign", "e-empty-log"]
    assert rows["a-finished"].split()[3:7] == ["5/5", "5", "4", "finished"]
    assert "3/5" in rows["b-killed"] and "incomplete: no stop record" in rows["b-killed"]
    assert "unreadable:" in rows["c-corrupt"] and "malformed record" in rows["c-corrupt"]
    assert "not a run: no run.jsonl" in rows["d-foreign"]
    assert "unreadable:" in rows["e-empty-log"] and "start record" in rows["e-empty-log"]
    assert main(["runs", "list", str(tmp_path), "--json"]) == 0
    listed = {row["run"]: row for row in json.loads(capsys.readouterr().out)}
    assert listed["a-finished"]["onset_mps"] == 5.0 and listed["a-finished"]["decay_mps"] == 4.0
    assert listed["a-finished"]["points_done"] == listed["a-finished"]["points_planned"] == 5
    assert listed["a-finished"]["started_unix"] == 1_790_000_000.0 and listed["a-finished"]["reason"] is None
    assert listed["b-killed"]["status"] == "incomplete" and listed["c-corrupt"]["status"] == "unreadable"
    assert listed["d-foreign"]["status"] == "not a run" and listed["d-foreign"]["points_done"] is None


@pytest.mark.parametrize("t_unix", ["1e300", "NaN"])
def test_a_start_time_that_is_no_time_leaves_the_listing_whole(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], t_unix: str
) -> None:
    """It was an OverflowError / ValueError that aborted the whole listing, good runs included."""
    make_runs(tmp_path)
    log_path = tmp_path / "b-killed" / "run.jsonl"
    first, *rest = log_path.read_text().splitlines(keepends=True)
    start = json.loads(first)
    start["t_unix"] = float(t_unix)
    log_path.write_text("".join([json.dumps(start) + "\n", *rest]))
    assert main(["runs", "list", str(tmp_path), "--json"]) == 0
    listed = {row["run"]: row for row in json.loads(capsys.readouterr().out)}
    assert listed["b-killed"]["started"] is None and listed["b-killed"]["status"] == "incomplete"
    assert listed["a-finished"]["status"] == "finished"


def test_a_control_run_is_listed_as_one(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`demo --feedback`'s folder has its own README.txt and run.json; it was "not a run: no run.jsonl"."""
    make_runs(tmp_path)
    description = {"format": "flagtrack-control-run", "started_unix": 1_790_000_000.0, "status": "stopped",
                   "stop_reason": "Ctrl-C", "error": None}  # fmt: skip
    (tmp_path / "f-control").mkdir()
    (tmp_path / "f-control" / "run.json").write_text(json.dumps(description))
    assert main(["runs", "list", str(tmp_path)]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()[1:]}
    assert rows["f-control"].endswith("control run, stopped: Ctrl-C") and "not a run" in rows["d-foreign"]
    assert main(["runs", "list", str(tmp_path), "--json"]) == 0
    listed = {row["run"]: row for row in json.loads(capsys.readouterr().out)}
    assert listed["f-control"]["kind"] == "control" and listed["f-control"]["status"] == "stopped"
    assert listed["a-finished"]["kind"] == "sweep" and listed["d-foreign"]["kind"] is None


def test_runs_list_of_one_run_folder_and_of_a_missing_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    start_run(tmp_path / "only", upto=2, stop="SIGINT")
    assert main(["runs", "list", str(tmp_path / "only"), "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["run"] == "only" and row["status"] == "stopped" and row["reason"] == "SIGINT"
    assert main(["runs", "list", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"flagtrack runs: error: no such folder: {tmp_path / 'nowhere'}"]
