"""Where the flag's events end along the chain (:mod:`flagtrack.daemon.core.chain_reach`)."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.chain_reach import MIN_EVENTS, ChainReach, ReachProfile, along_chain

# a chain of 4 links of 25 along +x from (10, 20), then bent: the last two links go up (+y)
BENT_X = np.array([10.0, 35.0, 60.0, 60.0, 60.0])
BENT_Y = np.array([20.0, 20.0, 20.0, 45.0, 70.0])


@pytest.mark.parametrize(
    ("point", "s", "distance"),
    [
        ((10.0, 20.0), 0.0, 0.0),  # the root
        ((40.0, 23.0), 30.0, 3.0),  # beside the second link
        ((57.0, 50.0), 80.0, 3.0),  # beside the fourth link (after the bend)
        ((60.0, 90.0), 120.0, 0.0),  # 20 past the tip, along the last link prolonged
        ((0.0, 20.0), 0.0, 10.0),  # behind the root: not prolonged backwards
    ],
)
def test_a_point_is_placed_at_its_arc_length_along_the_chain(point, s, distance) -> None:
    got_s, got_d = along_chain(np.array([point[0]]), np.array([point[1]]), BENT_X, BENT_Y)
    assert got_s[0] == pytest.approx(s) and got_d[0] == pytest.approx(distance)


def _profile_of_a_flag_ending_at(fraction: float, length: float = 200.0, seed: int = 0) -> ReachProfile:
    """Events along a straight chain of ``length``, uniform up to ``fraction`` of it, a little scatter."""
    rng = np.random.default_rng(seed)
    profile = ReachProfile(length, band=12.0)
    joints_x, joints_y = np.linspace(0.0, length, 11), np.zeros(11)
    for _ in range(20):
        s = rng.uniform(0.0, fraction * length, 500)
        profile.add(s, rng.normal(0.0, 1.0, 500), joints_x, joints_y)
    return profile


@pytest.mark.parametrize("fraction", [0.8, 0.95, 1.0, 1.1, 1.3])
def test_the_reach_is_where_the_events_end(fraction: float) -> None:
    reach = _profile_of_a_flag_ending_at(fraction).reach()
    assert reach is not None and reach.updates == 20 and reach.events == 10_000
    assert reach.reach == pytest.approx(fraction * 0.995, abs=0.005)  # (uniform: 0.5 % of events lie beyond)


def test_events_far_from_the_chain_are_not_the_flags() -> None:
    profile = ReachProfile(100.0, band=5.0)
    joints_x, joints_y = np.linspace(0.0, 100.0, 6), np.zeros(6)
    s = np.linspace(0.0, 100.0, 3000)
    profile.add(np.concatenate([s, s]), np.concatenate([np.zeros(3000), np.full(3000, 30.0)]), joints_x, joints_y)
    assert profile.events == 3000


def test_too_few_events_say_nothing() -> None:
    profile = ReachProfile(100.0, band=5.0)
    profile.add(np.linspace(0.0, 100.0, MIN_EVENTS - 1), np.zeros(MIN_EVENTS - 1), np.array([0.0, 100.0]), np.zeros(2))
    assert profile.reach() is None


@pytest.mark.parametrize(("length", "band"), [(0.0, 1.0), (100.0, 0.0), (float("nan"), 1.0), (100.0, float("inf"))])
def test_a_profile_needs_a_positive_length_and_band(length: float, band: float) -> None:
    with pytest.raises(ValueError, match="length and band"):
        ReachProfile(length, band)


@pytest.mark.parametrize(
    ("reach", "words"),
    [
        (0.87, "the chain's last 13 % had no events: from this root the flag looks about 174 px long, not 200"),
        (1.09, "the flag's events reach 9 % past the chain's tip: from this root the flag looks about 218 px long"),
        (0.975, None),
        (1.025, None),
    ],
)
def test_a_chain_off_its_flags_length_by_more_than_3_percent_is_named(reach: float, words: str | None) -> None:
    misfit = ChainReach(reach, 5000, 40).misfit(200.0, "px")
    assert misfit == words if words is None else misfit is not None and misfit.startswith(words)
