"""The ``tracker:`` config section: YAML in, core parameters out, errors naming key and file."""

from __future__ import annotations

from pathlib import Path

import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.tracking.section import Method, TrackingConfig, load_tracking_config


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    return path


def test_yaml_section_to_tracker_params(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        """
camera: {id: main}
tracker:
  root: [102, 240.5]
  length: 180
  direction_deg: 10
  joints: 12
  alpha: 0.5
  tau_s: 0.0004
  dt_s: 0.0002
  ds: 2.0
  min_events: 3
  denoise: {window_us: 800}
""",
    )
    config = load_tracking_config(path)
    params = config.tracker_params(path=str(path))
    assert params.chain.root == (102.0, 240.5) and params.chain.n_joints == 12
    assert params.chain.min_events == 3 and params.chain.refine_deg == 10.0
    assert params.denoise is not None and params.denoise.window_us == 800
    assert params.schedule.segments[0].dt_s == 0.0002 and params.schedule.segments[0].tau_s == 0.0004
    assert params.n_s == 91


def test_paper_method_drops_the_robust_additions() -> None:
    params = TrackingConfig(root=(0, 0), length=100, method=Method.PAPER, min_events=7).tracker_params()
    assert params.chain.min_events == 1 and params.chain.refine_deg is None and params.denoise is None
    attrs = TrackingConfig(root=(0, 0), length=100, method=Method.PAPER).attrs()
    assert attrs["method"] == "paper" and attrs["min_events"] == 1 and attrs["denoise_enabled"] is False


def test_defaults_are_the_papers() -> None:
    params = TrackingConfig(root=(1, 2), length=200).tracker_params()
    assert params.chain.n_joints == 10 and params.chain.alpha == 0.6
    assert params.n_s == 51  # ds = L / 50
    seg = params.schedule.segments[0]
    assert seg.dt_s == seg.tau_s == 2.5e-4


def test_schedule_segments(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        """
tracker:
  root: [0, 0]
  length: 100
  schedule:
    - {t_from_s: 0, dt_s: 0.005, tau_s: 0.005}
    - {t_from_s: 2.5, dt_s: 0.0003, tau_s: 0.0004}
""",
    )
    params = load_tracking_config(path).tracker_params()
    assert [(s.t_from_s, s.dt_s, s.tau_s) for s in params.schedule.segments] == [
        (0.0, 0.005, 0.005),
        (2.5, 0.0003, 0.0004),
    ]


@pytest.mark.parametrize(
    ("text", "key", "words"),
    [
        ("tracker: {length: 100}", "tracker.root", "required"),
        ("tracker: {root: [0, 0]}", "tracker.length", "required"),
        ("tracker: {root: [0, 0], length: 100, alpah: 1}", "tracker.alpah", "unknown key"),
        ("tracker: {root: [0, 0], length: 100, joints: ten}", "tracker.joints", "expected int"),
        ("tracker: {root: [0, 0], length: 100, method: fast}", "tracker.method", "must be one of"),
        ("tracker: {root: [0, 0], length: 100, alpha: 1.5}", "tracker.alpha", "alpha"),
        ("tracker: {root: [0, 0], length: 100, denoise: {window_us: 0}}", "tracker.denoise", "window_us"),
        (
            "tracker: {root: [0, 0], length: 100, schedule: [{t_from_s: 0, dt_s: 0, tau_s: 1}]}",
            "tracker.schedule[0]",
            "dt_s",
        ),
    ],
)
def test_errors_name_key_and_file(tmp_path: Path, text: str, key: str, words: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_tracking_config(path).tracker_params(path=str(path))
    assert info.value.key == key and info.value.path == str(path)
    assert words in str(info.value)


def test_overrides_replace_only_given_values() -> None:
    config = TrackingConfig(root=(1, 2), length=50, alpha=0.4)
    new = config.with_overrides(alpha=None, length=80.0, root=None)
    assert new.alpha == 0.4 and new.length == 80.0 and new.root == (1, 2)


def test_missing_section_gives_defaults(tmp_path: Path) -> None:
    assert load_tracking_config(_write(tmp_path, "camera: {}\n")) == TrackingConfig()


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("traker: {root: [0, 0], length: 100}\n", "key 'traker': unknown key (did you mean 'tracker'?)"),
        ("format: flagtrack-calibration\nversion: 1\n", "a calibration file, not a config with a 'tracker:' section"),
    ],
)
def test_a_misspelt_section_or_a_calibration_is_named_not_taken_for_defaults(tmp_path: Path, text, words) -> None:
    """`reconstruct -c` with `traker:` said "key 'tracker.root': required"; with a calibration, the same."""
    with pytest.raises(ConfigError) as caught:
        load_tracking_config(_write(tmp_path, text))
    assert words in str(caught.value) and "rig.yaml" in str(caught.value)


def test_the_denoise_section_is_the_core_filter_parameters_with_the_robust_default(tmp_path: Path) -> None:
    """One definition of each filter parameter: the section is the core's DenoiseParams; keys it does not
    give keep the robust method's adaptive default (max 3 neighbours), not the classic filter's 1."""
    from flagtrack.daemon.core.denoise import DenoiseParams
    from flagtrack.daemon.tracking.section import ROBUST_DENOISE

    config = load_tracking_config(_write(tmp_path, "tracker: {root: [0, 0], length: 100, denoise: {window_us: 800}}"))
    assert isinstance(config.denoise, DenoiseParams)
    assert config.denoise.window_us == 800 and config.denoise.max_neighbours == ROBUST_DENOISE.max_neighbours == 3
    assert DenoiseParams().max_neighbours == 1  # the classic filter stays the core's own default
    assert TrackingConfig().denoise == ROBUST_DENOISE


def test_the_tracker_section_defaults_are_the_chain_defaults() -> None:
    """The section's chain keys default to ChainParams' own values (no second definition drifting)."""
    import dataclasses

    from flagtrack.daemon.core.chain import ChainParams

    chain = {f.name: f.default for f in dataclasses.fields(ChainParams)}
    section = TrackingConfig()
    assert (section.joints, section.direction_deg, section.alpha, section.angle_limit_deg) == (
        chain["n_joints"],
        chain["direction_deg"],
        chain["alpha"],
        chain["angle_limit_deg"],
    )
