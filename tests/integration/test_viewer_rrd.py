"""The demo's .rrd, checked as a person would without a screen, through Rerun's own tools: `rerun rrd
verify` loads it, the dataframe API finds the entities and the one timeline docs/viewer.md promises,
the layout (blueprint) is in it, `rerun rrd stats` finds it within 5 times its lower bound in chunks,
and what it shows makes sense (the sweep's speeds, a flag that flapped, the points logged)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.conftest import REPO
from tests.integration.test_viewer_layout import blueprint_views, columns

pytestmark = pytest.mark.slow  # (the quick demo, run once for this module and test_demo: conftest.py)


def rerun_cli(*args: str) -> subprocess.CompletedProcess[str]:
    """The `rerun` command that comes with rerun-sdk (``python -m rerun``)."""
    return subprocess.run([sys.executable, "-m", "rerun", *args], capture_output=True, text=True, timeout=240)


def promised_entities() -> dict[str, tuple[str, bool]]:
    """{entity path: (archetype, in the demo)} from the table of docs/viewer.md."""
    text = (REPO / "docs" / "viewer.md").read_text()
    section = text.split("## Entities and timeline", 1)[1].split("\n## ", 1)[0]
    rows = [line.split("|")[1:-1] for line in section.splitlines() if line.startswith("| `")]
    return {"/" + row[0].strip(" `"): (row[1].strip(), row[4].strip().startswith("yes")) for row in rows}


def dataframe_schema(rrd: Path) -> tuple[set[str], dict[str, set[str]]]:
    """(index column names, {entity path: archetype names}) from Rerun's dataframe API: the store's
    schema in rerun-sdk 0.41 (rerun.chunk), rerun.dataframe.load_recording in older ones."""
    archetypes: dict[str, set[str]] = {}
    try:
        from rerun.chunk import RrdReader
    except ImportError:
        import rerun.dataframe

        schema = rerun.dataframe.load_recording(str(rrd)).schema()
        for column in schema.component_columns():  # archetypes show as their indicator components
            name = column.component_name.rsplit(".", 1)[-1]
            if name.endswith("Indicator"):
                archetypes.setdefault(column.entity_path, set()).add(name.removesuffix("Indicator"))
    else:
        schema = RrdReader(rrd).store().schema()
        for column in schema.component_columns():
            if column.archetype:
                archetypes.setdefault(column.entity_path, set()).add(column.archetype.rsplit(".", 1)[-1])
    return {column.name for column in schema.index_columns()}, archetypes


@pytest.fixture(scope="module")
def demo(quick_demo: subprocess.CompletedProcess[str]) -> dict[str, Any]:
    result = quick_demo
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    assert summary["rrd"] and Path(summary["rrd"]).is_file()
    return summary


def test_rerun_verifies_the_demo_file(demo: dict[str, Any]) -> None:
    result = rerun_cli("rrd", "verify", demo["rrd"])
    assert result.returncode == 0, result.stderr + result.stdout
    assert "1 file verified without error" in result.stdout + result.stderr


def test_the_file_has_the_entities_and_timeline_the_docs_promise(demo: dict[str, Any]) -> None:
    promised = promised_entities()
    assert len(promised) >= 13 and "/plots/lost" in promised  # the table was read
    indexes, archetypes = dataframe_schema(Path(demo["rrd"]))
    assert indexes == {"camera"}  # one timeline: seconds of the camera clock
    for entity, (archetype, in_demo) in promised.items():
        if in_demo:
            assert archetype in archetypes.get(entity, set()), f"{entity}: {archetypes.get(entity)}"
        else:
            assert entity not in archetypes
    assert set(archetypes) <= set(promised) | {"/__properties", "/__properties/recording"}


def test_the_camera_timeline_is_a_duration_and_every_entity_is_on_it(demo: dict[str, Any]) -> None:
    import pyarrow as pa

    rerun_chunk = pytest.importorskip("rerun.chunk", reason="rerun.chunk (RrdReader) is rerun-sdk 0.41's")
    seen: dict[str, int] = {}
    for chunk in rerun_chunk.RrdReader(demo["rrd"]).stream():
        batch = chunk.to_record_batch()
        if "camera" in batch.schema.names:
            assert pa.types.is_duration(batch.schema.field("camera").type)
            seen[chunk.entity_path] = seen.get(chunk.entity_path, 0) + batch.num_rows
    wanted = [entity for entity, (_, in_demo) in promised_entities().items() if in_demo]
    assert all(seen.get(entity, 0) > 0 for entity in wanted), seen


def test_the_layout_is_in_the_file(demo: dict[str, Any]) -> None:
    pytest.importorskip("rerun.chunk", reason="rerun.chunk (RrdReader) is rerun-sdk 0.41's")
    views = blueprint_views(Path(demo["rrd"]))
    assert set(views) == {
        "camera",
        "supervisor",
        "sweep log",
        "tip y",
        "A/L",
        "event rate",
        "wind speed",
        "Δ_RMS",
        "lost",
        "shed",
    }
    assert {view["origin"] for view in views.values()} >= {"plots/tip_y", "plots/wind_speed_mps", "supervisor/state"}


def test_chunks_are_within_five_times_the_lower_bound(demo: dict[str, Any]) -> None:
    result = rerun_cli("rrd", "stats", demo["rrd"])
    assert result.returncode == 0, result.stderr
    bound = re.search(r"theoretical lower bound:\s*([\d ]+) chunks", result.stdout)
    effective = re.search(r"effective:\s*([\d ]+) chunks", result.stdout)
    if bound is None or effective is None:
        pytest.skip("this rerun's `rrd stats` prints no lower bound (rerun-sdk 0.41 does)")
    lower, got = int(bound.group(1).replace(" ", "")), int(effective.group(1).replace(" ", ""))
    assert 0 < got <= 5 * lower, result.stdout[-600:]


def test_what_the_file_shows_is_the_sweep(demo: dict[str, Any]) -> None:
    pytest.importorskip("rerun.chunk", reason="rerun.chunk (RrdReader) is rerun-sdk 0.41's")
    got = columns(Path(demo["rrd"]))
    speeds = np.array([v[0] for v in got["/plots/wind_speed_mps"]["Scalars:scalars"]])
    for speed in (4.2, 4.7, 5.2):  # the quick sweep's points, read back from the tunnel
        assert np.any(np.abs(speeds - speed) < 0.1), speed
    a_over_l = np.array([v[0] for v in got["/plots/amplitude_over_l"]["Scalars:scalars"]])
    assert a_over_l.max() > 0.1 and a_over_l.min() < 0.05  # the flag flapped at 5.2 m/s, was still at 4.2
    log = [v[0] for v in got["/supervisor/log"]["TextLog:text"]]
    points = {re.search(r"point (\S+)", line).group(1) for line in log if "point " in line}
    assert len(points) == demo["points"] == 5
    assert any("flag flapping" in line for line in log) and any("flag still" in line for line in log)
    assert got["/supervisor/state"]["TextDocument:text"][-1][0].startswith("**")
