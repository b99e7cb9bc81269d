"""``flagtrack bench verdicts`` end to end: the real command on its quick preset (recordings made into a
cache folder, tracked on two processes), its JSON figures checked for their keys, their arithmetic and
the targets that hold on the quick cases; bad options refused in one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from flagtrack.daemon.bench.verdict_runs import kinematics_seeds, plan
from flagtrack.daemon.cli import main

GROUPS = {"clean", "clean_paper", "acq", "noise", "weak_thinned", "weak_slow"}
TOTALS = ("updates", "off", "found_off", "lost_or_stale")


def _bench(*options: str) -> dict:
    command = [sys.executable, "-m", "flagtrack.daemon", "bench", "verdicts", "--json", "--jobs", "2", *options]
    result = subprocess.run(command, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr[-2000:]
    return json.loads(result.stdout)


def _check_arithmetic(figures: dict) -> None:
    for row in figures["runs"]:
        assert 0 <= row["found_off"] <= row["off"] <= row["updates"] and row["updates"] > 0, row
        assert max(row["lost"], row["stale"]) <= row["lost_or_stale"] <= min(row["lost"] + row["stale"], row["updates"])
    for group, totals in figures["groups"].items():
        rows = [row for row in figures["runs"] if row["group"] == group]
        assert totals["runs"] == len(rows) and all(totals[k] == sum(r[k] for r in rows) for k in TOTALS)
        if totals["off"]:
            assert totals["found_while_off"] == pytest.approx(totals["found_off"] / totals["off"])
    pooled = figures["pooled"]
    pooled_groups = GROUPS - {"clean", "clean_paper"}
    assert pooled["off"] == sum(figures["groups"][g]["off"] for g in pooled_groups)
    assert pooled["found_off"] == sum(figures["groups"][g]["found_off"] for g in pooled_groups)


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_quick_run_gives_every_figure_and_meets_the_clean_and_still_targets(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    figures = _bench("--quick", "--cache", str(cache))
    assert {"settings", "groups", "pooled", "clean", "still", "runs", "wall_s", "load_average"} <= set(figures)
    assert set(figures["groups"]) == GROUPS
    assert figures["settings"]["seeds"] == [2] and figures["pooled"]["cases"] == ["acq", "noise", "weak"]
    _check_arithmetic(figures)
    groups = figures["groups"]
    assert groups["clean"]["eps_max_over_l"] < 0.01 and groups["clean_paper"]["eps_max_over_l"] < 0.05
    assert figures["clean"]["within_target"] and figures["clean"]["lost_or_stale_share"] <= 0.02
    assert groups["acq"]["off"] > 0 and groups["acq"]["found_while_off"] <= 0.10  # started 90 deg off: off at first
    assert groups["weak_slow"]["off"] > 0  # the slow photoreceptor puts the chain off the flag
    still = figures["still"]
    assert [p["kind"] for p in still["points"]] == ["still_up", "flapping", "still_down"]
    assert all(p["updates"] > 500 and p["e_over_l_rms"] < 0.005 for p in still["points"])
    assert still["within_target"] and abs(still["gap_over_l"]) <= 0.0005
    assert sorted(p.name for p in cache.iterdir()) == [
        "verdicts_v1_esim_2_2p.npz",
        "verdicts_v1_slow_2_2p.npz",
        "verdicts_v1_twin_0_quick.npz",
    ]
    again = _bench("--quick", "--cache", str(cache), "--cases", "clean")  # from the cache: the same figures
    assert again["runs"] == [row for row in figures["runs"] if row["case"] == "clean"]
    assert again["still"] is None and again["pooled"] is None


def test_the_plan_covers_each_case_once_per_start_and_method() -> None:
    runs = plan(("clean", "acq", "noise", "weak"), (2, 11), 5.0)
    assert len(runs) == 2 * (2 + 3 + 1 + 4) and len({r.name for r in runs}) == len(runs)
    assert {r.start for r in runs if r.case == "acq"} == {"+90", "-90", "across"}
    assert {(r.generator, r.change) for r in runs if r.case == "weak"} == {("esim", "thin"), ("slow", "none")}
    assert [r.method for r in runs if r.case == "clean"] == ["robust", "paper"] * 2
    assert kinematics_seeds(8) == (2, 11, 5, 26, 9, 15, 27, 28)


@pytest.mark.parametrize(
    ("options", "named"),
    [
        (["--cases", "clean,windy"], "cases"),
        (["--seeds", "0"], "seeds"),
        (["--periods", "nan"], "periods"),
        (["--jobs", "-1"], "jobs"),
    ],
)
def test_bad_options_are_refused_in_one_line(options: list[str], named: str, capsys: pytest.CaptureFixture) -> None:
    assert main(["bench", "verdicts", *options]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and named in err and "Traceback" not in err


def test_a_cache_that_is_a_file_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "cache").write_text("not a folder")
    assert main(["bench", "verdicts", "--cache", str(tmp_path / "cache")]) == 2
    assert "is not a directory" in capsys.readouterr().err
