"""``flagtrack simulate`` writes real EVT 3.0 files and truth files; ``flagtrack metrics compare`` reads them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.drivers.formats import read_events
from flagtrack.drivers.formats.centreline import read_centrelines, write_centrelines
from flagtrack.drivers.sim.kinematics import FlagKinematics, sample_kinematics
from flagtrack.drivers.sim.render import LaserLineScene
from flagtrack.drivers.sim.scenes import simulate_events
from flagtrack.drivers.sim.simulate import RecordingSpec, optics_and_kinematics


def test_simulate_two_recordings_on_two_processes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(
            [
                "simulate",
                str(tmp_path),
                "--seed",
                "5",
                "--n",
                "2",
                "--duration",
                "0.02",
                "--jobs",
                "2",
                "--shot-noise",
                "0.5",
            ]
        )
        == 0
    )
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [Path(row["events"]).name for row in lines] == ["sim_00005.raw", "sim_00006.raw"]
    for seed in (5, 6):
        assert (tmp_path / f"sim_{seed:05d}.json").is_file()
    recording = read_events(tmp_path / "sim_00005.raw")
    assert recording.info.encoding == "evt3" and (recording.info.width, recording.info.height) == (640, 480)
    assert len(recording.events) == lines[0]["n_events"] > 10_000
    # the file holds exactly what the simulator generates for that seed
    spec = RecordingSpec(seed=5, duration_s=0.02)
    optics, kin = optics_and_kinematics(spec)
    from flagtrack.drivers.sim.dvs import DvsParams

    direct = np.concatenate(
        list(simulate_events(LaserLineScene(kin, optics, 640, 480), 0, 20_000, DvsParams(shot_noise_hz=0.5), seed=5))
    )
    np.testing.assert_array_equal(recording.events, direct)
    truth, attrs = read_centrelines(tmp_path / "sim_00005_truth.h5")
    assert attrs["units"] == "px" and attrs["length"] == pytest.approx(300.0)
    assert FlagKinematics.from_attrs(attrs["kinematics"]) == sample_kinematics(5, length=300.0, root=(150.0, 240.0))
    assert truth.joints_x.shape[1] == 11 and np.all(np.isnan(truth.delta_rms)) and np.all(truth.n_events == 0)
    x, y = kin.positions(truth.t_s[:3], truth.s)
    np.testing.assert_allclose(truth.x[:3], x)
    assert truth.t_s[-1] == pytest.approx(0.02)


def test_metrics_compare_prints_the_keys_in_order(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", str(tmp_path), "--seed", "2", "--duration", "0.1"]) == 0
    capsys.readouterr()
    truth_path = tmp_path / "sim_00002_truth.h5"
    truth, attrs = read_centrelines(truth_path)
    # a "reconstruction" at 1 kHz between the truth's samples, coarser in s, off by (3, 4) px:
    # delta = eps = 5 px = L / 60 up to the truth's linear interpolation in time
    kin = FlagKinematics.from_attrs(attrs["kinematics"])
    t_rec = np.arange(1e-4, 0.1, 1e-3)
    s_rec = np.linspace(0.0, 300.0, 51)
    x, y = kin.positions(t_rec, s_rec)
    n = len(t_rec)
    recon = CentrelineBatch(
        t_s=t_rec,
        s=s_rec,
        x=x + 3.0,
        y=y + 4.0,
        joints_x=x[:, ::5],
        joints_y=y[:, ::5],
        delta_rms=np.ones(n),
        n_events=np.ones(n, np.int64),
    )
    recon_path = tmp_path / "recon.h5"
    write_centrelines(recon_path, recon, {"units": "px", "length": 300.0})
    assert main(["metrics", "compare", str(recon_path), str(truth_path), "--json"]) == 0
    values = json.loads(capsys.readouterr().out)
    assert list(values)[:4] == ["tip_error_rms_over_l", "max_eps_rms_over_l", "twi", "twi_ref"]
    assert values["tip_error_rms_over_l"] == pytest.approx(5.0 / 300.0, rel=1e-3) == values["delta_rms_over_l"]
    assert values["max_eps_rms_over_l"] == pytest.approx(5.0 / 300.0, rel=1e-3)
    assert values["twi"] == pytest.approx(values["twi_ref"], abs=0.01)
    assert values["t_start_s"] == pytest.approx(1e-4) and values["t_stop_s"] < 0.1
    assert main(["metrics", "compare", str(truth_path), str(truth_path)]) == 0
    text = capsys.readouterr().out
    assert text.splitlines()[0].split()[:2] == ["tip_error_rms_over_l", "0"]
    assert main(["metrics", "compare", str(tmp_path / "missing.h5"), str(truth_path)]) == 2


def test_simulate_checkerboard(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", str(tmp_path), "--checkerboard", "--periods", "1", "--blink-ms", "20"]) == 0
    capsys.readouterr()
    params = json.loads((tmp_path / "checkerboard.json").read_text())
    corners = np.array(params["corners_px"])
    assert corners.shape == (54, 2) and params["units"] == "m"
    assert (
        corners[:, 0].min() > 0 and corners[:, 0].max() < 639 and corners[:, 1].min() > 0 and corners[:, 1].max() < 479
    )
    events = read_events(tmp_path / "checkerboard.raw").events
    assert len(events) == params["n_events"] > 1000
