"""``flagtrack batch`` end to end on real files: the outputs of a local process pool and of a real Dask
``LocalCluster`` are ``flagtrack reconstruct``'s, file by file; a corrupt input fails alone; a rerun skips
what is up to date and a changed parameter redoes it; a batch killed with SIGKILL resumes; ``batch
validate`` rewrites a simulated sweep run's summary as ``flagtrack validate --reconstruct`` does."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.batch.tasks import RUN_STAMP
from flagtrack.daemon.cli import main
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events
from tests.fakes.rig import SENSOR, simulated_rig
from tests.fakes.terminal import run_on_a_terminal

FLAG = WavyFlag(root=(120.0, 250.0), length=180.0)
TRACK = ["--root", "120", "250", "--length", "180", "--tau", "0.0003"]
BATCH_ATTRS = {"batch_input_size", "batch_input_mtime_ns", "batch_input_blake2b", "batch_params_blake2b"}
COLUMNS = ["input", "events", "duration", "updates", "seconds", "worker", "status", "error", "output"]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four recordings of a flapping line, 0.1 s each (~0.25 M events): three EVT 3.0 files and a .npy."""
    folder = tmp_path_factory.mktemp("campaign")
    params = QuickLineParams(events_per_px2=10, noise_rate_hz=1e5)
    for i in range(4):
        events = np.concatenate(list(line_events(FLAG, 1_000_000, 1_100_000, 640, 480, params, seed=i)))
        name = f"rec{i}.npy" if i == 3 else f"rec{i}.raw"
        write_events(folder / name, events, width=640, height=480, encoding="evt3" if i < 3 else None)
    return folder


def reconstruct_all(campaign: Path, out: Path, *track: str) -> dict[str, Path]:
    """``flagtrack reconstruct`` of every recording (the reference a batch must equal)."""
    out.mkdir(parents=True, exist_ok=True)
    files = {}
    for recording in sorted(campaign.iterdir()):
        files[recording.stem] = out / f"{recording.stem}_centrelines.h5"
        assert main(["reconstruct", str(recording), "-o", str(files[recording.stem]), *track, "--no-progress"]) == 0
    return files


