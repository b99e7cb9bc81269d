"""The chain update: the paper's rule against a plain reference, arcs, refining, minimum evidence."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.daemon.core.chain import ChainParams, ChainState, joint_positions, update_chain


def reference_update(angles: np.ndarray, x: np.ndarray, y: np.ndarray, p: ChainParams) -> np.ndarray:
    """The paper's update, written plainly: root to tip, circular mean of the events in each arc."""
    angles = angles.copy()
    px, py = p.root
    for k, r in enumerate(p.lengths()):
        dx, dy = x - px, y - py
        d = np.hypot(dx, dy)
        off = np.angle(np.exp(1j * (np.arctan2(dy, dx) - angles[k])))
        inside = (d >= (1 - p.alpha) * r) & (d <= (1 + p.alpha) * r) & (np.abs(off) <= math.radians(p.angle_limit_deg))
        if inside.sum() >= p.min_events:
            angles[k] = math.atan2(np.sum(dy[inside] / d[inside]), np.sum(dx[inside] / d[inside]))
        px += r * math.cos(angles[k])
        py += r * math.sin(angles[k])
    return angles


def _line_events(
    angles: np.ndarray, p: ChainParams, n: int, rng: np.random.Generator, width: float = 0.8
) -> tuple[np.ndarray, np.ndarray]:
    """Events scattered along the polyline of a chain, rounded to pixels."""
    jx, jy = joint_positions(p.root[0], p.root[1], angles, p.lengths())
    k = rng.integers(0, len(angles), n)
    f = rng.random(n)
    x = jx[k] + f * (jx[k + 1] - jx[k]) + rng.normal(0, width, n)
    y = jy[k] + f * (jy[k + 1] - jy[k]) + rng.normal(0, width, n)
    return np.rint(x), np.rint(y)


@pytest.mark.parametrize("seed", range(6))
def test_paper_rule_matches_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    p = ChainParams(root=(50.0, 300.0), length=200.0, angle_limit_deg=float(rng.choice([30, 60, 90])))
    old = np.full(10, 0.3) + np.cumsum(rng.normal(0, 0.03, 10))
    new = old + np.cumsum(rng.normal(0, 0.05, 10))  # the flag moved
    x, y = _line_events(new, p, 1500, rng)
    noise = rng.uniform([0, 200], [300, 500], (30, 2))
    x, y = np.concatenate([x, noise[:, 0]]), np.concatenate([y, noise[:, 1]])
    state, counts = update_chain(ChainState(old), x, y, p)
    np.testing.assert_allclose(state.angles_rad, reference_update(old, x, y, p), atol=2e-5)
    assert counts.sum() > 1500  # events are in about two areas each (alpha = 0.6)


def test_the_update_follows_the_flag() -> None:
    rng = np.random.default_rng(1)
    p = ChainParams(root=(0.0, 0.0), length=200.0)
    truth = np.cumsum(np.full(10, 0.04))
    x, y = _line_events(truth, p, 3000, rng, width=0.3)
    state, _ = update_chain(ChainState.straight(10, 0.0), x, y, p)
    assert np.max(np.abs(state.angles_rad - truth)) < 0.03


def test_a_link_without_events_keeps_its_angle() -> None:
    p = ChainParams(root=(0.0, 0.0), length=100.0, n_joints=5)
    old = np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    # events only around the first link's joint
    x, y = np.array([20 * math.cos(0.15)] * 3), np.array([20 * math.sin(0.15)] * 3)
    state, counts = update_chain(ChainState(old), x, y, p)
    assert counts[0] == 3 and state.angles_rad[0] == pytest.approx(0.15, abs=1e-6)
    np.testing.assert_array_equal(state.angles_rad[2:], old[2:])


def test_events_of_the_links_behind_are_not_taken() -> None:
    p = ChainParams(root=(0.0, 0.0), length=40.0, n_joints=2, angle_limit_deg=60.0)
    old = np.array([0.0, 0.0])
    # events on the first link, between 8 and 12 from the root: within radius of link 2's area
    # around joint 1 (20, 0), but behind it
    x, y = np.array([8.0, 9.0, 10.0, 11.0, 12.0]), np.zeros(5)
    state, counts = update_chain(ChainState(old), x, y, p)
    assert counts[1] == 0 and state.angles_rad[1] == 0.0
    wide = ChainParams(root=(0.0, 0.0), length=40.0, n_joints=2, angle_limit_deg=180.0)
    state, counts = update_chain(ChainState(old), x, y, wide)
    assert counts[1] == 5 and abs(state.angles_rad[1]) == pytest.approx(math.pi)  # the chain folds back


