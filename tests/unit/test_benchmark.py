"""Accuracy benchmark: plan (seeds, variants, noise rates), tables and summaries on small synthetic rows."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.bench.accuracy_suite import plan, tables
from flagtrack.daemon.bench.accuracy_suite.evaluate import loss_time_cycles
from flagtrack.daemon.bench.accuracy_suite.report import sweep_section, targets_section


def _row(
    part: str,
    kinematics: int,
    level: float,
    method: str,
    delta: float,
    *,
    joints: int = 10,
    tau: float = 5e-3,
    n_events: int = 1000,
    t_loss: float = math.nan,
) -> dict:
    return {
        "name": f"{part}_{kinematics}_{level:g}",
        "part": part,
        "kinematics": kinematics,
        "seed": kinematics,
        "level": level,
        "frequency_hz": 10.0,
        "wavelength_over_l": 2.0,
        "w_travel": 0.5,
        "peak_to_peak_over_l": 0.5,
        "duration_s": 1.0,
        "leak_rate_hz": 0.0,
        "shot_noise_hz": 0.0,
        "n_events": n_events,
        "method": method,
        "joints": joints,
        "tau_over_t": tau,
        "events_kept": n_events,
        "track_wall_s": 0.1,
        "delta_rms_over_l": delta,
        "max_eps_rms_over_l": 2 * delta,
        "twi": 0.5,
        "twi_ref": 0.5 + delta,
        "twi_abs_error": delta,
        "twi_rel_error": delta / (0.5 + delta),
        "t_loss_cycles": t_loss,
        "evaluated_cycles": 10.0,
        "max_delta_over_l": 3 * delta,
    }


def test_seeds_depend_only_on_the_benchmark_seed() -> None:
    preset = plan.PRESETS["quick"]
    a = plan.family_tasks(7, preset, ("paper",))
    b = plan.family_tasks(7, preset, ("paper",))
    assert a == b and len({t.seed for t in a}) == preset.n_family
    assert {t.seed for t in plan.family_tasks(8, preset, ("paper",))}.isdisjoint({t.seed for t in a})
    clean = plan.sweep_clean_tasks(7, preset, ("paper",), params=False)
    assert [t.seed for t in clean] == [t.seed for t in a[: preset.n_sweep]]  # the family's first kinematics


def test_shot_levels_add_the_papers_share_of_noise_events() -> None:
    preset = plan.Preset(shot_levels=(20.0, 37.0))
    clean = plan.sweep_clean_tasks(0, preset, ("paper", "robust"), params=True)[0]
    tasks = plan.shot_tasks(
        clean, clean_events=3_000_000, duration_s=0.5, preset=preset, methods=("paper", "robust"), params=True
    )
    pixels = clean.width * clean.height
    # level 37 doubles the events: as many noise events as clean ones over the recording
    assert tasks[1].shot_noise_hz * 0.5 * pixels == pytest.approx(3_000_000)
    assert len(tasks[0].variants) > len(tasks[1].variants) == 2  # f_snr/f = 20 also carries fig. 6's sweeps


def test_task_names_are_unique_file_stems() -> None:
    preset = plan.Preset(leak_levels=(0.3, 0.6, 1.2, 1.6), shot_levels=(10.0, 20.0, 35.0))
    clean = plan.sweep_clean_tasks(0, preset, ("paper",), params=False)
    tasks = clean + plan.leak_tasks(clean, preset, ("paper",)) + plan.family_tasks(0, preset, ("paper",))
    tasks += plan.shot_tasks(clean[0], 1000, 1.0, preset, ("paper",), params=False)
    stems = [Path(t.name).with_suffix(".raw").stem for t in tasks]  # how the simulator names the files
    assert len(set(stems)) == len(tasks)


def test_param_variants_cover_each_sweep_once() -> None:
    preset = plan.Preset(joints=(5, 10), tau_over_t=(1e-3, 5e-3))
    variants = plan.param_variants(("paper",), preset)
    assert len(variants) == len(set(variants)) == 3
    assert plan.Variant("paper") in variants


def test_loss_time_is_the_first_crossing_in_cycles() -> None:
    t = np.arange(10) * 0.01
    assert loss_time_cycles(t, np.array([0, 0, 0.05, 0.2, 0.01, 0.3, 0, 0, 0, 0]), 20.0) == pytest.approx(0.6)
    assert math.isnan(loss_time_cycles(t, np.zeros(10), 20.0))


def test_tables_split_by_part_with_noise_ratio() -> None:
    rows = [
        _row("family", 0, 0, "paper", 0.004),
        _row("clean", 0, 0, "paper", 0.002, n_events=1000),
        _row("leak", 0, 1.2, "paper", 0.3, n_events=3000, t_loss=2.5),
        _row("shot", 0, 20, "paper", 0.003, n_events=1540),
        _row("shot", 0, 70, "paper", 0.02, n_events=2900),
        _row("clean", 0, 0, "paper", 0.005, joints=4),
        _row("shot", 0, 20, "paper", 0.009, tau=1e-3),
    ]
    parts = tables.split_parts(rows)
    assert [r["level"] for r in parts["leak"]] == [0, 1.2]
    assert [r["n_over_n0"] for r in parts["shot_noise"]] == pytest.approx([1.0, 1.54, 2.9])
    assert sorted(r["joints"] for r in parts["params_joints"]) == [4, 10, 10]
    assert {r["condition"] for r in parts["params_tau"]} == {"clean", "shot 20"}
    assert len(parts["family"]) == 1


def test_csv_round_trip_keeps_numbers_and_nan(tmp_path: Path) -> None:
    rows = [_row("leak", 1, 2.4, "robust", 0.0012345678901234, t_loss=3.25), _row("leak", 1, 3.6, "robust", 0.5)]
    tables.write_csv(tmp_path / "t.csv", rows, tables.COLUMNS)
    back = tables.read_csv(tmp_path / "t.csv")
    assert list(back[0]) == list(tables.COLUMNS)
    assert back[0]["delta_rms_over_l"] == rows[0]["delta_rms_over_l"] and back[0]["t_loss_cycles"] == 3.25
    assert math.isnan(back[1]["t_loss_cycles"]) and back[1]["joints"] == 10 and back[1]["method"] == "robust"


def test_family_summary_gives_distributions_per_method() -> None:
    rows = [_row("family", i, 0, m, d) for i, d in enumerate((0.001, 0.002, 0.003, 0.02)) for m in ("robust", "paper")]
    rows.append(_row("family", 9, 0, "paper", 0.5, t_loss=0.3))
    summary = tables.family_summary(rows)
    assert [e["method"] for e in summary] == ["paper", "robust"]
    robust = summary[1]
    assert robust["recordings"] == 4 and robust["delta_rms_over_l_median"] == pytest.approx(0.0025)
    assert robust["delta_rms_over_l_max"] == 0.02 and robust["below_1pct"] == 0.75 and robust["lost"] == 0
    assert summary[0]["lost"] == 1


def test_sweep_summary_and_tolerated_level() -> None:
    rows = tables.with_noise_ratio(
        [_row("clean", k, 0, "robust", 0.002) for k in range(2)]
        + [
            _row("leak", k, lv, "robust", d, t_loss=(1.5 if d > 0.1 else math.nan))
            for k in range(2)
            for lv, d in ((1.2, 0.004 + k * 0.004), (2.4, 0.009 + k * 0.002), (3.6, 0.2))
        ]
    )
    summary = tables.sweep_summary(rows)
    assert [e["level"] for e in summary] == [0.0, 1.2, 2.4, 3.6]
    assert summary[2]["delta_rms_over_l_max"] == pytest.approx(0.011)
    assert summary[3]["lost"] == 2 and summary[3]["t_loss_cycles_min"] == 1.5
    assert tables.tolerated_level(summary, "robust") == 1.2
    text = sweep_section("(b) leak", summary, loss=True)
    assert "| 3.6 |" in text and "1.50" in text and "never (≥ 10.0)" in text
    assert "| robust | 1.10 (lost 0) |" in targets_section(summary, [], [])
