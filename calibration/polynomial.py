"""Polynomial maps R^2 -> R^2: least-squares fit, leave-one-out residuals, fast evaluation.

Each output is a polynomial of total degree ``d`` in normalised inputs ``u = (x - cx) / scale``,
``v = (y - cy) / scale`` (so the monomials stay in [-1, 1] and the fit is well conditioned):
``X = sum_t a_t u^i_t v^j_t`` over the exponents ``(i, j)``, ``i + j <= d``, listed by
:func:`exponents`. Evaluation is compiled (:mod:`._kernels`): Horner's scheme in v then in u,
``(d + 1)(d + 2) / 2`` multiply-adds per output, unrolled for d <= 5 so that the loop over points
vectorises.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flagtrack.calibration._kernels import evaluate


def exponents(degree: int) -> list[tuple[int, int]]:
    """Exponents (i of u, j of v) of the monomials of total degree <= ``degree``, by degree then i descending."""
    return [(total - j, j) for total in range(degree + 1) for j in range(total + 1)]


def design_matrix(u: np.ndarray, v: np.ndarray, degree: int) -> np.ndarray:
    """(n, n_terms) monomials of normalised inputs ``u``, ``v`` (n,)."""
    return np.column_stack([u**i * v**j for i, j in exponents(degree)])


@dataclass(frozen=True)
class Polynomial2D:
    """Two polynomials of total degree ``degree`` in normalised inputs.

    Attributes:
        degree: total degree d.
        centre: (cx, cy) subtracted from the inputs, input units.
        scale: inputs are divided by it after centring, input units.
        coef_x: coefficients of the first output, one per :func:`exponents` term.
        coef_y: coefficients of the second output.
    """

    degree: int
    centre: tuple[float, float]
    scale: float
    coef_x: tuple[float, ...]
    coef_y: tuple[float, ...]
    _ax: np.ndarray = field(init=False, repr=False, compare=False)  # coef_x in the kernels' padded layout
    _ay: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n = len(exponents(self.degree))
        if self.degree < 1 or len(self.coef_x) != n or len(self.coef_y) != n:
            raise ValueError(
                f"a degree-{self.degree} polynomial needs {n} coefficients per output "
                f"(got {len(self.coef_x)} and {len(self.coef_y)})"
            )
        if not self.scale > 0:
            raise ValueError("Polynomial2D.scale must be > 0")
        size = 4 if self.degree <= 3 else 6 if self.degree <= 5 else self.degree + 1  # kernels' padded sizes
        ax = np.zeros((size, size))
        ay = np.zeros_like(ax)
        for (i, j), cx, cy in zip(exponents(self.degree), self.coef_x, self.coef_y, strict=True):
            ax[i, j], ay[i, j] = cx, cy
        object.__setattr__(self, "_ax", ax)
        object.__setattr__(self, "_ay", ay)

    @staticmethod
    def fit(
        x: np.ndarray,
        y: np.ndarray,
        out_x: np.ndarray,
        out_y: np.ndarray,
        degree: int,
        centre: tuple[float, float],
        scale: float,
    ) -> Polynomial2D:
        """Least-squares fit of (out_x, out_y) = P(x, y) over n points (arrays (n,)).

        Raises:
            ValueError: fewer points than coefficients, or points that do not fix them (rank).
        """
        u, v = (np.asarray(x, np.float64) - centre[0]) / scale, (np.asarray(y, np.float64) - centre[1]) / scale
        a = design_matrix(u, v, degree)
        if a.shape[0] < a.shape[1] or np.linalg.matrix_rank(a) < a.shape[1]:
            raise ValueError(
                f"{a.shape[0]} points do not determine the {a.shape[1]} coefficients of a degree-{degree} polynomial"
            )
        coef, *_ = np.linalg.lstsq(a, np.column_stack([out_x, out_y]), rcond=None)
        return Polynomial2D(
            degree,
            (float(centre[0]), float(centre[1])),
            float(scale),
            tuple(float(c) for c in coef[:, 0]),
            tuple(float(c) for c in coef[:, 1]),
        )

    def __call__(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Evaluate at points of any matching shape and numeric dtype; float64 outputs of that shape."""
        x_arr, y_arr = np.asarray(x), np.asarray(y)
        if x_arr.shape != y_arr.shape:
            raise ValueError(f"x and y shapes differ: {x_arr.shape} vs {y_arr.shape}")
        flat_x, flat_y = np.ascontiguousarray(x_arr).ravel(), np.ascontiguousarray(y_arr).ravel()
        if flat_x.dtype.kind not in "fiu":
            flat_x, flat_y = flat_x.astype(np.float64), flat_y.astype(np.float64)
        out_x, out_y = np.empty(flat_x.size), np.empty(flat_x.size)
        evaluate(
            flat_x,
            flat_y,
            self.centre[0],
            self.centre[1],
            1.0 / self.scale,
            self._ax,
            self._ay,
            out_x,
            out_y,
        )
        return out_x.reshape(x_arr.shape), out_y.reshape(x_arr.shape)

    def evaluate_numpy(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Same as calling, with a numpy design matrix (reference for tests)."""
        u = (np.asarray(x, np.float64) - self.centre[0]) / self.scale
        v = (np.asarray(y, np.float64) - self.centre[1]) / self.scale
        a = design_matrix(u.ravel(), v.ravel(), self.degree)
        return (a @ np.asarray(self.coef_x)).reshape(u.shape), (a @ np.asarray(self.coef_y)).reshape(u.shape)

    def jacobian(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(..., 2, 2) derivatives [[dX/dx, dX/dy], [dY/dx, dY/dy]] at points of any matching shape."""
        u = (np.asarray(x, np.float64) - self.centre[0]) / self.scale
        v = (np.asarray(y, np.float64) - self.centre[1]) / self.scale
        jac = np.zeros(u.shape + (2, 2))
        for (i, j), cx, cy in zip(exponents(self.degree), self.coef_x, self.coef_y, strict=True):
            du = i * u ** max(i - 1, 0) * v**j if i else 0.0
            dv = j * u**i * v ** max(j - 1, 0) if j else 0.0
            jac[..., 0, 0] += cx * du
            jac[..., 0, 1] += cx * dv
            jac[..., 1, 0] += cy * du
            jac[..., 1, 1] += cy * dv
        return jac / self.scale

    def leave_one_out(
        self, x: np.ndarray, y: np.ndarray, out_x: np.ndarray, out_y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (prediction - data) of each point predicted by the fit without it (exact, hat matrix)."""
        u, v = (
            (np.asarray(x, np.float64) - self.centre[0]) / self.scale,
            (np.asarray(y, np.float64) - self.centre[1]) / self.scale,
        )
        a = design_matrix(u, v, self.degree)
        q, _ = np.linalg.qr(a)
        leverage = np.minimum(np.sum(q**2, axis=1), 1.0 - 1e-12)
        px, py = self(x, y)
        return (px - out_x) / (1.0 - leverage), (py - out_y) / (1.0 - leverage)

    def to_mapping(self) -> dict[str, object]:
        """Plain data for YAML: degree, centre, scale, exponents, coefficients."""
        return {
            "degree": self.degree,
            "centre": list(self.centre),
            "scale": self.scale,
            "exponents": [list(e) for e in exponents(self.degree)],
            "x": list(self.coef_x),
            "y": list(self.coef_y),
        }
