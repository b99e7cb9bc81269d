"""A recorder command names a recording inside the recorder's folders, or it is refused: nothing created."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from flagtrack.daemon.services.recorder import confined_base


@pytest.fixture()
def folders(tmp_path: Path) -> tuple[Path, Path, Path]:
    rec, runs, outside = tmp_path / "rec", tmp_path / "runs", tmp_path / "outside"
    for folder in (rec, runs, outside):
        folder.mkdir()
    (rec / "out").symlink_to(outside)  # a folder link that leaves
    (rec / "trap.raw").symlink_to(outside / "trap.raw")  # a file link that leaves
    return rec, runs, outside


def test_paths_inside_the_folders_are_taken(folders: tuple[Path, Path, Path]) -> None:
    rec, runs, _ = folders
    assert confined_base("run1", [rec, runs]) == rec / "run1"
    assert confined_base("day2/run1", [rec, runs]) == rec / "day2" / "run1"
    assert (
        confined_base(str(runs / "run-1" / "points" / "000-up-4.00"), [rec, runs])
        == runs / "run-1" / "points" / "000-up-4.00"
    )
    assert confined_base("a..b", [rec]) == rec / "a..b"  # a name with dots is not '..'


@pytest.mark.parametrize(
    ("path", "words"),
    [
        ("/etc/flagtrack/evil", "outside"),
        ("../outside/evil", "'..' is not allowed"),
        ("day/../../outside/evil", "'..' is not allowed"),
        ("out/evil", "outside"),
        ("trap", "symbolic link"),
        ("~nosuchuser/x", "'~' is not expanded"),
        ("~/x", "'~' is not expanded"),
        ("", "empty path"),
        (".", "outside"),
        ("a\x00b", "NUL"),
    ],
)
def test_paths_that_leave_are_refused_and_nothing_is_created(
    folders: tuple[Path, Path, Path], path: str, words: str
) -> None:
    rec, runs, outside = folders
    before = sorted(p.relative_to(rec.parent) for p in rec.parent.rglob("*"))
    with pytest.raises(ValueError, match=words):
        confined_base(path, [rec, runs])
    assert sorted(p.relative_to(rec.parent) for p in rec.parent.rglob("*")) == before
    assert os.listdir(outside) == []
