"""A batch of reconstructed (or true) centrelines: what the tracker outputs and files store."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CentrelineBatch:
    """``n_t`` centreline updates sampled at ``n_s`` arc-length positions.

    Attributes:
        t_s: (n_t,) float64, centre of each update window, seconds on the recording's clock.
        s: (n_s,) float64, arc length of the samples, in the events' length unit.
        x: (n_t, n_s) float64 smoothed centreline x.
        y: (n_t, n_s) float64 smoothed centreline y.
        joints_x: (n_t, n_joints + 1) float64 chain joints x, root first.
        joints_y: (n_t, n_joints + 1) float64 chain joints y, root first.
        delta_rms: (n_t,) float64 RMS distance of the window's events to the centreline (NaN if none).
        n_events: (n_t,) int64 events used by each update.
        lost: (n_t,) uint8, 1 where the flag was not found in the update (its shape is not to be
            trusted); ``None`` when constructed: zeros (a tracker without loss detection).
        stale: (n_t,) uint8, 1 where the shape rests on no recent evidence (it was not measured, only
            remembered); ``None`` when constructed: zeros.
        shed: (n_t,) float32 in [0, 1], the fraction of the camera's data since the previous update
            that a live tracker shed to keep within its latency budget (not looked at); ``None``
            when constructed: zeros (everything used, as offline).
    """

    t_s: np.ndarray
    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    joints_x: np.ndarray
    joints_y: np.ndarray
    delta_rms: np.ndarray
    n_events: np.ndarray
    lost: np.ndarray = None  # type: ignore[assignment]  # None: zeros, set in __post_init__
    stale: np.ndarray = None  # type: ignore[assignment]  # None: zeros, set in __post_init__
    shed: np.ndarray = None  # type: ignore[assignment]  # None: zeros, set in __post_init__

    def __post_init__(self) -> None:
        n_t, n_s = len(self.t_s), len(self.s)
        for name in ("lost", "stale"):
            value = getattr(self, name)
            flags = np.zeros(n_t, dtype=np.uint8) if value is None else np.asarray(value, dtype=np.uint8)
            object.__setattr__(self, name, flags)
        shed: np.ndarray | None = self.shed
        object.__setattr__(self, "shed", np.zeros(n_t, np.float32) if shed is None else np.asarray(shed, np.float32))
        checks: tuple[tuple[str, tuple[int, ...]], ...] = (
            ("x", (n_t, n_s)),
            ("y", (n_t, n_s)),
            ("delta_rms", (n_t,)),
            ("n_events", (n_t,)),
            ("lost", (n_t,)),
            ("stale", (n_t,)),
            ("shed", (n_t,)),
        )
        for name, want in checks:
            got = getattr(self, name).shape
            if got != want:
                raise ValueError(f"CentrelineBatch.{name} has shape {got}, expected {want}")
        if self.joints_x.shape != self.joints_y.shape or self.joints_x.shape[:1] != (n_t,):
            raise ValueError(f"CentrelineBatch joints shapes {self.joints_x.shape}/{self.joints_y.shape} mismatch")

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def tip_x(self) -> np.ndarray:
        """(n_t,) x of the tip (last sample of the smoothed centreline)."""
        return self.x[:, -1]

    @property
    def tip_y(self) -> np.ndarray:
        """(n_t,) y of the tip (last sample of the smoothed centreline)."""
        return self.y[:, -1]

    def select(self, index: slice | np.ndarray) -> CentrelineBatch:
        """Return the updates picked by ``index`` (a slice or boolean/integer array)."""
        return CentrelineBatch(
            t_s=self.t_s[index],
            s=self.s,
            x=self.x[index],
            y=self.y[index],
            joints_x=self.joints_x[index],
            joints_y=self.joints_y[index],
            delta_rms=self.delta_rms[index],
            n_events=self.n_events[index],
            lost=self.lost[index],
            stale=self.stale[index],
            shed=self.shed[index],
        )

    @staticmethod
    def concatenate(batches: list[CentrelineBatch]) -> CentrelineBatch:
        """Join batches sharing the same ``s`` in time order."""
        if not batches:
            raise ValueError("no batches to concatenate")
        first = batches[0]
        return CentrelineBatch(
            t_s=np.concatenate([b.t_s for b in batches]),
            s=first.s,
            x=np.concatenate([b.x for b in batches]),
            y=np.concatenate([b.y for b in batches]),
            joints_x=np.concatenate([b.joints_x for b in batches]),
            joints_y=np.concatenate([b.joints_y for b in batches]),
            delta_rms=np.concatenate([b.delta_rms for b in batches]),
            n_events=np.concatenate([b.n_events for b in batches]),
            lost=np.concatenate([b.lost for b in batches]),
            stale=np.concatenate([b.stale for b in batches]),
            shed=np.concatenate([b.shed for b in batches]),
        )
