"""Property-based fuzzing of the rig's YAML loader: a rig file with any value in any key, characters
changed, or any text at all, loads or gives one ConfigError naming the file (never another exception)."""

from __future__ import annotations

from pathlib import Path

from hypothesis import HealthCheck, given, settings

from flagtrack.daemon.bench.fuzz_targets import check_rig_text, rig_texts


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=rig_texts())
def test_any_rig_text_loads_or_is_a_config_error_naming_the_file(tmp_path: Path, text: str) -> None:
    check_rig_text(tmp_path, text)


def test_a_rig_file_that_is_not_utf8_is_a_config_error(tmp_path: Path) -> None:
    """What `bench fuzz` found: bytes that are not UTF-8 raised UnicodeDecodeError (a traceback)."""
    check_rig_text(tmp_path, "rig: \ud800")  # written as the bytes a lone surrogate makes
