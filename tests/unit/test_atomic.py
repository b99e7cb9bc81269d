"""atomic_write / atomic_open / atomic_path on real files: a file appears whole or the old one stays,
and no temporary file is left behind, whether the writer raises or the OS refuses a write."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.drivers.atomic import PendingFile, atomic_open, atomic_path, atomic_write, temporary_path


def names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("data", ["text é\n", b"\x00\xffbytes"])
def test_atomic_write_writes_text_and_bytes_and_leaves_nothing_else(tmp_path: Path, data: str | bytes) -> None:
    target = tmp_path / "out.dat"
    assert atomic_write(target, data) == target
    got = target.read_text(encoding="utf-8") if isinstance(data, str) else target.read_bytes()
    assert got == data and names(tmp_path) == ["out.dat"]


def test_atomic_write_replaces_an_existing_file(tmp_path: Path) -> None:
    target = tmp_path / "doc.json"
    target.write_text("old")
    atomic_write(target, json.dumps({"a": 1}))
    assert json.loads(target.read_text()) == {"a": 1} and names(tmp_path) == ["doc.json"]


def test_a_writer_that_raises_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "rows.csv"
    target.write_text("old rows\n")
    with pytest.raises(RuntimeError, match="cut"), atomic_open(target, "w", newline="") as handle:
        handle.write("new rows, half written")
        handle.flush()
        assert len(names(tmp_path)) == 2  # the temporary file, beside the target
        raise RuntimeError("cut")
    assert target.read_text() == "old rows\n" and names(tmp_path) == ["rows.csv"]


FULL = """
import resource, signal, sys
from pathlib import Path
from flagtrack.drivers.atomic import atomic_write
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
resource.setrlimit(resource.RLIMIT_FSIZE, (4096, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
try:
    atomic_write(Path(sys.argv[1]), sys.argv[2] * 100_000)
except OSError as exc:
    print(exc.errno)
"""


@pytest.mark.parametrize("kind", ["text", "bytes"])
def test_a_write_the_os_refuses_leaves_the_old_file_and_no_temporary(tmp_path: Path, kind: str) -> None:
    """A file-size limit (RLIMIT_FSIZE, in a child process) makes the OS refuse the write half way."""
    target = tmp_path / "sidecar.json"
    target.write_text("old")
    script = FULL if kind == "text" else FULL.replace("sys.argv[2] * 100_000", "sys.argv[2].encode() * 100_000")
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(script), str(target), "x"], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "27"  # EFBIG
    assert target.read_text() == "old" and names(tmp_path) == ["sidecar.json"]


def test_permissions_are_set_before_anything_is_written(tmp_path: Path) -> None:
    target = tmp_path / "key.pem"
    atomic_write(target, b"secret", permissions=0o600)
    assert target.stat().st_mode & 0o777 == 0o600


def test_default_permissions_follow_the_umask_as_open_does(tmp_path: Path) -> None:
    old = os.umask(0o027)
    try:
        atomic_write(tmp_path / "a.txt", "x")
        (tmp_path / "b.txt").write_text("x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == (tmp_path / "b.txt").stat().st_mode & 0o777 == 0o640


def test_atomic_path_for_a_library_that_writes_by_name(tmp_path: Path) -> None:
    """np.save adds ``.npy`` to a name without it: ``keep_suffix`` keeps the temporary name's suffix."""
    target = tmp_path / "x.npy"
    with atomic_path(target, keep_suffix=True) as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".x.npy.") and tmp.suffix == ".npy"
        np.save(tmp, np.arange(3))
        assert not target.exists()
    np.testing.assert_array_equal(np.load(target), np.arange(3))
    assert names(tmp_path) == ["x.npy"]


def test_atomic_path_removes_what_the_library_wrote_when_the_block_raises(tmp_path: Path) -> None:
    target = tmp_path / "c.h5"
    with h5py.File(target, "w") as f:
        f["old"] = 1
    with pytest.raises(KeyError), atomic_path(target) as tmp:
        with h5py.File(tmp, "w") as f:
            f["new"] = 2
        raise KeyError("a dataset missing")
    with h5py.File(target, "r") as f:
        assert list(f) == ["old"]
    assert names(tmp_path) == ["c.h5"]


def test_a_pending_file_whose_temporary_is_missing_fails_and_leaves_the_target(tmp_path: Path) -> None:
    target = tmp_path / "t.txt"
    target.write_text("old")
    pending = PendingFile(target)
    with pytest.raises(FileNotFoundError):
        pending.commit()
    assert target.read_text() == "old" and names(tmp_path) == ["t.txt"]


def test_temporary_names_are_hidden_fresh_and_end_in_tmp(tmp_path: Path) -> None:
    a, b = temporary_path(tmp_path / "r_centrelines.h5"), temporary_path(tmp_path / "r_centrelines.h5")
    assert a != b and a.parent == tmp_path
    assert (
        a.name.startswith(".r_centrelines.h5.")
        and a.name.endswith(".tmp")
        and len(a.name) == len(".r_centrelines.h5.") + 12 + 4
    )


def test_only_write_modes_are_taken(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="'a'"):
        atomic_open(tmp_path / "x", "a")  # type: ignore[call-overload]


def test_a_file_that_cannot_be_created_is_named_in_the_error_not_its_temporary(tmp_path: Path) -> None:
    target = tmp_path / "missing" / "summary.csv"
    with pytest.raises(FileNotFoundError) as caught:
        atomic_write(target, "x")
    assert caught.value.filename == str(target) and str(target) in str(caught.value)
