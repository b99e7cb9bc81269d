"""Every tracker parameter reaches a result or a clean refusal (issue 30): no crash, no hang.

A property test drives the options of ``flagtrack reconstruct`` (numbers of any kind: NaN, infinities,
zero, negative, tiny and huge) through the command's own parser and the tracking set-up, then runs the
public ``Tracker`` on a short flapping recording with what was accepted. Each example has a time
bound (hypothesis' deadline); a refusal must be a ConfigError naming the option.
"""

from __future__ import annotations

import contextlib
import functools
import io
import math
from collections.abc import Iterator
from datetime import timedelta

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flagtrack.daemon.cli import build_parser
from flagtrack.daemon.commands._tracking_args import setup_from_arguments
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.chain import ChainParams, ChainState
from flagtrack.daemon.core.lost_params import LostParams
from flagtrack.daemon.core.tracker import Tracker, TrackerParams
from flagtrack.daemon.core.windows import WindowSchedule, WindowSegment
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.tracking.section import TrackingConfig
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag(length=200.0, root=(100.0, 240.0))
SPECIAL = [math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 1e-300, 1e-9, 1e-6, 1e-4, 0.5, 1.0, 7.0, 200.0, 1e9, 1e300]
NUMBERS = st.one_of(st.sampled_from(SPECIAL), st.floats(allow_nan=True, allow_infinity=True))
COUNTS = st.one_of(st.integers(-5, 2000), st.sampled_from([10**6, 10**9, -(10**9)]))
OPTIONS = {
    "--root": st.tuples(NUMBERS, NUMBERS),
    "--length": NUMBERS,
    "--direction": NUMBERS,
    "--joints": COUNTS,
    "--alpha": NUMBERS,
    "--tau": NUMBERS,
    "--dt": NUMBERS,
    "--ds": NUMBERS,
    "--t-start": NUMBERS,
    "--t-stop": NUMBERS,
    "--method": st.sampled_from(["robust", "paper"]),
}


@functools.cache
def _events() -> np.ndarray:
    """3 ms of a flapping line (about 2 000 events) and some noise."""
    params = QuickLineParams(events_per_px2=2.0, noise_rate_hz=2e5)
    return np.concatenate(list(line_events(FLAG, 0, 3_000, 640, 480, params, seed=3)))


def _argv(options: dict) -> list[str]:
    argv = ["reconstruct", "in.raw", "-o", "out.h5"]
    for name, value in options.items():
        argv += [name, *map(repr, value)] if isinstance(value, tuple) else [name, str(value)]
    return argv


def _run(tracker: Tracker) -> Iterator[CentrelineBatch]:
    """Feed the recording in 0.5 ms chunks; yield each chunk's updates (a long series is not kept)."""
    events = _events()
    for lo in range(0, 3_000, 500):
        yield tracker.feed(events[(events["t"] >= lo) & (events["t"] < lo + 500)])
    yield tracker.finish()


@settings(
    max_examples=120,
    deadline=timedelta(seconds=20),
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=True,
)
@given(st.fixed_dictionaries({}, optional=OPTIONS))
def test_any_option_gives_a_result_or_one_clean_refusal(options: dict) -> None:
    options.setdefault("--root", (100.0, 240.0))
    options.setdefault("--length", 200.0)
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            args = build_parser("reconstruct").parse_args(_argv(options))
    except SystemExit as exc:  # the parser's own refusal (``--root -inf 1``: "-inf" reads as an option)
        assert exc.code == 2
        return
    try:
        setup = setup_from_arguments(TrackingConfig(), args, path=None)
    except ConfigError as exc:
        message = str(exc)
        assert "\n" not in message and message.startswith("--"), message  # one line, naming the option
        assert message.split(":")[0] in options or message.startswith("--t-"), message
        return
    for batch in _run(setup.new_tracker((640, 480))):
        assert batch.x.shape == (len(batch), len(setup.params.s))
        assert np.isfinite(batch.x).all() and np.isfinite(batch.y).all()
        assert set(np.unique(batch.lost)) <= {0, 1} and set(np.unique(batch.stale)) <= {0, 1}
        assert not (batch.lost & batch.stale).any()


