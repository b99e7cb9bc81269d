"""numba's ``njit`` for every compiled kernel of flagtrack, with a faster first call.

The first compiled call of a process (even one that only loads a cached kernel) makes numba import
its implementations, among them ``numba.np.arraymath``, whose BLAS probe imports ``scipy.linalg``
(with ``numpy.f2py`` and ``numpy.testing`` behind it): about 0.15 s of every ``flagtrack`` command
that tracks or decodes, a tenth of a whole ``flagtrack reconstruct`` of a 6 s recording. The probe
only decides whether numba's compiled ``np.correlate``/``np.convolve`` call BLAS or numba's own
loop; no flagtrack kernel uses them, and numba's ``np.dot`` and ``np.linalg`` look for SciPy
again when they are compiled. So this module imports ``numba.np.arraymath`` once with the probe's
module made unimportable, then undoes that at once: SciPy imports normally afterwards.
"""

from __future__ import annotations

import sys

_BLAS_PROBE = "scipy.linalg.cython_blas"


def _import_arraymath_without_blas_probe() -> None:
    """Import ``numba.np.arraymath`` with ``scipy.linalg.cython_blas`` unimportable for that moment."""
    if _BLAS_PROBE in sys.modules or "numba.np.arraymath" in sys.modules:
        return  # SciPy's linalg is loaded already, or numba's implementations are: nothing to save
    sys.modules[_BLAS_PROBE] = None  # type: ignore[assignment]  # "import" of it raises ImportError
    try:
        import numba.np.arraymath  # noqa: F401
    except Exception:  # noqa: BLE001 - another numba than we know: leave it to its first call
        pass
    finally:
        if _BLAS_PROBE in sys.modules and sys.modules[_BLAS_PROBE] is None:
            del sys.modules[_BLAS_PROBE]


_import_arraymath_without_blas_probe()

from numba import njit  # noqa: E402

__all__ = ["njit"]
