"""Typed config: values checked against type hints, errors name the key and the file."""

from __future__ import annotations

import enum
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.typed_yaml import (
    from_mapping,
    load_yaml,
    require_file,
    require_folder,
    require_output_file,
    to_mapping,
)


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
        ({"name": "a", "inner": {"alpha": 10**400}}, "inner.alpha", "401 digits is beyond any float"),  # OverflowError
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


def test_a_key_given_twice_is_refused_naming_both_lines(tmp_path: Path) -> None:
    """PyYAML keeps the last of two equal keys: an edit to the first would do nothing, silently."""
    twice = tmp_path / "rig.yaml"
    twice.write_text("tracker:\n  root: [100, 240]\n  length: 400\n  root: [0, 0]\nrecorder: {}\n")
    with pytest.raises(ConfigError, match=r"rig.yaml.*line 4.*'root' given twice \(first at line 2\)"):
        load_yaml(twice)
    twice.write_text("tracker: {root: [1, 2]}\ntracker: {length: 3}\n")
    with pytest.raises(ConfigError, match="'tracker' given twice"):
        load_yaml(twice)
    merged = tmp_path / "merged.yaml"  # a merge key and an override of what it brings are not a repeat
    merged.write_text("base: &b {root: [1, 2], length: 3}\ntracker:\n  <<: *b\n  length: 4\n")
    assert load_yaml(merged)["tracker"] == {"root": [1, 2], "length": 4}
    once = tmp_path / "ok.yaml"
    once.write_text("tracker: {root: [1, 2]}\nrecorder: {root: 3}\n")  # the same key in two sections
    assert load_yaml(once) == {"tracker": {"root": [1, 2]}, "recorder": {"root": 3}}


@dataclass(frozen=True)
class Window:
    x: int = 0

    def __post_init__(self) -> None:
        if self.x < 0:
            raise ConfigError("must be >= 0", key="camera.roi.x")  # a section's own check: key, no file


@dataclass(frozen=True)
class WithWindow:
    roi: Window = field(default_factory=Window)


def test_a_sections_own_error_also_names_the_file() -> None:
    with pytest.raises(ConfigError) as info:
        from_mapping(WithWindow, {"roi": {"x": -1}}, path="rig.yaml")
    assert info.value.key == "camera.roi.x" and info.value.path == "rig.yaml"
    assert str(info.value) == "file rig.yaml, key 'camera.roi.x': must be >= 0"


def test_required_file_must_exist_and_be_a_file(tmp_path: Path) -> None:
    (tmp_path / "run.raw").write_bytes(b"x")
    assert require_file(tmp_path / "run.raw", key="camera.replay.path", path="rig.yaml") == tmp_path / "run.raw"
    for value, words in ((tmp_path / "nope.raw", "no such file"), (tmp_path, "is a folder")):
        with pytest.raises(ConfigError, match=words) as info:
            require_file(value, key="camera.replay.path", path="rig.yaml")
        assert info.value.key == "camera.replay.path" and info.value.path == "rig.yaml"
        assert str(value) in str(info.value)


def test_output_folders_are_checked_without_being_created(tmp_path: Path) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a folder should go")
    deep = tmp_path / "a" / "b" / "c"
    assert require_folder(deep, key="recorder.directory", path="rig.yaml") == deep
    assert require_output_file(deep / "live.rrd", key="viewer.rrd_path", path="rig.yaml") == deep / "live.rrd"
    assert not (tmp_path / "a").exists()  # checked, not made
    for check, value, key, words in (
        (require_folder, blocker / "sub", "recorder.directory", f"{blocker} is a file"),
        (require_folder, blocker, "supervisor.runs_dir", f"{blocker} is a file"),
        (require_output_file, blocker / "live.rrd", "viewer.rrd_path", f"{blocker} is a file"),
        (require_output_file, tmp_path, "viewer.rrd_path", "is a folder, not a file"),
    ):
        with pytest.raises(ConfigError, match=re.escape(words)) as info:
            check(value, key=key, path="rig.yaml")
        assert info.value.key == key and info.value.path == "rig.yaml"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_a_folder_without_write_permission_is_refused(tmp_path: Path) -> None:
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    with pytest.raises(ConfigError, match="not writable") as info:
        require_folder(locked / "rec", key="recorder.directory", path="rig.yaml")
    assert info.value.key == "recorder.directory"


@dataclass(frozen=True)
class _Leaf:
    a: int = 1
    b: int = 2
    extra: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class _Branch:
    leaf: _Leaf = _Leaf(a=5)
    name: str = "x"


@dataclass(frozen=True)
class _Root:
    branch: _Branch = _Branch(leaf=_Leaf(a=7, b=8))


def test_a_nested_section_starts_from_its_fields_default() -> None:
    """Keys a section leaves out keep the value of the field's default (here a=7, b=8 set by _Root),
    not the section class's own defaults (a=1, b=2); plain values below it are converted as usual."""
    got = from_mapping(_Root, {"branch": {"leaf": {"b": 3, "extra": {"k": 1}}}})
    assert got.branch.leaf == _Leaf(a=7, b=3, extra={"k": 1}) and got.branch.name == "x"
    assert from_mapping(_Branch, {"leaf": {"b": 4}}).leaf == _Leaf(a=5, b=4)
    with pytest.raises(ConfigError, match="branch.leaf.c"):
        from_mapping(_Root, {"branch": {"leaf": {"c": 1}}})
