"""Compiled evaluation of the calibration polynomials (Horner's scheme), the per-event hot path.

Coefficients come as (n, n) matrices ``a[i, j]`` of ``u^i v^j`` (zero where i + j > degree).
Degrees up to 3 and up to 5 have unrolled kernels (coefficients held in registers, so the loop
over points vectorises: several hundred million points per second); higher degrees use a generic
kernel that runs Horner's steps on blocks of points.
"""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.jit import njit

_BLOCK = 256


def evaluate(
    x: np.ndarray,
    y: np.ndarray,
    cx: float,
    cy: float,
    inv_scale: float,
    ax: np.ndarray,
    ay: np.ndarray,
    out_x: np.ndarray,
    out_y: np.ndarray,
) -> None:
    """``out = P((x - cx) inv_scale, (y - cy) inv_scale)`` for 1-D x, y; picks the kernel by ``ax``'s size."""
    if ax.shape[0] == 4:
        _evaluate3(x, y, cx, cy, inv_scale, ax, ay, out_x, out_y)
    elif ax.shape[0] == 6:
        _evaluate5(x, y, cx, cy, inv_scale, ax, ay, out_x, out_y)
    else:
        _evaluate_any(x, y, cx, cy, inv_scale, ax, ay, out_x, out_y)


@njit(cache=True)
def _evaluate3(x, y, cx, cy, inv_scale, ax, ay, out_x, out_y):  # noqa: ANN001, ANN202
    """Degree <= 3 (4 x 4 coefficient matrices), unrolled."""
    a00, a01, a02, a03, a10, a11, a12, a20, a21, a30 = (
        ax[0, 0],
        ax[0, 1],
        ax[0, 2],
        ax[0, 3],
        ax[1, 0],
        ax[1, 1],
        ax[1, 2],
        ax[2, 0],
        ax[2, 1],
        ax[3, 0],
    )
    b00, b01, b02, b03, b10, b11, b12, b20, b21, b30 = (
        ay[0, 0],
        ay[0, 1],
        ay[0, 2],
        ay[0, 3],
        ay[1, 0],
        ay[1, 1],
        ay[1, 2],
        ay[2, 0],
        ay[2, 1],
        ay[3, 0],
    )
    for k in range(x.size):
        u = (x[k] - cx) * inv_scale
        v = (y[k] - cy) * inv_scale
        px0 = a00 + v * (a01 + v * (a02 + v * a03))
        px1 = a10 + v * (a11 + v * a12)
        px2 = a20 + v * a21
        py0 = b00 + v * (b01 + v * (b02 + v * b03))
        py1 = b10 + v * (b11 + v * b12)
        py2 = b20 + v * b21
        out_x[k] = px0 + u * (px1 + u * (px2 + u * a30))
        out_y[k] = py0 + u * (py1 + u * (py2 + u * b30))


@njit(cache=True)
def _evaluate5(x, y, cx, cy, inv_scale, ax, ay, out_x, out_y):  # noqa: ANN001, ANN202
    """Degree <= 5 (6 x 6 coefficient matrices), unrolled."""
    a00, a01, a02, a03, a04, a05 = ax[0, 0], ax[0, 1], ax[0, 2], ax[0, 3], ax[0, 4], ax[0, 5]
    a10, a11, a12, a13, a14 = ax[1, 0], ax[1, 1], ax[1, 2], ax[1, 3], ax[1, 4]
    a20, a21, a22, a23, a30, a31, a32, a40, a41, a50 = (
        ax[2, 0],
        ax[2, 1],
        ax[2, 2],
        ax[2, 3],
        ax[3, 0],
        ax[3, 1],
        ax[3, 2],
        ax[4, 0],
        ax[4, 1],
        ax[5, 0],
    )
    b00, b01, b02, b03, b04, b05 = ay[0, 0], ay[0, 1], ay[0, 2], ay[0, 3], ay[0, 4], ay[0, 5]
    b10, b11, b12, b13, b14 = ay[1, 0], ay[1, 1], ay[1, 2], ay[1, 3], ay[1, 4]
    b20, b21, b22, b23, b30, b31, b32, b40, b41, b50 = (
        ay[2, 0],
        ay[2, 1],
        ay[2, 2],
        ay[2, 3],
        ay[3, 0],
        ay[3, 1],
        ay[3, 2],
        ay[4, 0],
        ay[4, 1],
        ay[5, 0],
    )
    for k in range(x.size):
        u = (x[k] - cx) * inv_scale
        v = (y[k] - cy) * inv_scale
        px0 = a00 + v * (a01 + v * (a02 + v * (a03 + v * (a04 + v * a05))))
        px1 = a10 + v * (a11 + v * (a12 + v * (a13 + v * a14)))
        px2 = a20 + v * (a21 + v * (a22 + v * a23))
        px3 = a30 + v * (a31 + v * a32)
        px4 = a40 + v * a41
        py0 = b00 + v * (b01 + v * (b02 + v * (b03 + v * (b04 + v * b05))))
        py1 = b10 + v * (b11 + v * (b12 + v * (b13 + v * b14)))
        py2 = b20 + v * (b21 + v * (b22 + v * b23))
        py3 = b30 + v * (b31 + v * b32)
        py4 = b40 + v * b41
        out_x[k] = px0 + u * (px1 + u * (px2 + u * (px3 + u * (px4 + u * a50))))
        out_y[k] = py0 + u * (py1 + u * (py2 + u * (py3 + u * (py4 + u * b50))))


@njit(cache=True)
def _evaluate_any(x, y, cx, cy, inv_scale, ax, ay, out_x, out_y):  # noqa: ANN001, ANN202
    """Any degree d ((d+1, d+1) matrices).

    Horner's scheme, run on blocks of points: each multiply-add step is a loop over the block
    (SIMD, independent points) instead of a chain of dependent multiply-adds per point.
    """
    d = ax.shape[0] - 1
    n = x.size
    u = np.empty(_BLOCK)
    v = np.empty(_BLOCK)
    sx = np.empty(_BLOCK)
    sy = np.empty(_BLOCK)
    bx = np.empty(_BLOCK)
    by = np.empty(_BLOCK)
    for start in range(0, n, _BLOCK):
        m = min(_BLOCK, n - start)
        for b in range(m):
            u[b] = (x[start + b] - cx) * inv_scale
            v[b] = (y[start + b] - cy) * inv_scale
            sx[b] = 0.0
            sy[b] = 0.0
        for i in range(d, -1, -1):
            for b in range(m):
                bx[b] = 0.0
                by[b] = 0.0
            for j in range(d - i, -1, -1):
                kx = ax[i, j]
                ky = ay[i, j]
                for b in range(m):
                    bx[b] = bx[b] * v[b] + kx
                    by[b] = by[b] * v[b] + ky
            for b in range(m):
                sx[b] = sx[b] * u[b] + bx[b]
                sy[b] = sy[b] * u[b] + by[b]
        for b in range(m):
            out_x[start + b] = sx[b]
            out_y[start + b] = sy[b]
