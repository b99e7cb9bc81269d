"""`flagtrack sweep -c rig.yaml --runs-dir DIR`: the flag replaces the rig's runs_dir before it is checked, and a
rig without a sweep plan is one clear line (it was a ValueError traceback)."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest

from flagtrack.daemon.cli import main


def test_runs_dir_flag_is_checked_instead_of_the_rigs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the rig says its runs go")
    rig = tmp_path / "rig.yaml"
    rig.write_text(
        f"rig: s\ntunnel: {{driver: simulated}}\nsupervisor: {{runs_dir: {blocker / 'runs'}}}\nservices: [supervisor]\n"
    )
    assert main(["sweep", "-c", str(rig), "--runs-dir", str(tmp_path / "runs")]) == 2
    err = capsys.readouterr().err
    assert "needs a 'sweep:' plan" in err and "key 'supervisor.runs_dir'" not in err  # past the rig's runs_dir


def test_a_sweep_that_never_began_is_not_exit_0(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Services that do not appear in time: the run never starts; an unattended script must see it
    (it printed one warning and exited 0)."""
    import yaml

    rig = yaml.safe_load((Path(__file__).resolve().parents[2] / "deploy" / "rig-sensor-sim.yaml").read_text())
    rig["supervisor"].update(startup_timeout_s=0.001, runs_dir=str(tmp_path / "runs"))
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    assert main(["sweep", "-c", str(path), "-q"]) == 1
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1] == "flagtrack sweep: no run was started (the lines above say why)"


def _finished_run(run_dir: Path, last_status: str) -> Path:
    """A run whose log says it finished; its last point ``last_status``. Its stored config names a
    tunnel on a port that does not exist: starting the rig would fail loudly."""
    from flagtrack.daemon.sweep.plan import Branch, SweepConfig, plan_points
    from flagtrack.daemon.sweep.runlog import PointResult, RunLog

    points = plan_points(SweepConfig(speeds=(3.0, 4.0), branches=(Branch.UP,)))
    config = {"rig": "gone", "tunnel": {"driver": "ascii", "port": str(run_dir / "no-such-port")}}
    with RunLog.create(run_dir, run_id="night", config=config, plan=points) as log:
        for point in points:
            log.point(PointResult.planned(point, status=last_status if point is points[-1] else "done"))
        log.stop("finished")
    return run_dir


def test_resuming_a_finished_run_leaves_it_and_the_rig_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every point done: one line and exit 0, the run log untouched, no rig started (it started the
    whole rig, ramped nothing and appended a resume and a stop record)."""
    from flagtrack.daemon.sweep.restart import nothing_to_resume
    from flagtrack.daemon.sweep.runlog import read_run

    run_dir = _finished_run(tmp_path / "night", "done")
    before = (run_dir / "run.jsonl").read_bytes()
    assert main(["sweep", "--resume", str(run_dir), "-q"]) == 0
    err = capsys.readouterr().err
    assert f"flagtrack sweep: run {run_dir} is finished (2 of 2 points done); nothing to resume" in err
    assert f"log {run_dir / 'run.jsonl'}" in err
    assert (run_dir / "run.jsonl").read_bytes() == before

    # a finished run with a failed point still has work: it is resumed, as before
    failed = _finished_run(tmp_path / "failed", "failed")
    assert nothing_to_resume(read_run(failed)) is None


@pytest.mark.parametrize(("last_status", "words"), [("done", "exists and is finished: set another"),
                                                    ("failed", "exists: resume it (flagtrack sweep --resume "),
                                                    ("held", "is in use by pid ")])  # fmt: skip
def test_a_new_sweep_into_an_earlier_runs_folder_is_one_line_before_the_rig_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], last_status: str, words: str
) -> None:
    """A fixed supervisor.run_name run twice: the rig started, then three ERROR lines, exit 1, and a
    hint to resume a run that was finished."""
    import yaml

    from flagtrack.daemon.sweep.runlock import RunLock

    run_dir = _finished_run(tmp_path / "runs" / "night", "failed" if last_status == "held" else last_status)
    before = (run_dir / "run.jsonl").read_bytes()

    rig = yaml.safe_load((Path(__file__).resolve().parents[2] / "deploy" / "rig-sensor-sim.yaml").read_text())
    rig["supervisor"].update(runs_dir=str(tmp_path / "runs"), run_name="night")
    rig["tunnel"] = {"driver": "ascii", "port": str(tmp_path / "no-such-port")}  # (a rig that starts fails loudly)
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    with contextlib.ExitStack() as held:
        if last_status == "held":  # a sweep of it running: not "resume it"
            held.enter_context(RunLock.acquire(run_dir, "flagtrack sweep --resume runs/night"))
        assert main(["sweep", "-c", str(path), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "key 'supervisor.run_name'" in err[0] and f"run {run_dir} {words}" in err[0], err
    assert "set another supervisor.run_name (or --runs-dir)" in err[0]
    assert (run_dir / "run.jsonl").read_bytes() == before
