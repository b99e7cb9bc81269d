"""Fixtures that install a fake camera SDK under its real import name for one test."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

FAKES = Path(__file__).resolve().parent
FAKE_MODULES = ("neuromorphic_drivers", "metavision_hal", "dv_processing", "_fake_streams")


def _forget_fakes() -> None:
    for name in [m for m in sys.modules if m.split(".")[0] in FAKE_MODULES]:
        del sys.modules[name]


def _install(monkeypatch: pytest.MonkeyPatch, name: str) -> Iterator[ModuleType]:
    _forget_fakes()
    monkeypatch.syspath_prepend(str(FAKES))
    module = importlib.import_module(name)
    if not str(getattr(module, "__file__", "")).startswith(str(FAKES)):
        raise RuntimeError(f"{name} resolved to {module.__file__}, not the fake")
    try:
        yield module
    finally:
        _forget_fakes()


@pytest.fixture()
def fake_nd(monkeypatch: pytest.MonkeyPatch) -> Iterator[ModuleType]:
    """The fake ``neuromorphic_drivers``, with an empty USB bus (plug cameras with ``fake_nd._fake.plug``)."""
    yield from _install(monkeypatch, "neuromorphic_drivers")


@pytest.fixture()
def fake_hal(monkeypatch: pytest.MonkeyPatch) -> Iterator[ModuleType]:
    """The fake ``metavision_hal`` (plug cameras with ``fake_hal._fake.plug``)."""
    yield from _install(monkeypatch, "metavision_hal")


@pytest.fixture()
def fake_dv(monkeypatch: pytest.MonkeyPatch) -> Iterator[ModuleType]:
    """The fake ``dv_processing`` (plug cameras with ``fake_dv._fake.plug``)."""
    yield from _install(monkeypatch, "dv_processing")


@pytest.fixture()
def no_sdk(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make every camera SDK unimportable, as on a machine without them."""
    _forget_fakes()
    for name in FAKE_MODULES[:3]:
        monkeypatch.setitem(sys.modules, name, None)