def test_circular_mean_across_the_branch_cut() -> None:
    p = ChainParams(root=(100.0, 100.0), length=20.0, n_joints=1)
    a = np.radians([178.0, -178.0, 179.0, -179.0])
    x, y = 100 + 20 * np.cos(a), 100 + 20 * np.sin(a)
    state, _ = update_chain(ChainState(np.array([math.pi])), x, y, p)
    assert abs(abs(state.angles_rad[0]) - math.pi) < 1e-5


def test_refining_ignores_a_stray_event_the_paper_rule_takes() -> None:
    rng = np.random.default_rng(2)
    base = dict(root=(0.0, 0.0), length=100.0, n_joints=5, angle_limit_deg=60.0)
    paper = ChainParams(**base)
    robust = ChainParams(**base, min_events=3, refine_deg=10.0)
    angles = np.zeros(5)
    x, y = _line_events(angles, paper, 12, rng, width=0.2)  # few real events, as near a still root
    stray = (20 * math.cos(0.8), 20 * math.sin(0.8))  # 46 degrees off, in link 1's arc
    x, y = np.append(x, stray[0]), np.append(y, stray[1])
    paper_state, _ = update_chain(ChainState(angles), x, y, paper)
    robust_state, _ = update_chain(ChainState(angles), x, y, robust)
    assert abs(robust_state.angles_rad[0]) < 0.01
    assert abs(paper_state.angles_rad[0]) > 0.05


def test_minimum_evidence() -> None:
    p = ChainParams(root=(0.0, 0.0), length=20.0, n_joints=1, min_events=3, refine_deg=10.0)
    x, y = np.array([20 * math.cos(0.2)] * 2), np.array([20 * math.sin(0.2)] * 2)
    assert update_chain(ChainState(np.zeros(1)), x, y, p)[0].angles_rad[0] == 0.0
    x, y = np.append(x, x[0]), np.append(y, y[0])
    assert update_chain(ChainState(np.zeros(1)), x, y, p)[0].angles_rad[0] == pytest.approx(0.2, abs=1e-6)


def test_given_link_lengths() -> None:
    p = ChainParams(root=(0.0, 0.0), length=60.0, n_joints=3, link_lengths=(10.0, 20.0, 30.0))
    jx, jy = ChainState.at_rest(p).joints(p)
    np.testing.assert_allclose(jx, [0, 10, 30, 60])
    np.testing.assert_allclose(jy, 0.0, atol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"alpha": 1.2}, "alpha"),
        ({"n_joints": 0}, "n_joints"),
        ({"angle_limit_deg": 0.0}, "angle_limit_deg"),
        ({"min_events": 0}, "min_events"),
        ({"link_lengths": (1.0, 2.0)}, "link_lengths"),
        ({"length": -1.0}, "length"),
        ({"refine_deg": 200.0}, "refine_deg"),
    ],
)
def test_params_are_checked(kwargs: dict, words: str) -> None:
    with pytest.raises(ValueError, match=words):
        ChainParams(**{"root": (0.0, 0.0), "length": 10.0, **kwargs})


@pytest.mark.parametrize("seed", range(3))
def test_area_distance_to_root_bounds_hold(seed: int) -> None:
    from flagtrack.daemon.core.kernels import sector_rho_range

    rng = np.random.default_rng(seed)
    for _ in range(200):
        px, py, theta = *rng.uniform(-30, 30, 2), rng.uniform(-np.pi, np.pi)
        r_in, r_out = sorted(rng.uniform(0.5, 25, 2))
        half = rng.choice([0.3, 1.0, np.pi / 2, 2.5, np.pi])
        lo, hi = sector_rho_range(px, py, np.cos(theta), np.sin(theta), r_in, r_out, half, 0.0, 0.0)
        rho = rng.uniform(r_in, r_out, 4000)
        phi = theta + rng.uniform(-half, half, 4000)
        dist = np.hypot(px + rho * np.cos(phi), py + rho * np.sin(phi))
        assert lo - 1e-9 <= dist.min() and dist.max() <= hi + 1e-9
        assert dist.min() - lo < 0.05 * r_out + 0.5  # and the bound is tight
