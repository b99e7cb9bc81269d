"""Typed config: values checked against type hints, errors name the key and the file."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from flagtrack.daemon.config import from_mapping, load_yaml, to_mapping
from flagtrack.daemon.errors import ConfigError


class Mode(enum.Enum):
    FAST = "fast"
    SLOW = "slow"


@dataclass(frozen=True)
class Inner:
    alpha: float = 0.6
    joints: int = 10


@dataclass(frozen=True)
class Outer:
    name: str
    inner: Inner = field(default_factory=Inner)
    mode: Mode = Mode.FAST
    root: tuple[float, float] = (0.0, 0.0)
    limit: float | None = None

    def __post_init__(self) -> None:
        if self.inner.joints < 1:
            raise ValueError("inner.joints must be at least 1")


def test_nested_values_are_converted() -> None:
    cfg = from_mapping(Outer, {"name": "rig", "inner": {"alpha": 1}, "mode": "slow", "root": [1, 2]})
    assert cfg == Outer(name="rig", inner=Inner(alpha=1.0), mode=Mode.SLOW, root=(1.0, 2.0))
    assert to_mapping(cfg)["mode"] == "slow"


@pytest.mark.parametrize(
    ("data", "key", "words"),
    [
        ({}, "name", "required"),
        ({"name": "a", "inner": {"alpah": 1}}, "inner.alpah", "unknown key"),
        ({"name": "a", "inner": {"joints": "ten"}}, "inner.joints", "expected int"),
        ({"name": "a", "inner": {"joints": True}}, "inner.joints", "expected int"),
        ({"name": "a", "mode": "medium"}, "mode", "one of"),
        ({"name": "a", "root": [1]}, "root", "expected 2 values"),
        ({"name": "a", "limit": "x"}, "limit", "expected float"),
        ({"name": "a", "inner": {"joints": 0}}, None, "at least 1"),
    ],
)
def test_errors_name_key_and_file(data: dict, key: str | None, words: str) -> None:
    with pytest.raises(ConfigError) as info:
        from_mapping(Outer, data, path="rig.yaml")
    message = str(info.value)
    assert "rig.yaml" in message and words in message
    if key:
        assert f"'{key}'" in message and info.value.key == key


def test_load_yaml_reports_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("tracker:\n  alpha: [1, 2\n")
    with pytest.raises(ConfigError, match=r"bad.yaml.*line 3"):
        load_yaml(bad)
    with pytest.raises(ConfigError, match="cannot read"):
        load_yaml(tmp_path / "missing.yaml")
