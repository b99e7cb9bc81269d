"""A short demo sweep (the demo's rig: twin camera, pty tunnel, tracker, recorder, supervisor, simulated
laser sensor, real Zenoh; 3 points instead of 17) reads the same wherever its numbers are shown (issue
32): the terminal's lines, README.txt, run.json, run.jsonl, summary.csv, the demo's report and --json,
and every figure the run draws, live and by ``flagtrack validate``: the figures' arguments are taken as
they are drawn and read back as matplotlib figures."""

from __future__ import annotations

import io
import json
from collections.abc import Callable
from typing import Any

import pytest

from flagtrack.daemon.commands._progress import SweepProgressView
from flagtrack.daemon.commands.demo import demo_report, demo_rig
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.rig.run import run_rig
from flagtrack.daemon.services.supervisor import sensor_check
from flagtrack.daemon.sweep import summary
from flagtrack.daemon.sweep.figures import amplitude_figure, sweep_figure
from flagtrack.daemon.sweep.runlog import point_record
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.daemon.validation import run as validation_run
from flagtrack.daemon.validation.figures import point_figure
from tests.results_agree import (
    check_demo_report,
    check_files,
    check_point_figure,
    check_sweep_figures,
    check_terminal,
)

pytestmark = pytest.mark.slow


def spy(monkeypatch: pytest.MonkeyPatch, module: Any, name: str, calls: list) -> None:
    """Note the arguments of every call of ``module.name`` (it still draws and saves as before)."""
    original: Callable[..., Any] = getattr(module, name)

    def noted(*args: Any, **kwargs: Any) -> Any:
        calls.append((args, kwargs))
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, noted)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("results") / "demo"
    config = demo_rig(out, headless=True, quick=True)
    config["supervisor"]["sweep"] = {"speeds": [4.0, 5.5], "branches": ["up", "down"], "settle_s": 1.0,
                                     "record_s": 1.5}  # fmt: skip
    config["services"] = [name for name in config["services"] if name != "viewer"]  # (the view: elsewhere)
    rig = from_mapping(RigConfig, config, key="demo")
    calls: dict[str, list] = {"point": [], "amplitude": [], "sweep": [], "validate_point": [], "validate_sweep": []}
    terminal = io.StringIO()
    with pytest.MonkeyPatch.context() as monkeypatch:
        spy(monkeypatch, sensor_check, "plot_point", calls["point"])
        spy(monkeypatch, summary, "plot_amplitude", calls["amplitude"])
        spy(monkeypatch, summary, "plot_sweep", calls["sweep"])
        spy(monkeypatch, validation_run, "plot_point", calls["validate_point"])
        spy(monkeypatch, validation_run, "plot_sweep", calls["validate_sweep"])
        with SweepProgressView(terminal, terminal=False) as progress:
            result = run_rig(rig, list(rig.services), shutdown_timeout_s=30.0, quiet=True, on_supervisor_state=progress)
        assert result.code == 0
        validation_run.validate_run(out / "sweep")
    return {"run_dir": out / "sweep", "terminal": terminal.getvalue().splitlines(), "calls": calls}


def test_the_terminal_the_files_and_the_report_agree(sweep: dict[str, Any]) -> None:
    run = check_files(sweep["run_dir"])
    assert [p["state"] for p in run["points"]] == ["still", "flapping", "still"]
    assert check_terminal(sweep["terminal"], run) == 3
    report, text = demo_report(sweep["run_dir"], None, 1.5)
    check_demo_report(text, report, run)
    assert not (sweep["run_dir"] / ".lock").exists()  # a finished run leaves no lock file


def test_the_figures_of_the_run_agree_with_its_files(sweep: dict[str, Any]) -> None:
    run = json.loads((sweep["run_dir"] / "run.json").read_text())
    calls = sweep["calls"]
    (points, _, amplitude_title, transitions), _ = calls["amplitude"][-1]
    (sweep_points, _, sweep_title), _ = calls["sweep"][-1]
    assert sweep_points == points
    check_sweep_figures(run, amplitude_figure(points, amplitude_title, transitions), sweep_figure(points, sweep_title))
    records = {p["point_id"]: p for p in run["points"]}
    assert len(calls["point"]) == 3
    for (validation, _, title), _ in calls["point"]:  # drawn live by the supervisor
        point_id = title.split("point ")[1].split(":")[0]
        assert title.startswith(f"run {run['run_id']}, point {point_id}")
        check_point_figure(point_figure(validation, title), records[point_id])


def test_the_figures_of_flagtrack_validate_agree_with_its_numbers(sweep: dict[str, Any]) -> None:
    calls = sweep["calls"]
    assert len(calls["validate_point"]) == 3
    for (validation, _, title, window_s), _ in calls["validate_point"]:
        check_point_figure(point_figure(validation, title, window_s), validation.fields())
    (points, _, title), _ = calls["validate_sweep"][-1]
    assert "recomputed" in title
    run_id = json.loads((sweep["run_dir"] / "run.json").read_text())["run_id"]
    recomputed = {"run_id": run_id, "points": [point_record(p) for p in points]}  # as validation.csv holds them
    check_sweep_figures(recomputed, None, sweep_figure(points, title))
    csv = (sweep["run_dir"] / "validation" / "validation.csv").read_text().splitlines()[0].split(",")
    assert "cloud_distance_mean_over_l" in csv and csv[-2:] == ["delta_rms_over_l", "delta_rms_std_over_l"]
