"""Centreline files explain themselves: every dataset has ``units`` and ``description``, unset values are
absent (never the text ``null``), booleans are 0/1 integers, the layout has a version, and files of the
layout before (version 1) still read."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.drivers.formats.centreline import CentrelineSink, read_centrelines, read_truth, write_centrelines
from flagtrack.drivers.formats.centreline_layout import DATASETS, FORMAT_VERSION, LENGTH, dataset_spec
from tests.unit.test_centreline_file import make_batch

PROCESSING = {
    "alpha": 0.6,
    "root": [150.0, 240.0],
    "length": 300.0,
    "direction_deg": 0.0,
    "refine_deg": None,
    "t_start_s": None,
    "t_stop_s": None,
    "calibration": None,
    "denoise_enabled": True,
    "lost_enabled": False,
    "schedule": [],
}


def every_dataset(path: Path) -> dict[str, dict[str, object]]:
    """The attributes of every dataset of ``path``, by its name."""
    found: dict[str, dict[str, object]] = {}

    def visit(name: str, node: object) -> None:
        if isinstance(node, h5py.Dataset):
            found[name] = dict(node.attrs)

    with h5py.File(path) as f:
        f.visititems(visit)
    return found


def plain_type(f: h5py.File, name: str) -> bool:
    """The root attribute ``name`` is a number, text or numbers, not an HDF5 enum (h5py's booleans)."""
    dtype = f.attrs.get_id(name).dtype
    return dtype.kind in "iufOS" and h5py.check_enum_dtype(dtype) is None


def assert_self_describing(path: Path, length_units: str) -> None:
    """Every dataset has a units and a description (a dataset added without an entry fails here)."""
    datasets = every_dataset(path)
    assert datasets, path
    for name, attrs in datasets.items():
        assert "units" in attrs and "description" in attrs, f"/{name} has no units or description"
        spec = dataset_spec(name)
        assert spec is not None
        assert attrs["units"] == (length_units if spec.units == LENGTH else spec.units)
        assert len(str(attrs["description"])) > 10
    with h5py.File(path) as f:
        for name, value in f.attrs.items():
            assert not (isinstance(value, str | bytes) and value in ("null", b"null")), f"attribute {name} is 'null'"
            assert plain_type(f, name), name
        assert f.attrs["format_version"] == FORMAT_VERSION and f.attrs["format"] == "flagtrack-centrelines"


def test_a_sinks_file_describes_every_dataset_and_leaves_unset_values_out(tmp_path: Path) -> None:
    path = tmp_path / "c.h5"
    with CentrelineSink(path, {**PROCESSING, "units": "px", "input_file": None}) as sink:
        sink.set_attrs({"sensor_width_px": 640, "sensor_height_px": 480, "late": 3})
        sink.add(make_batch(5))
        sink.set_attrs({"late": None})  # unset again: removed
    assert_self_describing(path, "px")
    with h5py.File(path) as f:
        for name in ("refine_deg", "t_start_s", "t_stop_s", "calibration", "input_file", "late", "calibration_units"):
            assert name not in f.attrs
        assert f.attrs["denoise_enabled"] == 1 and f.attrs["lost_enabled"] == 0
        assert f.attrs["denoise_enabled"].dtype.kind == "i"
        assert (f.attrs["sensor_width_px"], f.attrs["sensor_height_px"]) == (640, 480)
    _, attrs = read_centrelines(path)
    assert attrs.get("t_start_s") is None and attrs["denoise_enabled"] == 1 and attrs["schedule"] == []


def test_a_calibrated_file_names_the_plane_unit(tmp_path: Path) -> None:
    path = tmp_path / "m.h5"
    write_centrelines(path, make_batch(3), {"units": "m", "calibration_degree": 3, "calibration_yaml": "degree: 3\n"})
    assert_self_describing(path, "m")
    with h5py.File(path) as f:
        assert f.attrs["calibration_units"] == "m" and f["x"].attrs["units"] == "m" and f["t"].attrs["units"] == "s"


def test_every_dataset_of_the_layout_has_an_entry() -> None:
    names = [spec.name for spec in DATASETS]
    assert len(names) == len(set(names))
    for name in ("t", "s", "x", "y", "joints/x", "joints/y", "delta_rms", "n_events", "lost", "stale", "shed"):
        assert dataset_spec(name) is not None and dataset_spec("/" + name) is not None
    assert "event-cloud distance" in dataset_spec("delta_rms").description  # not the tip error
    assert dataset_spec("shed").units == "1" and "tracker.max_lag_ms" in dataset_spec("shed").description
    assert "tracker.lost.stale_after_s" in dataset_spec("stale").description


def test_files_of_the_first_layout_still_read(tmp_path: Path) -> None:
    """A version-1 file: no format_version, 'null' strings, boolean enums, no dataset attributes, no /lost."""
    path = tmp_path / "v1.h5"
    batch = make_batch(4)
    with h5py.File(path, "w") as f:
        for name, values in (("t", batch.t_s), ("s", batch.s), ("x", batch.x), ("y", batch.y),
                             ("joints/x", batch.joints_x), ("joints/y", batch.joints_y),
                             ("delta_rms", batch.delta_rms), ("n_events", batch.n_events)):  # fmt: skip
            f[name] = values
        f.attrs.update({"units": "px", "t_start_s": "null", "denoise_enabled": np.bool_(True), "root": [1.0, 2.0]})
    got, attrs = read_centrelines(path)
    np.testing.assert_array_equal(got.x, batch.x)
    assert attrs["t_start_s"] is None and attrs["denoise_enabled"] is True and not got.lost.any()
    truth, _, present = read_truth(path)
    assert "lost" not in present and len(truth) == 4


@pytest.mark.parametrize("value", [None, True, np.bool_(False), [], [1, 2.5], {"a": None}])
def test_attribute_values_are_what_matlab_reads(tmp_path: Path, value: object) -> None:
    path = tmp_path / "a.h5"
    write_centrelines(path, make_batch(1), {"units": "px", "v": value})
    with h5py.File(path) as f:
        if value is None:
            assert "v" not in f.attrs
        else:
            assert plain_type(f, "v")


def test_docs_formats_lists_every_dataset_with_its_unit() -> None:
    text = (Path(__file__).resolve().parents[2] / "docs" / "formats.md").read_text()
    section = text.split("## Centreline files (HDF5)", 1)[1].split("\n## ", 1)[0]
    rows = {
        line.split("|")[1].strip(): line.split("|")[4].strip()
        for line in section.splitlines()
        if line.startswith("| `/")
    }
    for spec in DATASETS:
        row = next((unit for names, unit in rows.items() if f"`/{spec.name}`" in names), None)
        assert row == ("length" if spec.units == LENGTH else spec.units), spec.name
