"""Flag kinematics of the paper's benchmark: a travelling plus a standing wave under a growing envelope.

The wave is put on the tangent angle and integrated along the arc length, so the flag is
inextensible by construction (|d(x, y)/ds| = 1 at every s and t)::

    theta(s, t) = dir + a * env(s) * [w_t sin(k s - phi) + w_s sin(k s) cos(phi)],  phi = 2 pi f t + phi0
    env(s) = e0 + (1 - e0) (s / L)^q,     k = 2 pi / lambda

``sample_kinematics(seed)`` draws one member of the family whose peak-to-peak tip amplitude 2A/L
spans 0.085-1.05 and wavelength lambda/L spans 1.5-3.0 (Raynaud & Mulleners 2024, section 3).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from flagtrack.daemon.core.jit import njit

_N_FINE = 256  # Simpson intervals along the flag; position error ~1e-9 L


@dataclass(frozen=True)
class FlagKinematics:
    """One flapping kinematics; lengths in the caller's unit (px for a plain camera, m for a tilted one).

    Attributes:
        length: flag length L.
        root: (x, y) of the clamped root.
        direction_deg: rest direction of the flag (angle of the chord at rest), degrees.
        frequency_hz: flapping frequency f.
        wavelength_over_l: lambda / L of both waves.
        amp_rad: scale a of the tangent-angle wave, radians.
        w_travel: weight w_t of the travelling wave.
        w_standing: weight w_s of the standing wave.
        envelope_root: e0, envelope value at the root (1 at the tip).
        envelope_power: q, shape of the envelope growth.
        phase0_rad: phase phi0 at t = 0.
    """

    length: float = 300.0
    root: tuple[float, float] = (150.0, 240.0)
    direction_deg: float = 0.0
    frequency_hz: float = 15.0
    wavelength_over_l: float = 2.0
    amp_rad: float = 0.5
    w_travel: float = 0.7
    w_standing: float = 0.3
    envelope_root: float = 0.2
    envelope_power: float = 1.5
    phase0_rad: float = 0.0

    def angles_at_phase(self, phase_rad: np.ndarray, s: np.ndarray, amp_scale: float = 1.0) -> np.ndarray:
        """Tangent angle theta, radians, shape (len(phase_rad), len(s)), for flapping phases phi."""
        phi = np.asarray(phase_rad, dtype=np.float64).reshape(-1, 1)
        s_row = np.asarray(s, dtype=np.float64).reshape(1, -1)
        k_s = 2.0 * np.pi * s_row / (self.wavelength_over_l * self.length)
        env = (
            self.envelope_root
            + (1.0 - self.envelope_root) * np.clip(s_row / self.length, 0.0, None) ** self.envelope_power
        )
        wave = self.w_travel * np.sin(k_s - phi) + self.w_standing * np.sin(k_s) * np.cos(phi)
        return np.deg2rad(self.direction_deg) + amp_scale * self.amp_rad * env * wave

    def phase(self, t_s: np.ndarray) -> np.ndarray:
        """Flapping phase phi = 2 pi f t + phi0, radians."""
        return 2.0 * np.pi * self.frequency_hz * np.asarray(t_s, dtype=np.float64) + self.phase0_rad

    def positions(self, t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x, y of shape (len(t_s), len(s)) at arc lengths ``s`` (0 <= s <= L) and times ``t_s`` (s)."""
        return self.positions_at_phase(self.phase(np.atleast_1d(t_s)), s)

    def positions_at_phase(
        self, phase_rad: np.ndarray, s: np.ndarray, amp_scale: float = 1.0, n_fine: int = _N_FINE
    ) -> tuple[np.ndarray, np.ndarray]:
        """x, y of shape (len(phase_rad), len(s)) for given phases (for a twin whose phase is integrated).

        ``n_fine`` Simpson intervals are integrated; positions in between use cubic Hermite
        interpolation with the exact tangent (error ~ (L / n_fine)^4 curvature^3).
        """
        s = np.ascontiguousarray(s, dtype=np.float64)
        phi = np.ascontiguousarray(np.atleast_1d(np.asarray(phase_rad, dtype=np.float64)))
        x = np.empty((len(phi), len(s)))
        y = np.empty((len(phi), len(s)))
        _positions_kernel(
            phi,
            s,
            n_fine,
            self.length,
            math.radians(self.direction_deg),
            amp_scale * self.amp_rad,
            2.0 * math.pi / (self.wavelength_over_l * self.length),
            self.w_travel,
            self.w_standing,
            self.envelope_root,
            self.envelope_power,
            x,
            y,
        )
        return self.root[0] + x, self.root[1] + y

    def lateral(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Displacement perpendicular to the rest direction, same shape as ``x``."""
        d = np.deg2rad(self.direction_deg)
        return -(x - self.root[0]) * np.sin(d) + (y - self.root[1]) * np.cos(d)

    def peak_to_peak_over_l(self, n_phase: int = 256, amp_scale: float = 1.0, n_fine: int = _N_FINE) -> float:
        """Peak-to-peak tip lateral amplitude 2A/L over one period (periodic, so phases suffice)."""
        phi = np.linspace(0.0, 2.0 * np.pi, n_phase, endpoint=False)
        x, y = self.positions_at_phase(phi, np.array([self.length]), amp_scale, n_fine)
        tip = self.lateral(x[:, 0], y[:, 0])
        return float((tip.max() - tip.min()) / self.length)

    def max_speed(self, n_phase: int = 256, n_s: int = 65) -> float:
        """Largest speed of any point of the flag, length unit per second."""
        phi = np.linspace(0.0, 2.0 * np.pi, n_phase + 1)
        x, y = self.positions_at_phase(phi, np.linspace(0.0, self.length, n_s))
        dt = 1.0 / (self.frequency_hz * n_phase)
        return float(np.max(np.hypot(np.diff(x, axis=0), np.diff(y, axis=0))) / dt)

    def to_attrs(self) -> dict[str, Any]:
        """Parameters as a flat mapping (for file attributes and JSON)."""
        values = asdict(self)
        values["root"] = list(self.root)
        return values

    @staticmethod
    def from_attrs(values: dict[str, Any]) -> FlagKinematics:
        """Inverse of :meth:`to_attrs` (unknown keys ignored)."""
        names = set(FlagKinematics.__dataclass_fields__)
        kept = {k: v for k, v in values.items() if k in names}
        if "root" in kept:
            kept["root"] = tuple(float(v) for v in kept["root"])
        return FlagKinematics(**kept)


@dataclass(frozen=True)
class KinematicsFamily:
    """Ranges the benchmark family is drawn from (uniform in each range).

    2A/L is drawn first, then ``amp_rad`` is solved so that the kinematics has exactly that amplitude.
    """

    peak_to_peak_over_l: tuple[float, float] = (0.085, 1.05)
    wavelength_over_l: tuple[float, float] = (1.5, 3.0)
    frequency_hz: tuple[float, float] = (8.0, 25.0)
    w_travel: tuple[float, float] = (0.0, 1.0)
    envelope_root: tuple[float, float] = (0.1, 0.4)
    envelope_power: tuple[float, float] = (1.0, 2.0)
    max_amp_rad: float = 1.3


def _peak_to_peak_curve(kin: FlagKinematics, n_phase: int = 128, n_fine: int = 64):
    """Return f(amps) -> 2A/L for an array of ``amp_rad`` values (tip only, Simpson, vectorised)."""
    phi = np.linspace(0.0, 2.0 * np.pi, n_phase, endpoint=False)
    s = np.linspace(0.0, kin.length, 2 * n_fine + 1)
    unit = replace(kin, amp_rad=1.0, direction_deg=0.0)
    base = unit.angles_at_phase(phi, s)  # (n_phase, 2 n_fine + 1), linear in amp_rad
    weights = np.ones(len(s))
    weights[1:-1:2], weights[2:-1:2] = 4.0, 2.0
    weights *= (s[1] - s[0]) / 3.0

    def curve(amps: np.ndarray) -> np.ndarray:
        tip = np.sin(np.asarray(amps, dtype=np.float64).reshape(-1, 1, 1) * base) @ weights  # lateral, rest frame
        return (tip.max(axis=1) - tip.min(axis=1)) / kin.length

    return curve


def with_peak_to_peak(kin: FlagKinematics, target_over_l: float, max_amp_rad: float = 1.3) -> FlagKinematics | None:
    """Return ``kin`` with ``amp_rad`` solved so that 2A/L equals ``target_over_l`` (None if unreachable).

    The smallest solution is taken: a coarse scan brackets the first crossing, then Brent's method
    refines it on 128 phases per period (2A/L accurate to ~3e-4 relative).
    """
    coarse, fine = _peak_to_peak_curve(kin, n_phase=32), _peak_to_peak_curve(kin, n_phase=128)
    grid = np.linspace(0.0, max_amp_rad, 14)
    above = np.flatnonzero(coarse(grid) >= target_over_l)
    i = int(above[0]) if len(above) else len(grid) - 1
    i = max(i, 1)
    values = fine(grid)
    while i > 1 and values[i - 1] >= target_over_l:
        i -= 1
    while i < len(grid) - 1 and values[i] < target_over_l:
        i += 1
    if not values[i - 1] < target_over_l <= values[i]:
        return None
    from scipy.optimize import brentq  # (here: SciPy's import is ~0.35 s of every service's start)

    solved = brentq(lambda amp: float(fine(np.array([amp]))[0]) - target_over_l, grid[i - 1], grid[i], xtol=1e-10)
    return replace(kin, amp_rad=float(solved))


def sample_kinematics(
    seed: int,
    family: KinematicsFamily = KinematicsFamily(),
    length: float = 300.0,
    root: tuple[float, float] = (150.0, 240.0),
    direction_deg: float = 0.0,
) -> FlagKinematics:
    """Draw one kinematics of ``family`` from ``seed`` (deterministic)."""
    rng = np.random.default_rng(seed)
    for _ in range(100):
        w_travel = float(rng.uniform(*family.w_travel))
        base = FlagKinematics(
            length=length,
            root=root,
            direction_deg=direction_deg,
            frequency_hz=float(rng.uniform(*family.frequency_hz)),
            wavelength_over_l=float(rng.uniform(*family.wavelength_over_l)),
            w_travel=w_travel,
            w_standing=1.0 - w_travel,
            envelope_root=float(rng.uniform(*family.envelope_root)),
            envelope_power=float(rng.uniform(*family.envelope_power)),
            phase0_rad=float(rng.uniform(0.0, 2.0 * math.pi)),
        )
        lo, hi = family.peak_to_peak_over_l
        target = float(rng.uniform(lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo)))
        solved = with_peak_to_peak(base, target, family.max_amp_rad)
        if solved is not None:
            return solved
    raise ValueError(f"seed {seed}: no kinematics of the family reached the drawn amplitude in 100 draws")


@njit(cache=True, nogil=True)
def _positions_kernel(
    phi,
    s,
    n_fine,
    length,
    direction,
    amp,
    k,
    w_travel,
    w_standing,
    env_root,
    env_power,
    out_x,
    out_y,
):
    """x, y (relative to the root) of :meth:`FlagKinematics.positions_at_phase`, one phase per row.

    The tangent angle at ``2 n_fine + 1`` points (nodes and mid-points), Simpson per interval for
    the node positions, cubic Hermite with the exact tangent in between.
    """
    h = length / n_fine
    n_pts = 2 * n_fine + 1  # node i at 2 i, mid-point of interval i at 2 i + 1
    env_sin, env_cos = np.empty(n_pts), np.empty(n_pts)  # phase-independent parts of the wave
    for m in range(n_pts):
        sm = 0.5 * h * m
        env = env_root + (1.0 - env_root) * (sm / length) ** env_power
        env_sin[m], env_cos[m] = env * np.sin(k * sm), env * np.cos(k * sm)
    cos_t, sin_t = np.empty(n_pts), np.empty(n_pts)
    xn, yn = np.empty(n_fine + 1), np.empty(n_fine + 1)
    for r in range(len(phi)):
        cos_phi, sin_phi = np.cos(phi[r]), np.sin(phi[r])
        for m in range(n_pts):
            # sin(ks - phi) = sin ks cos phi - cos ks sin phi
            wave = w_travel * (env_sin[m] * cos_phi - env_cos[m] * sin_phi) + w_standing * env_sin[m] * cos_phi
            theta = direction + amp * wave
            cos_t[m], sin_t[m] = np.cos(theta), np.sin(theta)
        xn[0] = yn[0] = 0.0
        for i in range(n_fine):
            xn[i + 1] = xn[i] + h / 6.0 * (cos_t[2 * i] + 4.0 * cos_t[2 * i + 1] + cos_t[2 * i + 2])
            yn[i + 1] = yn[i] + h / 6.0 * (sin_t[2 * i] + 4.0 * sin_t[2 * i + 1] + sin_t[2 * i + 2])
        for j in range(len(s)):
            i0 = min(max(int(np.floor(s[j] / h)), 0), n_fine - 1)
            u = min(max(s[j] / h - i0, 0.0), 1.0)
            h00, h10 = 2 * u**3 - 3 * u**2 + 1, (u**3 - 2 * u**2 + u) * h
            h01, h11 = -2 * u**3 + 3 * u**2, (u**3 - u**2) * h
            a, b = 2 * i0, 2 * i0 + 2
            out_x[r, j] = h00 * xn[i0] + h10 * cos_t[a] + h01 * xn[i0 + 1] + h11 * cos_t[b]
            out_y[r, j] = h00 * yn[i0] + h10 * sin_t[a] + h01 * yn[i0 + 1] + h11 * sin_t[b]
