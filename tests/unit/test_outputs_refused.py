"""An output that would destroy an input or a file of another kind is refused before any work: one
line naming the option, exit 2, the file left as it was (it was overwritten, exit 0)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.drivers.formats.files import write_events

RIG = "rig: t\ncamera: {adapter: simulated}\ntracker: {root: [150, 240], length: 300}\n"


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    events = np.zeros(100, EVENT_DTYPE)
    events["t"] = np.arange(100) * 10
    write_events(tmp_path / "rec.raw", events, width=640, height=480)
    write_events(tmp_path / "other.raw", events, width=640, height=480)  # a recording made before
    (tmp_path / "rig.yaml").write_text(RIG)
    (tmp_path / "rig.yaml.csv").write_text("t,x,y,p\n")
    (tmp_path / "old.png").write_text("notes, not a picture")
    (tmp_path / "empty.csv").write_text("")
    (tmp_path / "cut.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(2000))
    return tmp_path


CASES = [
    (["geometry", "rec.raw", "-o", "rec.raw"], "-o rec.raw: is the input rec.raw itself"),
    (["geometry", "rec.raw", "-o", "rig.yaml"], "-o rig.yaml: holds something else than a tracker: section"),
    (["calibrate", "rec.raw", "--board", "9x6", "--square-mm", "20", "-o", "rec.raw"], "-o rec.raw: is the input"),
    (["calibrate", "rec.raw", "--board", "9x6", "--square-mm", "20", "-o", "rig.yaml"], "than a calibration"),
    (["calibrate", "rec.raw", "--board", "9x6", "--square-mm", "20", "-o", "c.yaml", "--figure", "rec.raw"],
     "--figure rec.raw: is the input"),
    (["aim", "--replay", "rec.raw", "--snapshot", "rec.raw", "--viewer", "none", "-q"], "--snapshot rec.raw: is the input"),
    (["aim", "--replay", "rec.raw", "--rrd", "rig.yaml", "-c", "rig.yaml", "-q"], "--rrd rig.yaml: is the input"),
    (["up", "--replay", "rec.raw", "--centrelines", "rec.raw", "--exit-at-eof", "-q"], "--centrelines rec.raw: is the input"),
    (["up", "-c", "rig.yaml", "--rrd", "rig.yaml", "-q"], "--rrd rig.yaml: is the input"),
    (["reconstruct", "rec.raw", "-o", "rig.yaml", "-c", "rig.yaml"], "-o rig.yaml: is the config file itself"),
    (["up", "-c", "rig.yaml", "--root", "900", "100", "-q"], "--root: (900, 100) is off the 640 x 480 sensor"),
    # a file of another kind: each was overwritten, exit 0 (a recording became HDF5, a config a picture)
    (["reconstruct", "rec.raw", "-o", "other.raw", "--root", "150", "240", "--length", "300"],
     "-o other.raw: holds something else than flagtrack centrelines (HDF5)"),
    (["reconstruct", "rec.raw", "-o", "rig.yaml", "--root", "150", "240", "--length", "300"],
     "-o rig.yaml: holds something else than flagtrack centrelines"),
    (["up", "--replay", "rec.raw", "--centrelines", "rig.yaml", "--exit-at-eof", "-q"],
     "--centrelines rig.yaml: holds something else than flagtrack centrelines"),
    (["up", "-c", "rig.yaml", "--rrd", "other.raw", "-q"], "--rrd other.raw: holds something else than a Rerun view"),
    (["aim", "--replay", "rec.raw", "--rrd", "rig.yaml", "-q"], "--rrd rig.yaml: holds something else than a Rerun"),
    (["aim", "--replay", "rec.raw", "--snapshot", "rig.yaml", "--viewer", "none", "-q"],
     "--snapshot rig.yaml: give a picture file (.png, .pdf, .svg), not .yaml"),
    (["aim", "--replay", "rec.raw", "--snapshot", "view", "--viewer", "none", "-q"], "not no suffix"),
    (["aim", "--replay", "rec.raw", "--snapshot", "old.png", "--viewer", "none", "-q"],
     "--snapshot old.png: holds something else than a .png picture"),
    (["events", "convert", "rec.raw", "other.raw"], "other.raw: exists (it is left as is"),
    (["events", "convert", "rec.raw", "rig.yaml.csv"], "rig.yaml.csv: exists"),
    (["events", "convert", "rec.raw", "empty.csv"], "empty.csv: exists"),
    # an HDF5 file cut by a forced exit: it cannot tell what it held (not "something else")
    (["reconstruct", "rec.raw", "-o", "cut.h5", "--root", "150", "240", "--length", "300"],
     "-o cut.h5: cannot be read (damaged, in use or no permission): delete it or give a new file"),
]  # fmt: skip


@pytest.mark.parametrize(("argv", "words"), CASES)
def test_an_output_over_an_input_or_another_kind_of_file_is_refused(
    folder: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    monkeypatch.chdir(folder)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


def test_an_earlier_output_of_the_same_kind_is_replaced(folder: Path) -> None:
    from flagtrack.daemon.commands._outputs import check_output, only_yaml_sections

    earlier = folder / "tracker.yaml"
    earlier.write_text("# the flag's geometry\ntracker: {root: [1, 2], length: 3}\n")
    check_output(earlier, "-o", (folder / "rec.raw",), replaceable=only_yaml_sections("tracker"), holds="x")
    (folder / "empty.yaml").write_text("")
    check_output(folder / "empty.yaml", "-o", (), replaceable=only_yaml_sections("tracker"), holds="x")


def test_up_record_refuses_a_name_recorded_before(
    folder: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second `up --record test1` replaced recordings/test1.raw (2.28 MB -> 1.24 MB), exit 0."""
    monkeypatch.chdir(folder)
    (folder / "recordings").mkdir()
    (folder / "recordings" / "test1.raw").write_bytes(b"the first recording")
    assert main(["up", "-c", "rig.yaml", "--record", "test1", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--record: recordings/test1.raw exists" in err[0], err
    assert (folder / "recordings" / "test1.raw").read_bytes() == b"the first recording"


def test_aim_refuses_a_snapshot_onto_the_rigs_calibration(
    folder: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(folder)
    (folder / "cal.yaml").write_text("format: flagtrack-calibration\n")
    (folder / "rig.yaml").write_text(RIG.replace("length: 300}", "length: 300, calibration: cal.yaml}"))
    assert main(["aim", "-c", "rig.yaml", "--snapshot", "cal.yaml", "--viewer", "none", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--snapshot cal.yaml: is the input" in err[0], err
    assert (folder / "cal.yaml").read_text() == "format: flagtrack-calibration\n"


def test_reconstruct_writes_through_a_symbolic_link(folder: Path) -> None:
    """The atomic write renamed a new file over the link (the link's target kept the old result)."""
    (folder / "results").mkdir()
    target = folder / "results" / "out.h5"
    argv = ["reconstruct", str(folder / "rec.raw"), "--root", "150", "240", "--length", "300"]
    assert main([*argv, "-o", str(target), "--t-stop", "0.0005"]) == 0  # an earlier result, replaced
    earlier = target.read_bytes()
    (folder / "out.h5").symlink_to(target)
    assert main([*argv, "-o", str(folder / "out.h5")]) == 0
    assert (folder / "out.h5").is_symlink() and target.read_bytes()[:4] == b"\x89HDF" and target.read_bytes() != earlier


def test_earlier_outputs_of_each_kind_are_replaced(folder: Path) -> None:
    """A centreline file, a Rerun view and a picture made before are what these options write again."""
    from flagtrack.daemon.commands._outputs import PICTURES, RRD, centrelines_file, check_picture

    argv = ["reconstruct", str(folder / "rec.raw"), "--root", "150", "240", "--length", "300", "-o"]
    assert main([*argv, str(folder / "c.h5")]) == 0 and main([*argv, str(folder / "c.h5")]) == 0
    assert centrelines_file(folder / "c.h5") and not centrelines_file(folder / "rec.raw")
    (folder / "v.rrd").write_bytes(b"RRF2\x00\x29")
    assert RRD(folder / "v.rrd") and not RRD(folder / "rig.yaml")
    (folder / "a.png").write_bytes(PICTURES[".png"] + b"...")
    check_picture(folder / "a.png", "--snapshot")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_an_output_in_a_folder_without_write_permission_is_refused(
    folder: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """h5py's own error came after the work: its flags and the temporary file's name."""
    locked = folder / "locked"
    locked.mkdir(mode=0o500)
    argv = ["reconstruct", str(folder / "rec.raw"), "-o", str(locked / "c.h5"), "--root", "150", "240"]
    assert main([*argv, "--length", "300"]) == 2
    assert f"folder {locked} is not writable" in capsys.readouterr().err


def test_a_centreline_file_that_cannot_be_created_says_why_in_its_own_words(tmp_path: Path) -> None:
    from flagtrack.daemon.errors import FormatError
    from flagtrack.drivers.formats.centreline import CentrelineWriter

    with pytest.raises(FormatError) as info:
        CentrelineWriter(tmp_path / "gone" / ".c.h5.tmp", np.linspace(0, 1, 5), 4, {"units": "px"})
    assert (
        str(info.value)
        == f"{tmp_path / 'gone' / '.c.h5.tmp'}: cannot create a file in {tmp_path / 'gone'}: No such file or directory"
    )


def test_convert_refuses_a_link_to_no_file_and_leaves_nothing(folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A failed convert removed the link it wrote through, and left the part written where it pointed."""
    (folder / "link.csv").symlink_to(folder / "elsewhere.csv")
    assert main(["events", "convert", str(folder / "rec.raw"), str(folder / "link.csv")]) == 2
    assert "link.csv: exists" in capsys.readouterr().err
    assert (folder / "link.csv").is_symlink() and not (folder / "elsewhere.csv").exists()
