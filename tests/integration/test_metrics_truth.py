"""``flagtrack metrics compare`` with ground truths as users have them: a truth from another simulator
(only /t, /s, /x, /y, no attributes), a full flagtrack truth, and one missing /x."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.drivers.formats.centreline import write_centrelines

L = 300.0
N_J = 10


def flag(t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A flag along x from (150, 240) with a wave travelling to its tip, 8 Hz, 30 px at the tip."""
    x = 150.0 + np.broadcast_to(s[None, :], (len(t_s), len(s)))
    y = 240.0 + 30.0 * (s / L)[None, :] * np.sin(2 * np.pi * (8.0 * t_s[:, None] - s[None, :] / L))
    return x, y


def recon_file(path: Path, offset: tuple[float, float] = (3.0, 4.0), n_joints: int = N_J) -> Path:
    """A "reconstruction" at 1 kHz, the flag moved by ``offset``, Delta_RMS 1.5 px."""
    t, s = np.arange(0.0, 0.5, 1e-3), np.linspace(0.0, L, 51)
    x, y = flag(t, s)
    jx, jy = flag(t, np.linspace(0.0, L, n_joints + 1))
    n = len(t)
    batch = CentrelineBatch(
        t_s=t,
        s=s,
        x=x + offset[0],
        y=y + offset[1],
        joints_x=jx + offset[0],
        joints_y=jy + offset[1],
        delta_rms=np.full(n, 1.5),
        n_events=np.full(n, 100, np.int64),
    )
    write_centrelines(path, batch, {"units": "px", "length": L})
    return path


def truth_file(path: Path, datasets: tuple[str, ...], n_joints: int = N_J) -> Path:
    """A truth at 2 kHz holding only ``datasets`` (names of the layout), no attributes at all."""
    t, s = np.arange(0.0, 0.5, 5e-4), np.linspace(0.0, L, 101)
    x, y = flag(t, s)
    jx, jy = flag(t, np.linspace(0.0, L, n_joints + 1))
    data = {
        "t": t,
        "s": s,
        "x": x,
        "y": y,
        "joints/x": jx,
        "joints/y": jy,
        "delta_rms": np.full(len(t), 0.5),
        "n_events": np.zeros(len(t), np.int64),
    }
    with h5py.File(path, "w") as f:
        for name in datasets:
            f.create_dataset(name, data=data[name])
    return path


def compare(recon: Path, truth: Path, capsys: pytest.CaptureFixture[str]) -> tuple[dict, str]:
    assert main(["metrics", "compare", str(recon), str(truth), "--json"]) == 0
    out = capsys.readouterr()
    return json.loads(out.out), out.err


