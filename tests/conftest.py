"""Shared pytest fixtures: the real recordings in ../shared/data/real and the hardware switch; the fake
camera SDKs' fixtures (``fake_nd``, ``fake_hal``, ``fake_dv``, ``no_sdk``) are a plugin of every test.
The session: slow tests run first, and under xdist numba's cache is filled before the workers start."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_REAL = Path(os.environ.get("FLAGTRACK_SHARED_DATA", REPO.parent / "shared" / "data" / "real"))

pytest_plugins = ["tests.fakes.fixtures", "tests.fakes.tunnel"]


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--device", action="append", default=[], help="run hardware tests against DEVICE")


WARM_UP = "import sys; from pathlib import Path; from flagtrack.daemon.aot.build import run_workload; run_workload(Path(sys.argv[1]))"


def pytest_sessionstart(session: pytest.Session) -> None:
    """Under xdist, fill numba's cache once before the workers start: on a clean clone each worker (and
    each command a test runs) would otherwise compile the same kernels itself, beside the others."""
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    started = time.monotonic()
    with tempfile.TemporaryDirectory() as folder:
        try:
            code = subprocess.run([sys.executable, "-c", WARM_UP, folder], capture_output=True, timeout=600).returncode
        except subprocess.TimeoutExpired:
            code = None
    if reporter is not None:
        outcome = "ready" if code == 0 else f"not warmed (exit {code}; the tests compile them as they go)"
        reporter.write_line(f"numba kernels {outcome} in {time.monotonic() - started:.0f} s")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # the slow tests first (in their order): xdist's work stealing then ends the run on short tests
    # instead of one worker finishing a long one alone
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
    if config.getoption("--device"):
        return
    skip = pytest.mark.skip(reason="hardware test: name a device with --device")
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def shared_real() -> Path:
    """The folder of real recordings; skips the test when ../shared is absent (a user's clone)."""
    if not (SHARED_REAL / "REFERENCE.json").is_file():
        pytest.skip(f"real recordings not found at {SHARED_REAL} (../shared is absent in a user's clone)")
    return SHARED_REAL


@pytest.fixture(scope="session")
def reference_values(shared_real: Path) -> dict:
    """REFERENCE.json: per file, the maker's decoder's count, first/last events and digest."""
    return json.loads((shared_real / "REFERENCE.json").read_text())
