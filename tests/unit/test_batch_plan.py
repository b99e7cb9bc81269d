"""``flagtrack batch``'s planning on real files: inputs from files, folders and patterns, output names, the
stamp that decides what a rerun skips, the executor options, the folder lock, the progress lines."""

from __future__ import annotations

import io
import os
import re
from pathlib import Path

import h5py
import pytest

from flagtrack.daemon.batch.executor import ExecutorSpec, executor_spec, import_dask
from flagtrack.daemon.batch.folders import FolderLock, remove_partial_outputs
from flagtrack.daemon.batch.inputs import expand_inputs, output_paths
from flagtrack.daemon.batch.progress import Progress
from flagtrack.daemon.batch.stamp import (
    DIGEST,
    InputStat,
    file_digest,
    params_digest,
    read_stamp,
    stamp_attrs,
    up_to_date,
)
from flagtrack.daemon.errors import ConfigError, FormatError


def touch(path: Path, data: bytes = b"x") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)
    return path


def test_files_folders_and_patterns_give_each_recording_once_resolved(tmp_path: Path, monkeypatch) -> None:
    a = touch(tmp_path / "camp" / "a.raw")
    b = touch(tmp_path / "camp" / "b.NPY")
    touch(tmp_path / "camp" / "notes.txt")
    touch(tmp_path / "camp" / ".a_centrelines.h5.0123456789ab.tmp")
    touch(tmp_path / "camp" / ".hidden.raw")
    c = touch(tmp_path / "camp" / "deep" / "c.dat")
    odd = touch(tmp_path / "other" / "odd.bin")
    monkeypatch.chdir(tmp_path)
    assert expand_inputs(["camp"]) == [a, b]  # a folder: its recordings, not its sub-folders
    assert expand_inputs(["camp/**/*.dat", "camp/a.raw", "camp"]) == [c, a, b]  # in order, each once
    assert expand_inputs(["camp/**"]) == [a, b, c]  # a pattern matching folders takes their recordings
    assert expand_inputs(["other/odd.bin"]) == [odd]  # a named file is taken as it is
    assert expand_inputs(["camp"], exclude={a}) == [b]
    assert all(p.is_absolute() for p in expand_inputs(["camp/*"]))


@pytest.mark.parametrize(
    ("item", "words"),
    [
        ("missing.raw", "missing.raw: no such file or folder"),
        ("camp/*.aedat4", "camp/*.aedat4: the pattern matches no recording"),
        ("empty", "empty: no recordings in this folder"),
    ],
)
def test_an_input_naming_nothing_is_one_error_naming_it(tmp_path: Path, monkeypatch, item: str, words: str) -> None:
    touch(tmp_path / "camp" / "a.raw")
    (tmp_path / "empty").mkdir()
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FormatError, match=re.escape(words)):
        expand_inputs([item])


def test_two_inputs_of_one_stem_are_refused(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert output_paths(out, [tmp_path / "a" / "r1.raw", tmp_path / "a" / "r2.raw"]) == [
        out / "r1_centrelines.h5",
        out / "r2_centrelines.h5",
    ]
    with pytest.raises(ConfigError, match=r"a/r1.raw and .*b/r1.raw would both write r1_centrelines.h5"):
        output_paths(out, [tmp_path / "a" / "r1.raw", tmp_path / "b" / "r1.raw"])
    with pytest.raises(ConfigError, match="would both write"):
        output_paths(out, [tmp_path / "r1.raw", tmp_path / "r1.npy"])


def stamped_output(tmp_path: Path, recording: Path, params: str) -> Path:
    out = tmp_path / "out.h5"
    with h5py.File(out, "w") as f:
        f.attrs.update(stamp_attrs(InputStat.of(recording), file_digest(recording), params))
        f.attrs["input_file"] = str(recording.resolve())
    return out


def test_the_stamp_decides_by_size_time_content_and_parameters(tmp_path: Path) -> None:
    recording = touch(tmp_path / "r.raw", b"abcdef" * 1000)
    params = params_digest({"tau_s": 3e-4, "root": [1.0, 2.0], "calibration": tmp_path / "cal.yaml"})
    assert params == params_digest({"calibration": tmp_path / "cal.yaml", "root": [1.0, 2.0], "tau_s": 3e-4})
    assert params != params_digest({"tau_s": 4e-4, "root": [1.0, 2.0], "calibration": tmp_path / "cal.yaml"})
    recorded = read_stamp(stamped_output(tmp_path, recording, params))
    assert recorded is not None and recorded[DIGEST] == file_digest(recording)
    name = str(recording.resolve())
    assert up_to_date(recorded, name, InputStat.of(recording), params) is True
    assert up_to_date(recorded, name, InputStat.of(recording), params, checksum=True) is None  # digest decides
    assert up_to_date(recorded, name, InputStat.of(recording), "other") is False
    assert up_to_date(recorded, str(tmp_path / "elsewhere.raw"), InputStat.of(recording), params) is False
    assert up_to_date(None, name, InputStat.of(recording), params) is False
    st = os.stat(recording)
    os.utime(recording, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))  # touched: the content decides
    assert up_to_date(recorded, name, InputStat.of(recording), params) is None
    assert file_digest(recording) == recorded[DIGEST]
    recording.write_bytes(b"abcdeX" * 1000)  # same size, another content
    assert up_to_date(recorded, name, InputStat.of(recording), params) is None
    assert file_digest(recording) != recorded[DIGEST]
    recording.write_bytes(b"abc")
    assert up_to_date(recorded, name, InputStat.of(recording), params) is False
    assert read_stamp(tmp_path / "absent.h5") is None and read_stamp(touch(tmp_path / "junk.h5")) is None


