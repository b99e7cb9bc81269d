"""Parameters of the loss-of-track detection and re-acquisition, apart from their compiled kernels
(a config can be read without importing numba)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LostParams:
    """When an update has lost the flag, and how the chain finds it again.

    An update is judged on the window's events within the chain's reach of the root (the flag's
    region): the flag is found when at least ``min_fit`` of them lie within ``band`` L of the
    smoothed centreline. A window with no event there is not lost (a still flag); one with fewer
    than ``min_events`` keeps the previous update's verdict.

    Attributes:
        min_events: fewest events in the flag's region that decide an update.
        min_fit: smallest fraction of the region's events near the centreline of a found flag.
        band: "near the centreline", as a fraction of the flag length L.
        reacquire: on a lost update, search the window again root to tip with wide areas and keep
            that chain if it fits the events better.
        cone_deg: half-angle of that search around the previous link's new direction, degrees
            (the first link searches the whole circle).
        hold_updates: after a stretch of lost updates, as many updates (at most this many) are still
            said lost (a chain just back may be on something else than the flag for a while); 0:
            off (the default: measured in docs/tracking.md, it doubles false verdicts on heavy noise).
    """

    min_events: int = 40
    min_fit: float = 0.6
    search_fit: float = 0.7
    band: float = 0.03
    reacquire: bool = True
    cone_deg: float = 90.0
    hold_updates: int = 0
    stale_after_s: float = 0.1
    gather_events: int = 100
    tip_window_s: float = 0.01

    def __post_init__(self) -> None:
        if self.min_events < 1:
            raise ValueError(f"min_events must be at least 1, got {self.min_events}")
        if not 0 < self.min_fit < 1:
            raise ValueError(f"min_fit must be in (0, 1), got {self.min_fit}")
        if not 0 < self.search_fit < 1:
            raise ValueError(f"search_fit must be in (0, 1), got {self.search_fit}")
        if not 0 < self.band <= 0.04:
            raise ValueError(f"band must be in (0, 0.04], got {self.band}")
        if self.hold_updates < 0:
            raise ValueError(f"hold_updates must be at least 0, got {self.hold_updates}")
        if not 0 < self.cone_deg <= 180:
            raise ValueError(f"cone_deg must be in (0, 180], got {self.cone_deg}")
        if not 0 < self.stale_after_s <= 3600:
            raise ValueError(f"stale_after_s must be in (0, 3600] s, got {self.stale_after_s}")
        if not 0 <= self.tip_window_s <= 3600:
            raise ValueError(f"tip_window_s must be in [0, 3600] s, got {self.tip_window_s}")
        if not 0 <= self.gather_events <= 1_000_000:
            raise ValueError(f"gather_events must be in [0, 1000000], got {self.gather_events}")
