"""The lower bounds in pyproject.toml are no lower than the first releases that have what the code uses.

Each floor was found on the releases themselves (their wheels' sources and stubs, imported with this
NumPy): the table says why. The installed packages must have those APIs, which is what a lowered floor
would let a user's older install lack.
"""

from __future__ import annotations

import inspect
import tomllib

import pytest
from packaging.requirements import Requirement
from packaging.version import Version

from tests.conftest import REPO

FLOORS = {
    # zenoh-python 1.0.0's Session has no liveliness() (tokens, liveliness subscribers): 1.0.1 has
    "eclipse-zenoh": ("1.0.1", "Session.liveliness (transport.Bus.declare_alive, watch_liveliness)"),
    # rerun 0.22.1 has neither rr.Scalars, RecordingStream.set_time(duration=) nor serve_grpc: 0.23.0 has all
    "rerun-sdk": ("0.23", "rr.Scalars, set_time(duration=), TimeColumn(duration=), serve_grpc (services/viewer.py)"),
    # h5py 3.10 wheels are built for NumPy 1 ("numpy.dtype size changed" on import with NumPy 2)
    "h5py": ("3.11", "imports with NumPy 2, which numpy>=1.26 allows"),
    # opencv-python-headless 4.10.0.82 is built for NumPy 1 ("numpy.core.multiarray failed to import")
    "opencv-python-headless": ("4.10.0.84", "imports with NumPy 2 (calibration/corners.py)"),
    # numba 0.59 (NumPy <= 1.26) compiles and runs every kernel: EVT 2/3 codecs, packets, twin, tracker
    "numba": ("0.59", "njit(cache=True, nogil=True) kernels"),
    # cryptography 41.0.7 has no Certificate.not_valid_after_utc (42.0.0 has): tests/unit/test_certs.py fails on it
    "cryptography": ("42.0", "Certificate.not_valid_before_utc / not_valid_after_utc (daemon/security/certs.py)"),
}


def declared_floors() -> dict[str, Version]:
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    floors = {}
    for line in project["dependencies"]:
        req = Requirement(line)
        lower = [Version(s.version) for s in req.specifier if s.operator in (">=", "==", "~=")]
        if lower:
            floors[req.name] = max(lower)
    return floors


@pytest.mark.parametrize("name", sorted(FLOORS))
def test_floor_is_at_least_the_first_release_with_what_the_code_uses(name: str) -> None:
    first, why = FLOORS[name]
    declared = declared_floors()
    assert name in declared, f"{name} has no lower bound"
    assert declared[name] >= Version(first), f"{name}>={declared[name]} is too low: needs {first} for {why}"


def test_installed_rerun_has_the_viewers_apis() -> None:
    import rerun as rr

    assert hasattr(rr, "Scalars") and hasattr(rr.Scalars, "columns")
    assert hasattr(rr.RecordingStream, "serve_grpc") and hasattr(rr, "serve_web_viewer")
    assert "duration" in inspect.signature(rr.RecordingStream.set_time).parameters
    rr.TimeColumn("t", duration=[0.0, 1.0])


def test_installed_zenoh_has_liveliness() -> None:
    import zenoh

    assert hasattr(zenoh.Session, "liveliness") and hasattr(zenoh, "SampleKind")
