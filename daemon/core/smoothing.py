"""Smoothing of the chain (paper, section 2): modified Akima through the joints, exact length.

The joints are interpolated by a modified Akima ("makima", as MATLAB's ``makima`` and scipy's
``Akima1DInterpolator(method="makima")``) piecewise cubic Hermite curve ``x(u), y(u)`` whose knots
``u_k`` are the cumulative link lengths. The curve is sampled at ``n_s`` points evenly spaced in
``u`` (``ds = U / (n_s - 1)``); the smoothed length is the length of the polyline through these
samples. The interpolation makes the curve longer than the chain, so the tip link is shortened (its
direction kept) by a safeguarded secant search, vectorised over the updates by compiled loops, until
that length equals ``L`` within ``rel_tol * L``. The samples sit at ``s = u``, i.e. at arc lengths
exact to O((kappa r)^2) relative (the curve's speed in ``u`` is one up to that order).
"""

from __future__ import annotations

import math

import numpy as np

from flagtrack.daemon.core.jit import njit

REL_TOL = 1e-9
"""Default tolerance of the length correction, relative to L (the issue asks 1e-6)."""


def n_samples(length: float, ds: float) -> int:
    """Samples of the smoothed centreline for a step ``ds``: ``ceil(L / ds) + 1`` (at least 2)."""
    if not ds > 0:
        raise ValueError(f"ds must be positive, got {ds}")
    return max(2, int(math.ceil(length / ds - 1e-9)) + 1)


@njit(cache=True, nogil=True, error_model="numpy")
def makima_slopes(u: np.ndarray, v: np.ndarray, slopes: np.ndarray, m: np.ndarray) -> None:
    """Write the makima derivatives dv/du at the knots u (n,) into ``slopes`` (n,); n >= 2.

    ``m`` is a scratch array of at least n + 3 values.
    """
    n = len(u)
    if n == 2:
        slope = (v[1] - v[0]) / (u[1] - u[0])
        slopes[0] = slope
        slopes[1] = slope
        return
    for i in range(n - 1):
        m[i + 2] = (v[i + 1] - v[i]) / (u[i + 1] - u[i])
    m[1] = 2.0 * m[2] - m[3]
    m[0] = 2.0 * m[1] - m[2]
    m[n + 1] = 2.0 * m[n] - m[n - 1]
    m[n + 2] = 2.0 * m[n + 1] - m[n]
    for i in range(n):
        f1 = abs(m[i + 3] - m[i + 2]) + 0.5 * abs(m[i + 3] + m[i + 2])
        f2 = abs(m[i + 1] - m[i]) + 0.5 * abs(m[i + 1] + m[i])
        f12 = f1 + f2
        if f12 > 0.0:
            slopes[i] = m[i + 1] + (f2 / f12) * (m[i + 2] - m[i + 1])
        else:
            slopes[i] = 0.5 * (m[i + 3] + m[i])


@njit(cache=True, nogil=True, error_model="numpy")
def hermite_eval(u: np.ndarray, v: np.ndarray, slopes: np.ndarray, uq: np.ndarray, out: np.ndarray) -> None:
    """Evaluate the cubic Hermite curve (knots u, values v, derivatives slopes) at sorted ``uq``."""
    j = 0
    last = len(u) - 2
    for q in range(len(uq)):
        while j < last and uq[q] > u[j + 1]:
            j += 1
        h = u[j + 1] - u[j]
        t = (uq[q] - u[j]) / h
        t2 = t * t
        t3 = t2 * t
        out[q] = (
            (2 * t3 - 3 * t2 + 1) * v[j]
            + (t3 - 2 * t2 + t) * h * slopes[j]
            + (-2 * t3 + 3 * t2) * v[j + 1]
            + (t3 - t2) * h * slopes[j + 1]
        )


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _sampled_length(
    u: np.ndarray, jx: np.ndarray, jy: np.ndarray, work: np.ndarray, sx: np.ndarray, sy: np.ndarray
) -> float:
    """Sample the makima curve through (jx, jy) at n_s even u into sx, sy; return the polyline length.

    ``work`` is scratch of at least 3 len(u) + 3 values.
    """
    n = len(u)
    tx = work[:n]
    ty = work[n : 2 * n]
    m = work[2 * n : 3 * n + 3]
    makima_slopes(u, jx, tx, m)
    makima_slopes(u, jy, ty, m)
    n_s = len(sx)
    step = u[n - 1] / (n_s - 1)
    q = 0
    for j in range(n - 1):
        h = u[j + 1] - u[j]
        inv_h = 1.0 / h
        ax, ay = jx[j], jy[j]
        bx, by = h * tx[j], h * ty[j]
        dx, dy = h * tx[j + 1], h * ty[j + 1]
        # power-basis coefficients of the Hermite cubic in t = (u - u_j) / h
        c2x = 3.0 * (jx[j + 1] - ax) - 2.0 * bx - dx
        c3x = 2.0 * (ax - jx[j + 1]) + bx + dx
        c2y = 3.0 * (jy[j + 1] - ay) - 2.0 * by - dy
        c3y = 2.0 * (ay - jy[j + 1]) + by + dy
        end = u[j + 1]
        while q < n_s and (q * step <= end or j == n - 2):
            t = (q * step - u[j]) * inv_h
            sx[q] = ax + t * (bx + t * (c2x + t * c3x))
            sy[q] = ay + t * (by + t * (c2y + t * c3y))
            q += 1
    sx[n_s - 1] = jx[n - 1]
    sy[n_s - 1] = jy[n - 1]
    total = 0.0
    for q in range(n_s - 1):
        ex = sx[q + 1] - sx[q]
        ey = sy[q + 1] - sy[q]
        total += math.sqrt(ex * ex + ey * ey)
    return total


