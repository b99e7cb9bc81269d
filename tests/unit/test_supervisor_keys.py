"""docs/supervisor.md documents every key of the ``supervisor:`` section: each table lists exactly the
fields of its dataclass (a key added without a row fails here), with the code's defaults."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
import yaml

from flagtrack.daemon.core.onset import OnsetParams
from flagtrack.daemon.services.supervisor.section import ControlConfig, FeedbackConfig, SupervisorConfig
from flagtrack.daemon.sweep.plan import SweepConfig
from flagtrack.daemon.typed_yaml import to_mapping

DOC = Path(__file__).resolve().parents[2] / "docs" / "supervisor.md"
SECTIONS = {
    "supervisor:": SupervisorConfig,
    "supervisor.sweep:": SweepConfig,
    "supervisor.onset:": OnsetParams,
    "supervisor.feedback:": FeedbackConfig,
    "supervisor.control:": ControlConfig,
}


def tables(text: str) -> dict[str, dict[str, list[str]]]:
    """Heading (its first backticked words) -> key -> the row's cells."""
    found: dict[str, dict[str, list[str]]] = {}
    heading = None
    for line in text.splitlines():
        match = re.match(r"## `([^`]+)`", line)
        if match:
            heading = match.group(1)
            found[heading] = {}
        elif heading is not None and line.startswith("| `"):
            cells = [cell.strip() for cell in line.strip("|").split("|")]
            found[heading][cells[0].strip("`")] = cells
    return found


DOCUMENTED = tables(DOC.read_text())


@pytest.mark.parametrize(("heading", "cls"), SECTIONS.items(), ids=list(SECTIONS))
def test_each_table_lists_exactly_the_sections_keys(heading: str, cls: type) -> None:
    assert set(DOCUMENTED[heading]) == {f.name for f in dataclasses.fields(cls)}


@pytest.mark.parametrize(("heading", "cls"), SECTIONS.items(), ids=list(SECTIONS))
def test_documented_defaults_are_the_codes(heading: str, cls: type) -> None:
    compared = 0
    for f in dataclasses.fields(cls):
        cell = DOCUMENTED[heading][f.name][2]
        if f.default is dataclasses.MISSING:  # a section (default_factory): its own table
            continue
        if f.default is None:
            assert cell.startswith("null") or cell == "", f.name
        else:
            written = re.search(r"`([^`]*)`", cell)
            assert yaml.safe_load(written.group(1) if written else cell) == to_mapping(f.default), f.name
        compared += 1
    assert compared >= len(dataclasses.fields(cls)) - 3


def test_a_new_key_would_be_missed() -> None:
    """The parser sees the rows: a table without one of its rows no longer matches."""
    text = DOC.read_text().replace("| `readback_grace_s` |", "| readback_grace_s |")
    assert "readback_grace_s" not in tables(text)["supervisor:"]