@pytest.fixture(scope="module")
def references(campaign: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return reconstruct_all(campaign, tmp_path_factory.mktemp("reference"), *TRACK)


def batch(*args: str) -> tuple[int, str, str]:
    """``flagtrack batch ARGS`` in this process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["batch", *args])
    return code, out.getvalue(), err.getvalue()


def contents(path: Path) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    datasets: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: datasets.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
        attrs = dict(f.attrs)
    return datasets, attrs


def assert_same_file(batch_output: Path, reference: Path, *, but: tuple[str, ...] = ()) -> None:
    """Every dataset to 1e-12 and every attribute equal, but the batch's own ``batch_*`` stamp (and ``but``)."""
    got, got_attrs = contents(batch_output)
    want, want_attrs = contents(reference)
    assert set(got) == set(want)
    for name in want:
        assert got[name].shape == want[name].shape and got[name].dtype == want[name].dtype, name
        np.testing.assert_allclose(got[name], want[name], rtol=0, atol=1e-12, equal_nan=True, err_msg=name)
    assert set(got_attrs) == set(want_attrs) | BATCH_ATTRS
    for name, value in want_attrs.items():
        assert name in but or np.array_equal(got_attrs[name], value), name


def read_rows(out: Path) -> list[dict[str, str]]:
    with open(out / "batch.csv", newline="") as handle:
        reader = csv.DictReader(handle)
        assert reader.fieldnames == COLUMNS
        return list(reader)


@pytest.fixture(scope="module")
def pool_batch(campaign: Path, references: dict[str, Path], tmp_path_factory: pytest.TempPathFactory):
    """A first batch on a local pool of two processes: (out dir, exit code, --json object, stderr)."""
    out = tmp_path_factory.mktemp("pool") / "out"
    code, stdout, stderr = batch("reconstruct", str(campaign), "-o", str(out), *TRACK, "--jobs", "2", "--json")
    return out, code, json.loads(stdout), stderr


@pytest.mark.slow
def test_a_local_pool_writes_what_reconstruct_writes(pool_batch, references: dict[str, Path], campaign: Path) -> None:
    out, code, summary, stderr = pool_batch
    assert code == 0, stderr
    assert summary["counts"] == {"done": 4, "skipped": 0, "failed": 0}
    for stem, reference in references.items():
        assert_same_file(out / f"{stem}_centrelines.h5", reference)
    rows = read_rows(out)
    assert [r["input"] for r in rows] == [str(p) for p in sorted(campaign.iterdir())]
    for row, stem in zip(rows, references):
        with h5py.File(references[stem], "r") as f:
            events, updates = int(f.attrs["events_in"]), f["t"].shape[0]
            span = f["t"][-1] - f["t"][0]
        assert (row["status"], row["error"], row["output"]) == ("done", "", str(out / f"{stem}_centrelines.h5"))
        assert (int(row["events"]), int(row["updates"])) == (events, updates) and events > 200_000
        assert float(row["duration"]) == pytest.approx(span) and float(row["seconds"]) > 0
        assert row["worker"].split(":")[1].isdigit() and row["worker"].split(":")[1] != str(os.getpid())
    document = json.loads((out / "batch.json").read_text())
    assert document["rows"] == summary["rows"] and document["executor"] == "pool:2"
    assert document["parameters"]["tau_s"] == 0.0003 and document["parameters"]["root"] == [120.0, 250.0]
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.slow
def test_a_rerun_skips_everything_and_says_so(pool_batch, campaign: Path, tmp_path: Path) -> None:
    first = pool_batch[0]
    out = tmp_path / "out"
    shutil.copytree(first, out)  # outputs and their times as the first batch left them
    before = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in out.glob("*_centrelines.h5")}
    code, stdout, stderr = batch("reconstruct", str(campaign), "-o", str(out), *TRACK, "--jobs", "2", "--json")
    assert code == 0, stderr
    assert json.loads(stdout)["counts"] == {"done": 0, "skipped": 4, "failed": 0}
    assert stderr.count(": skipped (up to date)") == 4 and "0 done, 4 skipped (up to date)" in stderr
    assert {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in out.glob("*_centrelines.h5")} == before
    rows = read_rows(out)
    assert {r["status"] for r in rows} == {"skipped"}
    assert [r["events"] for r in rows] == [r["events"] for r in read_rows(first)]  # read back from the outputs


