"""How far along the chain the flag's events reach: the run's evidence for the chain's length.

A chain longer than the flag still finds the flag (its links near the tip lie on the flag's events)
and presents a tail past the tip with no event on it; a chain shorter than the flag presents the
flag cut short while its tip's events run on past the chain. Neither shows in the found, lost and
stale verdicts. Over a run, the events of sampled found updates are placed along their chain (arc
length from the root, the last link prolonged past the tip); the flag's tip moves most and fires
most, so the events end, sharply, where the flag does. :class:`ReachProfile` gathers them and
:meth:`ReachProfile.reach` says where they end, as a fraction of the chain's length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

BIN = 0.005
"""Width of the profile's bins, a fraction of the chain's length."""
TOP = 1.5
"""The profile runs from the root to this fraction of the chain's length (further events are not counted)."""
QUANTILE = 0.995
"""Where the events end: the arc length below which this share of the chain's events lie."""
MIN_EVENTS = 2000
"""Fewer events near the chain over the run than this: the reach is not judged."""
TOLERANCE = 0.03
"""The chain's length is questioned when the events end further than this fraction of it from its tip
(at the true length they end within 0.5 % of it: docs/tracking.md)."""


@dataclass(frozen=True)
class ChainReach:
    """Where the flag's events end along the chain.

    Attributes:
        reach: the arc length where the events end, a fraction of the chain's length (1: at its tip).
        events: events near the chain that the figure rests on.
        updates: found updates sampled.
    """

    reach: float
    events: int
    updates: int

    def misfit(self, length: float, units: str, tolerance: float = TOLERANCE) -> str | None:
        """One sentence when the events end further than ``tolerance`` (a fraction of the chain's
        ``length``) from the chain's tip, else None."""
        if abs(self.reach - 1.0) <= tolerance:
            return None
        seen = f"from this root the flag looks about {_figure(self.reach * length)} {units} long, not {length:g}"
        if self.reach < 1.0:
            return f"the chain's last {100 * (1 - self.reach):.0f} % had no events: {seen}"
        return f"the flag's events reach {100 * (self.reach - 1):.0f} % past the chain's tip: {seen}"


class ReachProfile:
    """Events placed along their chain, gathered over a run (a histogram of arc length / length).

    Args:
        length: the chain's length (the events' units).
        band: how far from the chain (the events' units) an event still counts as the flag's.
    """

    def __init__(self, length: float, band: float) -> None:
        if not (length > 0 and band > 0 and math.isfinite(length) and math.isfinite(band)):
            raise ValueError(f"length and band must be positive and finite, got {length}, {band}")
        self.length = float(length)
        self.band = float(band)
        self.counts = np.zeros(round(TOP / BIN), dtype=np.int64)
        self.updates = 0

    @property
    def events(self) -> int:
        """Events placed near the chain so far."""
        return int(self.counts.sum())

    def add(self, x: np.ndarray, y: np.ndarray, joints_x: np.ndarray, joints_y: np.ndarray) -> None:
        """Place the events ``(x, y)`` (n,) of one found update along its chain (joints (m,), root first)."""
        s, distance = along_chain(x, y, joints_x, joints_y)
        near = (distance <= self.band) & (s < TOP * self.length)
        bins = (s[near] * (1.0 / (BIN * self.length))).astype(np.int64)
        self.counts += np.bincount(bins, minlength=len(self.counts))[: len(self.counts)]
        self.updates += 1

    def reach(self) -> ChainReach | None:
        """Where the events end, or None when too few were gathered to say."""
        total = self.events
        if total < MIN_EVENTS:
            return None
        cumulative = np.cumsum(self.counts)
        end = int(np.searchsorted(cumulative, QUANTILE * total))  # the bin holding the quantile
        below = cumulative[end - 1] if end else 0
        inside = (QUANTILE * total - below) / max(int(self.counts[end]), 1)  # linear within the bin
        return ChainReach(round(float((end + inside) * BIN), 4), total, self.updates)


def _figure(value: float) -> str:
    """``value`` to three significant figures, without an exponent (179.7 -> 180, 1234 -> 1230)."""
    return f"{float(f'{value:.3g}'):g}"


def along_chain(
    x: np.ndarray, y: np.ndarray, joints_x: np.ndarray, joints_y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(s, distance) of each point (x, y) (n,) to the polyline of the joints (m,), root first.

    ``s`` is the arc length, from the root, of the nearest point of the polyline, whose last link
    is prolonged past the tip (a point beyond the tip gets ``s`` above the chain's length);
    ``distance`` the distance to that point. Same units as the inputs.
    """
    px, py = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    ax, ay = np.asarray(joints_x[:-1], dtype=np.float64), np.asarray(joints_y[:-1], dtype=np.float64)
    bx, by = np.asarray(joints_x[1:], dtype=np.float64), np.asarray(joints_y[1:], dtype=np.float64)
    links = np.maximum(np.hypot(bx - ax, by - ay), 1e-12)
    start = np.concatenate(([0.0], np.cumsum(links)[:-1]))
    ux, uy = (bx - ax) / links, (by - ay) / links
    dx, dy = px[:, None] - ax[None, :], py[:, None] - ay[None, :]
    along = np.clip(dx * ux + dy * uy, 0.0, None)
    along[:, :-1] = np.minimum(along[:, :-1], links[:-1])  # the last link runs on past the tip
    off = np.hypot(dx - along * ux, dy - along * uy)
    nearest = np.argmin(off, axis=1)
    rows = np.arange(len(px))
    return start[nearest] + along[rows, nearest], off[rows, nearest]
