"""`flagtrack bench reach`: one simulated recording of the geometry grid, its reach at three lengths."""

from __future__ import annotations

import json

import pytest

from flagtrack.daemon.bench.geometry import plan
from flagtrack.daemon.bench.reach import evaluate, summary
from flagtrack.daemon.cli import main


def test_the_reach_finds_the_true_length_from_chains_too_short_and_too_long() -> None:
    row = evaluate(plan(1, 0, 0.1)[0])
    for factor in ("1.0", "0.9", "1.1"):
        assert row["reach"][factor] * float(factor) == pytest.approx(1.0, abs=0.01), row["reach"]


def test_summary_counts_the_judged_and_takes_the_largest_miss() -> None:
    rows = [{"reach": {"1.0": 1.004, "0.9": 1.10, "1.1": None}}, {"reach": {"1.0": 0.99, "0.9": 1.12, "1.1": None}}]
    figures = summary(rows)
    assert figures["1.0"] == {"judged": 2, "max_miss": pytest.approx(0.01)}
    assert figures["0.9"]["max_miss"] == pytest.approx(0.01) and figures["1.1"] == {"judged": 0, "max_miss": None}


def test_the_command_prints_one_json_object(capsys: pytest.CaptureFixture) -> None:
    assert main(["bench", "reach", "--n", "1", "--duration", "0.1", "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["summary"]["recordings"] == 1 and len(document["cases"]) == 1