ROOTS = st.tuples(NUMBERS, NUMBERS)


@settings(max_examples=120, deadline=timedelta(seconds=20), derandomize=True)
@given(
    root=ROOTS,
    length=NUMBERS,
    joints=COUNTS,
    direction=NUMBERS,
    alpha=NUMBERS,
    tau=NUMBERS,
    stale=NUMBERS,
    min_fit=NUMBERS,
)
def test_the_core_api_refuses_with_a_value_error_or_tracks(
    root: tuple[float, float],
    length: float,
    joints: int,
    direction: float,
    alpha: float,
    tau: float,
    stale: float,
    min_fit: float,
) -> None:
    """The same through the public core API: a ValueError names the value, or the tracker runs."""
    try:
        chain = ChainParams(root=root, length=length, n_joints=joints, direction_deg=direction, alpha=alpha)
        schedule = WindowSchedule((WindowSegment(0.0, tau, tau),))
        lost = LostParams(min_fit=min_fit)
        params = TrackerParams(chain=chain, schedule=schedule, lost=lost, stale_after_s=stale)
    except ValueError as exc:
        assert "\n" not in str(exc)
        return
    tracker = Tracker(params, ChainState.at_rest(chain), sensor_size=(640, 480))
    for batch in _run(tracker):
        assert np.isfinite(batch.x).all()


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--root", "nan", "nan"], "--root: must be two finite numbers"),
        (["--joints", "1000000"], "--joints: must be 1-1000 links"),
        (["--direction", "nan"], "--direction: must be a finite number"),
        (["--t-start", "0.5", "--t-stop", "0.1"], "--t-start: must be before the stop time, got 0.5 >= 0.1"),
        (["--alpha", "1"], "--alpha: must be in (0, 1)"),
        (["--tau", "0"], "--tau: must be in [1e-06, 3600] s"),
        (["--dt", "-1"], "--dt: must be in [1e-06, 3600] s"),
        (["--ds", "1e-9"], "--ds: must be in [L / 100000, L]"),
        (["--length", "1e308"], "--length: must be a positive finite number of at most 1e+09"),  # an OverflowError
    ],
)
def test_the_issues_parameters_are_refused_by_option(argv: list[str], words: str) -> None:
    base = ["reconstruct", "in.raw", "-o", "out.h5", "--root", "100", "240", "--length", "200"]
    args = build_parser("reconstruct").parse_args(base + argv)
    with pytest.raises(ConfigError) as info:
        setup_from_arguments(TrackingConfig(), args, path=None)
    assert str(info.value).startswith(words)


def test_a_yaml_value_is_named_by_its_key(tmp_path) -> None:
    from flagtrack.daemon.tracking.setup import load_tracking_config_file

    path = tmp_path / "rig.yaml"
    path.write_text("tracker: {root: [100, 240], length: 200, joints: 5000}\n")
    args = build_parser("reconstruct").parse_args(["reconstruct", "in.raw", "-o", "out.h5"])
    with pytest.raises(ConfigError, match=r"key 'tracker.joints': must be 1-1000 links, got 5000"):
        setup_from_arguments(load_tracking_config_file(path), args, path=str(path))


def test_the_checks_and_the_core_share_their_limits() -> None:
    from flagtrack.daemon.core import chain, tracker, windows
    from flagtrack.daemon.tracking import checks

    assert (checks.MAX_JOINTS, checks.MAX_LINK_RATIO) == (chain.MAX_JOINTS, chain.MAX_LINK_RATIO)
    assert (checks.TIME_RANGE_S, checks.MAX_ABS_TIME_S) == (windows.STEP_RANGE_S, windows.MAX_ABS_TIME_S)
    assert checks.MAX_SAMPLES == tracker.MAX_SAMPLES
