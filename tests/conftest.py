"""Shared pytest fixtures: the real recordings in ../shared/data/real and the hardware switch; the fake
camera SDKs' fixtures (``fake_nd``, ``fake_hal``, ``fake_dv``, ``no_sdk``) are a plugin of every test."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_REAL = Path(os.environ.get("FLAGTRACK_SHARED_DATA", REPO.parent / "shared" / "data" / "real"))

pytest_plugins = ["tests.fakes.fixtures", "tests.fakes.tunnel"]


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--device", action="append", default=[], help="run hardware tests against DEVICE")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
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
