"""The chain of the paper (Raynaud & Mulleners 2024, section 2): state and one update.

The centreline is a chain of ``N_j`` links from a fixed root. Link ``k`` goes from joint ``k-1`` to
joint ``k``; its length ``r_k`` is fixed and its direction ``theta_k`` (absolute, radians from +x
towards +y) is the state. One update takes the events of a window and, from the root to the tip,
replaces ``theta_k`` by the circular mean of the directions, seen from the (already updated) joint
``k-1``, of the events in the link's search area: an arc of radii ``(1-alpha) r_k .. (1+alpha) r_k``
around joint ``k-1`` and of half-angle ``angle_limit`` around the link's previous direction (so the
events of the links behind are not taken). A link whose area holds fewer than ``min_events`` events
keeps its direction (the paper's rule is ``min_events = 1``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flagtrack.daemon.core.kernels import LANES, bucket_sort, update_sorted

MAX_JOINTS = 1000
"""Most links of a chain (each link costs every update a pass over its area)."""
MAX_LINK_RATIO = 1000.0
"""Longest link over shortest (the update sorts events in buckets of a quarter of the shortest)."""


@dataclass(frozen=True)
class ChainParams:
    """Geometry and search areas of the chain.

    Attributes:
        root: (x, y) of the fixed root, in the events' length unit.
        length: flag length L, same unit.
        n_joints: number of links N_j (joints excluding the root).
        direction_deg: rest direction of the flag, degrees from +x towards +y (the initial chain).
        link_lengths: N_j link lengths summing to ``length``; ``None``: equal, ``length / n_joints``.
        alpha: search radius parameter, the area of link k spans radii (1 +- alpha) r_k, 0 < alpha < 1.
        angle_limit_deg: half-angle of each search arc around the link's previous direction, degrees.
        min_events: fewest events in an area that update its link (the paper: 1).
        refine_deg: if set, the mean of the area's events is only a pilot: the link takes the circular
            mean of the area's events within this many degrees of it (robust to stray events);
            ``None``: the paper's single mean.
    """

    root: tuple[float, float]
    length: float
    n_joints: int = 10
    direction_deg: float = 0.0
    link_lengths: tuple[float, ...] | None = None
    alpha: float = 0.6
    angle_limit_deg: float = 60.0
    min_events: int = 1
    refine_deg: float | None = None

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in self.root):
            raise ValueError(f"root must be two finite numbers, got {self.root}")
        if not (self.length > 0 and math.isfinite(self.length)):
            raise ValueError(f"length must be positive, got {self.length}")
        if not math.isfinite(self.direction_deg):
            raise ValueError(f"direction_deg must be finite, got {self.direction_deg}")
        if not 1 <= self.n_joints <= MAX_JOINTS:
            raise ValueError(f"n_joints must be 1-{MAX_JOINTS}, got {self.n_joints}")
        if not 0 < self.alpha < 1:
            raise ValueError(f"alpha must be between 0 and 1, got {self.alpha}")
        if not 0 < self.angle_limit_deg <= 180:
            raise ValueError(f"angle_limit_deg must be in (0, 180], got {self.angle_limit_deg}")
        if self.refine_deg is not None and not 0 < self.refine_deg <= 180:
            raise ValueError(f"refine_deg must be in (0, 180], got {self.refine_deg}")
        if self.min_events < 1:
            raise ValueError(f"min_events must be at least 1, got {self.min_events}")
        if self.link_lengths is not None:
            if len(self.link_lengths) != self.n_joints:
                raise ValueError(f"link_lengths has {len(self.link_lengths)} values for {self.n_joints} joints")
            if min(self.link_lengths) <= 0 or abs(sum(self.link_lengths) - self.length) > 1e-9 * self.length:
                raise ValueError(f"link_lengths must be positive and sum to length {self.length}")
            if max(self.link_lengths) > MAX_LINK_RATIO * min(self.link_lengths):
                raise ValueError(f"link_lengths: the longest may be at most {MAX_LINK_RATIO:g} times the shortest")

    def lengths(self) -> np.ndarray:
        """(N_j,) float64 link lengths r_k."""
        if self.link_lengths is None:
            return np.full(self.n_joints, self.length / self.n_joints)
        return np.asarray(self.link_lengths, dtype=np.float64)


@dataclass(frozen=True)
class ChainState:
    """The tracked state: the absolute direction of every link, radians, shape (N_j,)."""

    angles_rad: np.ndarray

    @staticmethod
    def straight(n_joints: int, direction_deg: float) -> ChainState:
        """A straight chain pointing ``direction_deg`` (degrees from +x towards +y)."""
        return ChainState(np.full(n_joints, math.radians(direction_deg)))

    @staticmethod
    def at_rest(params: ChainParams) -> ChainState:
        """The straight chain along the rest direction of ``params``."""
        return ChainState.straight(params.n_joints, params.direction_deg)

    def joints(self, params: ChainParams) -> tuple[np.ndarray, np.ndarray]:
        """(N_j + 1,) x and y of the joints, root first."""
        return joint_positions(params.root[0], params.root[1], self.angles_rad, params.lengths())


def joint_positions(
    root_x: float, root_y: float, angles: np.ndarray, lengths: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(N_j + 1,) joint x, y of a chain from its root, link directions and lengths."""
    x = np.concatenate([[root_x], root_x + np.cumsum(lengths * np.cos(angles))])
    y = np.concatenate([[root_y], root_y + np.cumsum(lengths * np.sin(angles))])
    return x, y


