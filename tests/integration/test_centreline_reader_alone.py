"""A centreline file read as a MATLAB user would: an HDF5 library and nothing of flagtrack (h5py in a
fresh interpreter that never imports flagtrack) finds in the attributes what each array is, in which
unit, on which sensor, with the flag's length, and every dataset of the file has units and description."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from flagtrack.daemon.cli import main

READER = r"""
import json, sys
import h5py, numpy as np
out = {"datasets": {}, "problems": []}
with h5py.File(sys.argv[1], "r") as f:
    root = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in f.attrs.items()}
    def visit(name, node):
        if isinstance(node, h5py.Dataset):
            a = dict(node.attrs)
            if "units" not in a or "description" not in a:
                out["problems"].append(f"/{name} lacks units or description")
            out["datasets"][name] = {"units": str(a.get("units")), "description": str(a.get("description")),
                                     "shape": list(node.shape)}
    f.visititems(visit)
    for k, v in f.attrs.items():
        if isinstance(v, (str, bytes)) and v in ("null", b"null"):
            out["problems"].append(f"attribute {k} is the text null")
        if h5py.check_enum_dtype(f.attrs.get_id(k).dtype) is not None:
            out["problems"].append(f"attribute {k} is an HDF5 enum")
    x, length = f["x"][()], float(f.attrs["length"])
    out["tip_x_over_l_last"] = float(x[-1, -1] - root["root"][0]) / length
    out["root"] = {k: root[k] for k in ("format", "format_version", "units", "length", "sensor_width_px",
                                        "sensor_height_px", "direction_deg") if k in root}
out["flagtrack_imported"] = any(m.startswith("flagtrack") for m in sys.modules)
print(json.dumps(out))
"""


def test_a_reconstructed_file_is_read_by_an_hdf5_library_alone(recording: Path, tmp_path: Path) -> None:
    out = tmp_path / "run.h5"
    assert main(["reconstruct", str(recording), "-o", str(out), "--root", "100", "240", "--length", "200"]) == 0
    result = subprocess.run([sys.executable, "-c", READER, str(out)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    found = json.loads(result.stdout)
    assert not found["problems"] and not found["flagtrack_imported"]
    root = found["root"]
    assert root["format"] == "flagtrack-centrelines" and root["format_version"] >= 2 and root["units"] == "px"
    assert (root["sensor_width_px"], root["sensor_height_px"]) == (640, 480) and root["length"] == 200.0
    datasets = found["datasets"]
    assert set(datasets) >= {"t", "s", "x", "y", "joints/x", "joints/y", "delta_rms", "n_events", "lost"}
    assert datasets["t"]["units"] == "s" and datasets["x"]["units"] == "px" and datasets["lost"]["units"] == "1"
    assert "transpose" in datasets["x"]["description"] and "event-cloud" in datasets["delta_rms"]["description"]
    n_t, n_s = datasets["x"]["shape"]
    assert datasets["t"]["shape"] == [n_t] and datasets["s"]["shape"] == [n_s]
    assert 0.5 < found["tip_x_over_l_last"] <= 1.0  # the flag points along +x from its root