@njit(cache=True, nogil=True, error_model="numpy")
def smooth_one(
    jx: np.ndarray,
    jy: np.ndarray,
    lengths: np.ndarray,
    length: float,
    rel_tol: float,
    work: np.ndarray,
    sx: np.ndarray,
    sy: np.ndarray,
) -> float:
    """Smooth one chain in place; return the tip link length that gives the exact smoothed length.

    Args:
        jx, jy: (N_j + 1,) joints (root first) of the chain with its full tip link; the tip joint
            is moved in place to the shortened tip.
        lengths: (N_j,) link lengths r_k of the chain.
        length: the flag length L.
        rel_tol: tolerance on the smoothed length, relative to L.
        work: scratch array of at least 4 (N_j + 1) + 3 values; its first N_j + 1 receive the knots u.
        sx, sy: (n_s,) receive the samples.
    """
    n = len(lengths)
    u = work[: n + 1]
    scratch = work[n + 1 :]
    u[0] = 0.0
    for k in range(n):
        u[k + 1] = u[k] + lengths[k]
    r_full = lengths[n - 1]
    dx = (jx[n] - jx[n - 1]) / r_full
    dy = (jy[n] - jy[n - 1]) / r_full
    tol = rel_tol * length

    def excess(r: float) -> float:
        u[n] = u[n - 1] + r
        jx[n] = jx[n - 1] + r * dx
        jy[n] = jy[n - 1] + r * dy
        return _sampled_length(u, jx, jy, scratch, sx, sy) - length

    # safeguarded secant on f(r) = length(r) - L; f increases with r
    r0, f0 = r_full, excess(r_full)
    if abs(f0) <= tol:
        return r0
    lo, hi = 1e-6 * r_full, 4.0 * r_full
    if f0 > 0:
        hi = r0
    else:
        lo = r0
    r1 = min(max(r0 - f0, lo), hi)
    for _ in range(60):
        f1 = excess(r1)
        if abs(f1) <= tol:
            return r1
        if f1 > 0:
            hi = r1
        else:
            lo = r1
        denom = f1 - f0
        r2 = r1 - f1 * (r1 - r0) / denom if denom != 0.0 else 0.5 * (lo + hi)
        if not (lo < r2 < hi):
            r2 = 0.5 * (lo + hi)
        r0, f0, r1 = r1, f1, r2
    excess(r1)
    return r1


@njit(cache=True, nogil=True, error_model="numpy")
def smooth_batch(
    jx: np.ndarray,
    jy: np.ndarray,
    lengths: np.ndarray,
    length: float,
    rel_tol: float,
    sx: np.ndarray,
    sy: np.ndarray,
    r_tip: np.ndarray,
) -> None:
    """Smooth K chains: jx, jy (K, N_j + 1) (tip moved in place), sx, sy (K, n_s), r_tip (K,)."""
    work = np.empty(4 * (len(lengths) + 1) + 3)
    for k in range(jx.shape[0]):
        r_tip[k] = smooth_one(jx[k], jy[k], lengths, length, rel_tol, work, sx[k], sy[k])


def smooth_chains(
    joints_x: np.ndarray, joints_y: np.ndarray, lengths: np.ndarray, length: float, n_s: int, rel_tol: float = REL_TOL
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed centrelines of K chains (pure; inputs untouched).

    Args:
        joints_x, joints_y: (K, N_j + 1) or (N_j + 1,) joints, root first, full tip link.
        lengths: (N_j,) link lengths.
        length: flag length L (the smoothed polyline length is made equal to it).
        n_s: samples per centreline (see :func:`n_samples`).
        rel_tol: tolerance on the length, relative to L.

    Returns:
        x, y (K, n_s) samples; joints_x, joints_y (K, N_j + 1) with the shortened tip joint.
    """
    jx = np.array(np.atleast_2d(joints_x), dtype=np.float64)
    jy = np.array(np.atleast_2d(joints_y), dtype=np.float64)
    sx = np.empty((jx.shape[0], n_s))
    sy = np.empty((jx.shape[0], n_s))
    r_tip = np.empty(jx.shape[0])
    smooth_batch(jx, jy, np.asarray(lengths, dtype=np.float64), float(length), rel_tol, sx, sy, r_tip)
    return sx, sy, jx, jy


def makima(u: np.ndarray, v: np.ndarray, uq: np.ndarray) -> np.ndarray:
    """Modified Akima interpolation of (u, v) at sorted ``uq`` inside [u[0], u[-1]] (1-D arrays)."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    slopes = np.empty(len(u))
    makima_slopes(u, v, slopes, np.empty(len(u) + 3))
    out = np.empty(len(uq))
    hermite_eval(u, v, slopes, np.asarray(uq, dtype=np.float64), out)
    return out
