"""Residual report of a calibration: text lines and a PNG figure.

The figure shows the pseudo-image, the detected corners with their (i, j) indices along the top
row and left column (the names ``--origin-corner i,j`` uses), the origin and the plane axes, and
each corner's residual vector in pixel equivalents, magnified (scale written on the figure).
matplotlib is imported only when a figure is drawn (Agg backend, no display needed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flagtrack.calibration.fit import Calibration


def report_lines(cal: Calibration) -> list[str]:
    """Human-readable summary: corners, degree, residuals in mm and px, pixel size, blink."""
    r = cal.residuals
    n_cols, n_rows = cal.corners_px.shape[1], cal.corners_px.shape[0]
    i0, j0 = cal.frame.origin_index(n_cols, n_rows)
    lines = [
        f"board {n_cols}x{n_rows} inner corners, square {cal.board.square_m * 1e3:g} mm; origin corner "
        f"i,j = {i0},{j0}; x {cal.frame.x_axis.value}, y {cal.frame.y_dir.value} (image terms)",
        f"mapping degree {cal.mapping.degree}; effective pixel {r.pixel_size_mm:.3f} mm",
        f"residual mean {r.mean_mm:.3f} mm ({r.mean_px:.3f} px), max {r.max_mm:.3f} mm ({r.max_px:.3f} px), "
        f"rms {r.rms_mm:.3f} mm over {r.n_corners} corners",
        f"leave-one-out mean {r.loo_mean_mm:.3f} mm ({r.loo_mean_px:.3f} px), max {r.loo_max_mm:.3f} mm "
        f"({r.loo_max_px:.3f} px); inverse max {r.inverse_max_px:.3f} px",
    ]
    if cal.blink:
        b = cal.blink
        lines.append(
            f"blink period {float(b['period_us']) / 1e3:.3f} ms, {b['n_on']} on + {b['n_off']} off "
            f"switches accumulated (score {b['strength']})"
        )
    return lines


def save_figure(path: str | Path, image: np.ndarray, cal: Calibration) -> Path:
    """Draw the residual figure to ``path`` (PNG); return the path."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    path = Path(path)
    px = cal.corners_px
    n_rows, n_cols = px.shape[:2]
    jac = cal.mapping.forward.jacobian(px[..., 0], px[..., 1])
    res_px = np.einsum("...ab,...b->...a", np.linalg.inv(jac), cal.residual_m)
    spacing = float(np.median(np.hypot(*np.diff(px, axis=1).reshape(-1, 2).T)))
    biggest = float(np.hypot(res_px[..., 0], res_px[..., 1]).max()) or 1.0
    gain = 10 ** np.floor(np.log10(0.4 * spacing / biggest))
    h, w = image.shape
    fig, ax = plt.subplots(figsize=(w / 80 + 1, h / 80 + 1.2), dpi=100)
    ax.imshow(image, cmap="gray", vmin=0, vmax=max(float(np.percentile(image, 99.5)), 1e-9))
    ax.plot(px[..., 0].ravel(), px[..., 1].ravel(), "r.", ms=4)
    ax.quiver(
        px[..., 0],
        px[..., 1],
        gain * res_px[..., 0],
        gain * res_px[..., 1],
        color="yellow",
        angles="xy",
        scale_units="xy",
        scale=1.0,
        width=0.003,
    )
    for i in range(n_cols):
        ax.annotate(str(i), px[0, i], xytext=(0, 8), textcoords="offset points", color="cyan", fontsize=7, ha="center")
    for j in range(n_rows):
        ax.annotate(
            str(j), px[j, 0], xytext=(-10, 0), textcoords="offset points", color="orange", fontsize=7, va="center"
        )
    i0, j0 = cal.frame.origin_index(n_cols, n_rows)
    origin = px[j0, i0]
    for step, colour, name in ((cal.frame.x_step, "red", "x"), (cal.frame.y_step, "lime", "y")):
        i1, j1 = i0 + step[0], j0 + step[1]
        inside = 0 <= i1 < n_cols and 0 <= j1 < n_rows
        tip = px[j1, i1] if inside else origin - (px[j0 - step[1], i0 - step[0]] - origin)
        ax.annotate("", tip, origin, arrowprops={"arrowstyle": "->", "color": colour, "lw": 2})
        ax.annotate(name, tip, color=colour, fontsize=10, fontweight="bold")
    ax.plot(*origin, "o", mfc="none", mec="red", ms=10)
    r = cal.residuals
    ax.set_title(
        f"degree {cal.mapping.degree}: residual mean {r.mean_mm:.3f} mm ({r.mean_px:.3f} px), "
        f"max {r.max_mm:.3f} mm ({r.max_px:.3f} px); vectors x{gain:g}",
        fontsize=9,
    )
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def save_image(path: str | Path, image: np.ndarray) -> Path:
    """Write the pseudo-image alone (grey levels, negatives black) to ``path`` (PNG): a diagnosis aid."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from flagtrack.calibration.pseudo_image import to_uint8

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    plt.imsave(path, to_uint8(image), cmap="gray", vmin=0, vmax=255)
    return path