@pytest.mark.slow
def test_a_changed_parameter_redoes_everything(pool_batch, campaign: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    shutil.copytree(pool_batch[0], out)
    track = [*TRACK[:-1], "0.0004"]
    code, stdout, stderr = batch("reconstruct", str(campaign), "-o", str(out), *track, "--jobs", "2", "--json")
    assert code == 0, stderr
    assert json.loads(stdout)["counts"] == {"done": 4, "skipped": 0, "failed": 0}
    assert "skipped" not in stderr.replace("0 skipped", "")
    references = reconstruct_all(campaign, tmp_path / "reference", *track)
    for stem, reference in references.items():
        assert_same_file(out / f"{stem}_centrelines.h5", reference)


@pytest.mark.slow
def test_a_corrupt_input_fails_alone(campaign: Path, references: dict[str, Path], tmp_path: Path) -> None:
    folder = tmp_path / "campaign"
    folder.mkdir()
    for name in ("rec0.raw", "rec1.raw"):
        shutil.copy2(campaign / name, folder / name)
    (folder / "bad.raw").write_bytes(b"\x00not an event file" * 500)
    out = tmp_path / "out"
    code, stdout, stderr = batch("reconstruct", str(folder), "-o", str(out), *TRACK, "--jobs", "2", "--json")
    assert code == 1
    rows = {Path(r["input"]).name: r for r in read_rows(out)}
    bad = rows["bad.raw"]
    assert bad["status"] == "failed" and bad["output"] == "" and bad["events"] == ""
    assert bad["error"] == f"{folder / 'bad.raw'}, byte 0: not a RAW file: no '%' header (encoding unknown)"
    assert f"bad.raw: failed: {bad['error']}" in stderr and "2 done, 0 skipped (up to date), 1 failed" in stderr
    assert not (out / "bad_centrelines.h5").exists()
    for stem in ("rec0", "rec1"):
        assert rows[f"{stem}.raw"]["status"] == "done"
        assert_same_file(out / f"{stem}_centrelines.h5", references[stem], but=("input_file",))  # a copy's path
    assert json.loads(stdout)["counts"] == {"done": 2, "skipped": 0, "failed": 1}


def test_bad_inputs_and_options_are_one_line_and_exit_2(campaign: Path, tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    shutil.copy2(campaign / "rec0.raw", tmp_path / "a" / "rec0.raw")
    shutil.copy2(campaign / "rec0.raw", tmp_path / "b" / "rec0.raw")
    out = tmp_path / "out"
    cases = [
        ([str(tmp_path / "missing.raw")], f"{tmp_path / 'missing.raw'}: no such file or folder"),
        ([str(tmp_path / "a"), str(tmp_path / "b")], "would both write rec0_centrelines.h5"),
        ([str(tmp_path / "a"), "--jobs", "0"], "--jobs: must be at least 1"),
        ([str(tmp_path / "a"), "--scheduler", "head:8786"], "--scheduler: expected local"),
        ([str(tmp_path / "a"), "--alpha", "-1"], "alpha"),
    ]
    for args, words in cases:
        code, _, stderr = batch("reconstruct", *args, "-o", str(out), *TRACK)
        assert code == 2, args
        assert stderr.startswith("flagtrack batch: error: ") and words in stderr and stderr.count("\n") == 1, stderr
    assert not out.exists()  # nothing was run


def on_a_terminal(*args: str, timeout_s: float = 60.0) -> str:
    """``flagtrack ARGS`` with stderr on a real pseudo-terminal (100 x 24); what the terminal got."""
    return run_on_a_terminal([sys.executable, "-m", "flagtrack.daemon", *args], columns=100, timeout_s=timeout_s)


@pytest.mark.slow
def test_a_bar_on_a_terminal_and_plain_lines_with_no_progress(campaign: Path, tmp_path: Path) -> None:
    args = ["batch", "reconstruct", str(campaign), *TRACK, "--jobs", "1"]
    shown = on_a_terminal(*args, "-o", str(tmp_path / "a"))
    assert "/4 files:" in shown and "%|" in shown and "M events" in shown and "Mev/s" in shown, shown
    assert "4 inputs: 4 done" in shown and "[1/4," not in shown  # the summary, no per-file lines
    plain = on_a_terminal(*args, "-o", str(tmp_path / "b"), "--no-progress")
    assert "%|" not in plain and "[1/4, " in plain and "rec0.raw: done (" in plain, plain


def wait_until(predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return predicate()


def finished_outputs(out: Path) -> set[str]:
    return {p.name for p in out.glob("*_centrelines.h5")} if out.is_dir() else set()


@pytest.mark.slow
def test_a_killed_batch_resumes_with_only_the_rest(campaign: Path, references: dict[str, Path], tmp_path: Path) -> None:
    folder = tmp_path / "campaign"  # 12 recordings: the batch is far from its end when its first output appears
    folder.mkdir()
    sources = {}
    for copy in "abc":
        for recording in campaign.iterdir():
            sources[f"{recording.stem}{copy}"] = recording.stem
            shutil.copy2(recording, folder / f"{recording.stem}{copy}{recording.suffix}")
    out = tmp_path / "out"
    command = [sys.executable, "-m", "flagtrack.daemon", "batch", "reconstruct", str(folder), "-o", str(out)]
    proc = subprocess.Popen(
        [*command, *TRACK, "--jobs", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True
    )
    try:
        assert wait_until(lambda: finished_outputs(out) or proc.poll() is not None, 60.0)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the batch and its worker, as a power cut or `kill -9` of the job
        proc.communicate(timeout=30)
    done_before = finished_outputs(out)
    assert 1 <= len(done_before) < len(sources), "the batch ended before it could be killed"
    partial = [p for p in out.iterdir() if p.name.endswith(".tmp")]  # the output being written, if any
    code, stdout, stderr = batch("reconstruct", str(folder), "-o", str(out), *TRACK, "--jobs", "2", "--json")
    assert code == 0, stderr
    assert (f"removed {len(partial)} unfinished output(s)" in stderr) == bool(partial)
    status = {Path(r["output"]).name: r["status"] for r in json.loads(stdout)["rows"]}
    assert {name for name, s in status.items() if s == "skipped"} == done_before
    assert {name for name, s in status.items() if s == "done"} == set(status) - done_before
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]  # no partial file is left, none was taken
    for stem, source in sources.items():
        assert_same_file(out / f"{stem}_centrelines.h5", references[source], but=("input_file",))  # a copy


@pytest.mark.slow
def test_a_dask_local_cluster_writes_what_reconstruct_writes(
    campaign: Path, references: dict[str, Path], tmp_path: Path
) -> None:
    pytest.importorskip("distributed", reason="Dask is the cluster extra: pip install -e '.[cluster]'")
    out = tmp_path / "out"
    code, stdout, stderr = batch(
        "reconstruct", str(campaign), "-o", str(out), *TRACK, "--scheduler", "local:2", "--json"
    )
    assert code == 0, stderr
    summary = json.loads(stdout)
    assert summary["counts"] == {"done": 4, "skipped": 0, "failed": 0}
    for stem, reference in references.items():
        assert_same_file(out / f"{stem}_centrelines.h5", reference)
    document = json.loads((out / "batch.json").read_text())
    assert document["executor"] == "dask local:2" and document["workers"] == 2
    assert all(row["worker"].split(":")[1] != str(os.getpid()) for row in document["rows"])
    code, stdout, _ = batch("reconstruct", str(campaign), "-o", str(out), *TRACK, "--scheduler", "local:2", "--json")
    assert code == 0 and json.loads(stdout)["counts"]["skipped"] == 4


def sweep_rig(tmp_path: Path) -> object:
    """A one-point sweep of the simulated rig with its point sensor (as test_validate_sweep.py, shorter)."""
    from flagtrack.daemon.rig.config import RigConfig
    from flagtrack.daemon.typed_yaml import from_mapping

    mapping = simulated_rig(
        tmp_path,
        f"bval{time.monotonic_ns() % 10**9}",
        {"speeds": [5.5], "branches": ["up"], "settle_s": 0.5, "record_s": 0.8},
        tau_s=0.001,
        twin={"time_scale": 0.5, "trigger_period_ms": 50},
        supervisor={"onset": {"learn_s": 0.5}, "silence_timeout_s": 3.0},
        sensor=SENSOR,
    )
    return from_mapping(RigConfig, mapping)


@pytest.fixture(scope="module")
def sweep_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from flagtrack.daemon.rig.build import build_services
    from flagtrack.daemon.services.runner import ServiceGroup
    from flagtrack.daemon.transport import Bus

    tmp_path = tmp_path_factory.mktemp("sweep")
    config = sweep_rig(tmp_path)
    with Bus(config.bus_config) as bus:
        group = ServiceGroup(build_services(config, bus, list(config.services)), stop_when_any_finishes=["supervisor"])
        group.start()
        group.wait(240)  # (it ends with the sweep: the bound is for a busy machine)
        report = group.shutdown(30)
    assert not report.errors
    return tmp_path / "runs" / "run"


def assert_same_csv(got: str, want: str) -> None:
    """The same table: the same columns and rows, the same text, numbers equal to 1e-9 (the sensor's
    clock offset goes through sums whose last bit depends on where numpy's arrays lie in memory)."""
    got_rows, want_rows = list(csv.reader(io.StringIO(got))), list(csv.reader(io.StringIO(want)))
    assert [len(r) for r in got_rows] == [len(r) for r in want_rows] and got_rows[0] == want_rows[0]
    for got_row, want_row in zip(got_rows[1:], want_rows[1:], strict=True):
        for column, a, b in zip(want_rows[0], got_row, want_row, strict=True):
            try:
                x, y = float(a), float(b)
            except ValueError:
                assert a == b, column
            else:
                assert x == pytest.approx(y, rel=1e-9, abs=1e-12, nan_ok=True), column


@pytest.mark.slow
def test_batch_validate_rewrites_each_run_as_validate_reconstruct_does(sweep_run: Path, tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    for name in ("run-a", "run-b", "alone"):
        shutil.copytree(sweep_run, runs / name)
    alone = runs / "alone"
    assert main(["validate", str(alone), "--reconstruct", "--tau", "0.0008"]) == 0
    log = (runs / "run-a" / "run.jsonl").read_bytes()
    study = tmp_path / "study"
    args = [str(runs / "run-a"), str(runs / "run-b"), "-o", str(study), "--tau", "0.0008", "--jobs", "2", "--json"]
    code, stdout, stderr = batch("validate", *args)
    assert code == 0, stderr
    want = (alone / "validation" / "validation.csv").read_text()
    assert "000-up-5.50" in want and ",ok," in want
    for name in ("run-a", "run-b"):
        validation = runs / name / "validation"
        assert_same_csv((validation / "validation.csv").read_text(), want)  # the summary, number for number
        assert {p.name for p in validation.glob("*.png")} == {p.name for p in (alone / "validation").glob("*.png")}
        for point in (alone / "validation" / "centrelines").iterdir():
            assert_same_file(validation / "centrelines" / point.name, point, but=("input_file",))  # another copy
    assert (runs / "run-a" / "run.jsonl").read_bytes() == log  # the run log is never rewritten
    rows = read_rows(study)
    assert [(Path(r["input"]).name, r["status"]) for r in rows] == [("run-a", "done"), ("run-b", "done")]
    assert rows[0]["output"] == str(runs / "run-a" / "validation" / "validation.csv") and int(rows[0]["events"]) > 0
    document = json.loads((study / "batch.json").read_text())
    assert [p["point_id"] for p in document["runs"][0]["points"]] == ["000-up-5.50"]
    assert document["runs"][0]["parameters"]["tau_s"] == 0.0008 and document["runs"][0]["parameters"]["length"] == 300
    assert (study / "campaign.png").read_bytes()[:4] == b"\x89PNG" and json.loads(stdout)["figure"]
    code, stdout, stderr = batch("validate", *args)
    assert code == 0 and json.loads(stdout)["counts"] == {"done": 0, "skipped": 2, "failed": 0}
    assert "run run-a: skipped (up to date)" in stderr
    # a damaged sensor record: the run is done with that point's status, said, and not stamped up to date
    (runs / "run-b" / "points" / "000-up-5.50_sensor.h5").write_bytes(b"\x00damaged" * 8)
    (runs / "run-b" / "validation" / RUN_STAMP).unlink()
    code, stdout, stderr = batch("validate", str(runs / "run-b"), "-o", str(tmp_path / "study-b"), "--tau", "0.0008")
    assert code == 0 and "warning: " in stderr and "point 000-up-5.50 damaged: " in stderr, stderr
    assert not (runs / "run-b" / "validation" / RUN_STAMP).exists()


def test_a_root_off_the_sensor_fails_each_row_as_reconstruct_refuses_it(campaign: Path, tmp_path: Path) -> None:
    """`batch reconstruct --root 9999 9999` wrote centrelines at x ~ 10 000 px, `done`, exit 0, where
    `reconstruct` refuses the root in one line."""
    folder = tmp_path / "campaign"
    folder.mkdir()
    shutil.copy2(campaign / "rec0.raw", folder / "rec0.raw")
    out = tmp_path / "out"
    off = ["--root", "9999", "9999", *TRACK[3:]]
    code, _, stderr = batch("reconstruct", str(folder), "-o", str(out), *off, "--jobs", "1")
    assert code == 1, stderr
    (row,) = read_rows(out)
    assert row["status"] == "failed" and row["error"].endswith("the root (9999, 9999) is off its 640 x 480 sensor")
    assert not (out / "rec0_centrelines.h5").exists()