def test_executor_options() -> None:
    assert executor_spec(3, None) == ExecutorSpec("pool", 3)
    assert executor_spec(None, None).workers >= 1
    assert executor_spec(None, "local:2") == ExecutorSpec("local", 2)
    assert executor_spec(None, "tcp://head:8786") == ExecutorSpec("remote", 0, "tcp://head:8786")
    assert ExecutorSpec("remote", 0, "tcp://head:8786").describe() == "dask tcp://head:8786"
    for jobs, scheduler, words in (
        (0, None, "at least 1"),
        (None, "local:x", "needs a number"),
        (None, "local:0", "at least 1 worker"),
        (None, "head:8786", "expected local"),
    ):
        with pytest.raises(ConfigError, match=words):
            executor_spec(jobs, scheduler)


def test_a_scheduler_without_dask_is_one_line_saying_how_to_install_it(monkeypatch) -> None:
    monkeypatch.setitem(__import__("sys").modules, "distributed", None)  # as if not installed
    with pytest.raises(ConfigError, match=r"--scheduler: needs Dask distributed.*\.\[cluster\]") as info:
        import_dask()
    assert "\n" not in str(info.value)


def test_one_batch_at_a_time_per_folder_and_leftovers_removed(tmp_path: Path) -> None:
    out = tmp_path / "out"
    output = out / "r[1]_centrelines.h5"
    with FolderLock(out):
        with pytest.raises(ConfigError, match="another flagtrack batch is writing into"), FolderLock(out):
            pass
        leftover = touch(out / ".r[1]_centrelines.h5.0123456789ab.tmp")
        other = touch(out / ".r2_centrelines.h5.0123456789ab.tmp")
        assert remove_partial_outputs([output]) == [leftover]
        assert not leftover.exists() and other.exists()
    with FolderLock(out):  # released
        pass


def test_plain_progress_lines_say_what_each_input_became() -> None:
    stream = io.StringIO()
    progress = Progress("flagtrack batch", 3, 3_000_000, bar=False, stream=stream)
    progress.advance("a.raw", 1_000_000, "done", 5_000_000, "(5.00 M events)")
    progress.advance("b.raw", 1_000_000, "skipped", 4_000_000)
    progress.advance("c.raw", 1_000_000, "failed", None, "c.raw: not a RAW file")
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("flagtrack batch: [1/3, 1.0 of 3.0 MB, ETA ") and lines[0].endswith(
        "a.raw: done (5.00 M events)"
    )
    assert lines[1] == "flagtrack batch: [2/3, 2.0 of 3.0 MB, ETA 0 s] b.raw: skipped (up to date)"
    assert lines[2] == "flagtrack batch: [3/3, 3.0 of 3.0 MB] c.raw: failed: c.raw: not a RAW file"


def test_the_bar_counts_files_bytes_and_events() -> None:
    stream = io.StringIO()
    with Progress("flagtrack batch", 2, 2_000_000, bar=True, stream=stream) as progress:
        progress.advance("a.raw", 1_000_000, "done", 5_000_000)
        progress.advance("b.raw", 1_000_000, "failed", None, "b.raw: broken")
    text = stream.getvalue()
    assert "2/2 files" in text and "5.0 M events" in text and "2.00M/2.00M" in text
    assert "flagtrack batch: b.raw: failed: b.raw: broken" in text