@dataclass(frozen=True)
class AreaGeometry:
    """Numbers the compiled update needs, derived once from :class:`ChainParams`."""

    lengths: np.ndarray
    r2_min: np.ndarray
    r2_max: np.ndarray
    cos_limit_signed_sq: float
    cos_refine_signed_sq: float
    half_angle_rad: float
    bucket_width: float
    n_buckets: int

    @staticmethod
    def of(params: ChainParams) -> AreaGeometry:
        lengths = params.lengths()
        cos_limit = math.cos(math.radians(params.angle_limit_deg))
        cos_refine = math.cos(math.radians(params.refine_deg)) if params.refine_deg is not None else 2.0
        return AreaGeometry(
            lengths=lengths,
            r2_min=((1 - params.alpha) * lengths) ** 2,
            r2_max=((1 + params.alpha) * lengths) ** 2,
            cos_limit_signed_sq=cos_limit * abs(cos_limit),
            cos_refine_signed_sq=cos_refine * abs(cos_refine),
            half_angle_rad=math.radians(params.angle_limit_deg),
            bucket_width=float(lengths.min()) / 4,
            n_buckets=int(math.ceil((params.length + 2 * (1 + params.alpha) * lengths.max()) / (lengths.min() / 4)))
            + 1,
        )


def update_chain(state: ChainState, x: np.ndarray, y: np.ndarray, params: ChainParams) -> tuple[ChainState, np.ndarray]:
    """Return the chain after one update from the events (x, y) of one window; inputs untouched.

    Coordinates are taken in single precision, as the tracker does.

    Returns:
        The new state and the (N_j,) number of events in each link's (final) arc.
    """
    geo = AreaGeometry.of(params)
    xs = np.ascontiguousarray(x, dtype=np.float32)
    ys = np.ascontiguousarray(y, dtype=np.float32)
    n = len(xs)
    angles = np.array(state.angles_rad, dtype=np.float64)
    sorted_x, sorted_y = np.empty(n + LANES, dtype=np.float32), np.empty(n + LANES, dtype=np.float32)
    offsets = np.empty(geo.n_buckets + 1, dtype=np.int64)
    root_x, root_y = float(params.root[0]), float(params.root[1])
    bucket_sort(
        xs, ys, 0, n, root_x, root_y, 1.0 / geo.bucket_width, sorted_x, sorted_y, np.empty(n, dtype=np.int32), offsets
    )
    jx, jy = np.empty(params.n_joints + 1), np.empty(params.n_joints + 1)
    counts = np.zeros(params.n_joints, dtype=np.int64)
    update_sorted(
        sorted_x,
        sorted_y,
        offsets,
        1.0 / geo.bucket_width,
        root_x,
        root_y,
        angles,
        geo.lengths,
        np.sqrt(geo.r2_max),
        geo.r2_min,
        geo.r2_max,
        geo.cos_limit_signed_sq,
        geo.cos_refine_signed_sq,
        geo.half_angle_rad,
        params.min_events,
        np.empty((params.n_joints, 6)),
        jx,
        jy,
        counts,
    )
    return ChainState(angles), counts
