"""Every source module installs under the flagtrack namespace and imports."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from tests.conftest import REPO

TOP_FOLDERS = ("daemon", "drivers", "calibration", "client")


def source_modules() -> list[str]:
    names = []
    for top in TOP_FOLDERS:
        for path in sorted((REPO / top).rglob("*.py")):
            rel = path.relative_to(REPO / top).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            if parts and parts[-1] == "__main__":
                continue
            names.append(".".join(["flagtrack", top, *parts]))
    return names


@pytest.mark.parametrize("name", source_modules())
def test_module_imports_from_installed_namespace(name: str) -> None:
    module = importlib.import_module(name)
    top = name.split(".")[1]
    assert Path(module.__file__).resolve().is_relative_to(REPO / top) or "site-packages" in module.__file__