def test_a_truth_with_only_t_s_x_y_is_compared_and_says_what_it_used(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    truth = truth_file(tmp_path / "other_simulator.h5", ("t", "s", "x", "y"))
    values, err = compare(recon_file(tmp_path / "recon.h5"), truth, capsys)
    # the tip is off by (3, 4) px everywhere: 5 px over L, L from /s as the truth has no attribute
    assert values["tip_error_rms_over_l"] == pytest.approx(5.0 / L, rel=1e-3)
    assert values["max_eps_rms_over_l"] == pytest.approx(5.0 / L, rel=1e-3)
    assert values["twi"] == pytest.approx(values["twi_ref"], abs=1e-3) and values["twi"] > 0.3
    assert values["length"] == pytest.approx(L)
    assert values["cloud_distance_rms_over_l"] == pytest.approx(1.5 / L)
    assert values["truth_datasets"] == ["t", "s", "x", "y"]
    assert values["joint_rms_over_l"] is None and values["cloud_distance_rms_ref_over_l"] is None
    assert set(values["not_available"]) == {"joint_rms_over_l", "cloud_distance_rms_ref_over_l", "cloud_rms_ref_over_l"}
    # the names before the tip error and the cloud distance were told apart still read, with the same values
    assert values["aliases"]["delta_rms_over_l"] == "tip_error_rms_over_l"
    for old, new in values["aliases"].items():
        assert values[old] == values[new]
    lines = err.splitlines()
    assert lines[0] == f"flagtrack metrics: truth {truth}: used /t /s /x /y; L = 300 from the span of its /s"
    assert "joint_rms_over_l not available: the truth has no joints (/joints/x, /joints/y)" in lines[1]
    assert "cloud_distance_rms_ref_over_l not available: the truth has no Delta_RMS (/delta_rms)" in lines[2]


def test_the_text_output_prints_n_a_for_what_the_truth_lacks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    truth = truth_file(tmp_path / "other_simulator.h5", ("t", "s", "x", "y", "delta_rms"))
    assert main(["metrics", "compare", str(recon_file(tmp_path / "recon.h5")), str(truth)]) == 0
    rows = dict(line.split(maxsplit=1) for line in capsys.readouterr().out.splitlines())
    assert rows["joint_rms_over_l"] == "n/a (the truth has no joints)"
    value, percent = rows["cloud_distance_rms_ref_over_l"].split()[:2]  # a fraction, then % of L for a person
    assert float(value) == pytest.approx(0.5 / L, rel=1e-5)  # 6 digits printed
    assert float(percent.strip("(")) == pytest.approx(100 * 0.5 / L, rel=1e-2)
    assert list(rows)[:4] == ["tip_error_rms_over_l", "max_eps_rms_over_l", "twi", "twi_ref"]


def test_a_full_truth_gives_the_joint_error_and_its_delta_rms(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    truth = truth_file(tmp_path / "full.h5", ("t", "s", "x", "y", "joints/x", "joints/y", "delta_rms", "n_events"))
    values, err = compare(recon_file(tmp_path / "recon.h5"), truth, capsys)
    assert values["joint_rms_over_l"] == pytest.approx(5.0 / L, rel=1e-3)
    assert values["cloud_distance_rms_ref_over_l"] == pytest.approx(0.5 / L)
    assert values["truth_datasets"] == ["t", "s", "x", "y", "joints/x", "joints/y", "delta_rms"]
    assert values["not_available"] == {}
    assert err.splitlines() == [
        f"flagtrack metrics: truth {truth}: used /t /s /x /y /joints/x /joints/y "
        "/delta_rms; L = 300 from the span of its /s"
    ]


def test_joints_of_another_chain_are_not_compared(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth = truth_file(tmp_path / "five.h5", ("t", "s", "x", "y", "joints/x", "joints/y"), n_joints=5)
    values, err = compare(recon_file(tmp_path / "recon.h5"), truth, capsys)
    assert values["joint_rms_over_l"] is None
    assert values["not_available"]["joint_rms_over_l"] == "the truth has 6 joints, the reconstruction 11"
    assert "joint_rms_over_l not available: the truth has 6 joints, the reconstruction 11" in err


def test_a_truth_without_x_is_one_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth = truth_file(tmp_path / "no_x.h5", ("t", "s", "y", "joints/x", "joints/y", "delta_rms"))
    assert main(["metrics", "compare", str(recon_file(tmp_path / "recon.h5")), str(truth)]) == 2
    out = capsys.readouterr()
    assert out.out == ""
    assert out.err.splitlines() == [
        f"flagtrack metrics: error: {truth}: ground truth has no /x dataset (a truth needs /t, /s, /x, /y)"
    ]


@pytest.mark.parametrize("length", [0.0, float("nan"), -1.0])
def test_a_truth_length_that_is_no_length_is_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], length: float
) -> None:
    """0 was a ZeroDivisionError traceback, NaN printed NaN results."""
    truth = truth_file(tmp_path / "truth.h5", ("t", "s", "x", "y"))
    with h5py.File(truth, "a") as f:
        f.attrs["length"] = length
    assert main(["metrics", "compare", str(recon_file(tmp_path / "recon.h5")), str(truth)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and f"{truth}: ground truth: attribute 'length' must be a positive number" in err[0], err


def test_a_reconstruction_of_disagreeing_shapes_is_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recon = recon_file(tmp_path / "recon.h5")
    with h5py.File(recon, "a") as f:
        x = f["x"][()]
        del f["x"]
        f.create_dataset("x", data=x[:, :1])
    truth = truth_file(tmp_path / "truth.h5", ("t", "s", "x", "y"))
    assert main(["metrics", "compare", str(recon), str(truth)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and f"{recon}: not a flagtrack centreline file: " in err[0], err


@pytest.mark.parametrize("bad", ["nan", "descending"])
def test_a_reconstruction_whose_times_are_no_times_is_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], bad: str
) -> None:
    recon = recon_file(tmp_path / "recon.h5")
    with h5py.File(recon, "a") as f:
        t = f["t"][()]
        f["t"][...] = np.where(np.arange(len(t)) == 3, np.nan, t) if bad == "nan" else t[::-1]
    truth = truth_file(tmp_path / "truth.h5", ("t", "s", "x", "y"))
    assert main(["metrics", "compare", str(recon), str(truth)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "/t is not finite and increasing" in err[0], err
