"""``njit`` for every compiled kernel of flagtrack: numba imported only when a kernel needs it.

A kernel decorated here is a :class:`Kernel`. When a call's arguments match a signature compiled
ahead of time (a module built by ``flagtrack kernels build``, found by the loader that
:func:`set_compiled_loader` registers), that machine code runs: no numba import, no type inference
(numba's import alone is ~0.3 s of every command). Otherwise numba is imported, every kernel becomes
a numba dispatcher (compiled or loaded from numba's cache, as before), and the module globals that
held kernels are swapped for the dispatchers, so that compiled callers resolve their callees.

numba's first compiled call makes it import ``numba.np.arraymath``, whose BLAS probe imports
``scipy.linalg`` (~0.15 s); no flagtrack kernel needs it, so that module is imported once with the
probe made unimportable, then SciPy imports normally again.
"""

from __future__ import annotations

import gc
import sys
import threading
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from flagtrack.daemon.core import jit_hook

_BLAS_PROBE = "scipy.linalg.cython_blas"
ArgSpec = tuple[Any, ...]
"""``("a", dtype, ndim, contiguous, writeable, aligned)`` for an array, ``("s", dtype)`` for a scalar."""
CompiledTable = dict[str, list[tuple[tuple[ArgSpec, ...], Callable[..., Any]]]]
"""Kernel name (``module.qualname``) -> its compiled signatures and machine-code functions."""

_lock = threading.RLock()
_kernels: list[Kernel] = []
_numba_njit: Any = None
_loader: Callable[[], CompiledTable | None] | None = None
_table: CompiledTable | None = None
_loaded = False


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


def _scalar_dtype(value: Any) -> str | None:
    """The dtype numba gives a scalar argument (None: not a scalar it takes here)."""
    kind = type(value)
    if kind is bool:
        return "bool"
    if kind is int:
        return "int64"
    if kind is float:
        return "float64"
    if isinstance(value, np.generic):
        return value.dtype.name
    return None


def matches(args: Sequence[Any], specs: tuple[ArgSpec, ...]) -> bool:
    """Whether ``args`` are what a compiled signature takes (numba would pick the same types)."""
    if len(args) != len(specs):
        return False
    for value, spec in zip(args, specs):
        if spec[0] == "a":
            if not isinstance(value, np.ndarray) or value.dtype != spec[1] or value.ndim != spec[2]:
                return False
            flags = value.flags
            if (
                (spec[3] and not flags.c_contiguous)
                or (spec[4] and not flags.writeable)
                or (spec[5] and not flags.aligned)
            ):
                return False
        elif _scalar_dtype(value) != spec[1]:
            return False
    return True


class Kernel:
    """A kernel: compiled ahead of time where a signature matches, numba's dispatcher otherwise."""

    def __init__(self, py_func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = py_func
        self.options = options
        self.name = f"{py_func.__module__}.{py_func.__qualname__}"
        self.__name__ = py_func.__name__
        self.__qualname__ = py_func.__qualname__
        self.__module__ = py_func.__module__
        self.__doc__ = py_func.__doc__
        self._compiled: list[tuple[tuple[ArgSpec, ...], Callable[..., Any]]] | None = None
        self._dispatcher: Any = None

    def __call__(self, *args: Any) -> Any:
        compiled = self._compiled
        if compiled is None:
            compiled = self._compiled = list((_compiled_table() or {}).get(self.name, ()))
        for specs, function in compiled:
            if matches(args, specs):
                return function(*args)
        return self.dispatcher(*args)

    @property
    def dispatcher(self) -> Any:
        """numba's dispatcher of this kernel (numba imported, every kernel swapped, on first use)."""
        if self._dispatcher is None:
            _use_numba()
            with _lock:
                if self._dispatcher is None:  # a kernel made outside njit()
                    self._dispatcher = _numba_njit(**self.options)(self.py_func)
        return self._dispatcher

    @property
    def signatures(self) -> list[Any]:
        """Signatures numba compiled or loaded in this process (empty before numba is used)."""
        return [] if self._dispatcher is None else list(self._dispatcher.signatures)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.dispatcher, name)


def njit(*args: Any, **options: Any) -> Any:
    """``numba.njit`` with the same options, as ``@njit`` or ``@njit(...)``; a :class:`Kernel`."""

    def make(func: Callable[..., Any]) -> Any:
        with _lock:
            kernel = Kernel(func, options)
            _kernels.append(kernel)
            if _numba_njit is None:
                return kernel
            kernel._dispatcher = _numba_njit(**options)(func)  # numba in use: its callers resolve it
            return kernel._dispatcher

    if args and callable(args[0]):
        return make(args[0])
    return make


def set_compiled_loader(loader: Callable[[], CompiledTable | None] | None) -> None:
    """Set the function that finds the kernels compiled ahead of time (called once, at the next kernel
    call; by default :data:`.jit_hook.loader`, which ``flagtrack``'s ``main`` sets); ``None``: numba only."""
    global _loader, _table, _loaded
    with _lock:
        _loader, _table, _loaded = loader, None, loader is None
        for kernel in _kernels:
            kernel._compiled = None


def _compiled_table() -> CompiledTable | None:
    global _table, _loaded
    with _lock:
        if not _loaded:
            _loaded = True
            loader = _loader or jit_hook.loader
            _table = loader() if loader is not None else None
        return _table


def numba_in_use() -> bool:
    """Whether numba was imported for the kernels (a call no compiled signature matched)."""
    return _numba_njit is not None


def _use_numba() -> None:
    """Import numba, make every kernel's dispatcher and swap the module globals holding kernels."""
    global _numba_njit
    with _lock:
        if _numba_njit is not None:
            return
        collecting = gc.isenabled()
        gc.disable()  # numba's import makes ~100 k objects, none of them garbage: no collection meanwhile
        try:
            _import_arraymath_without_blas_probe()
            from numba import njit as numba_njit

            for kernel in _kernels:
                kernel._dispatcher = numba_njit(**kernel.options)(kernel.py_func)
        finally:
            if collecting:
                gc.enable()
        gc.freeze()  # and later full collections need not go through them again
        for module in list(sys.modules.values()):
            namespace = getattr(module, "__dict__", None)
            if not isinstance(namespace, dict):
                continue
            for name, value in list(namespace.items()):
                if isinstance(value, Kernel):
                    namespace[name] = value.dispatcher
        _numba_njit = numba_njit


def all_kernels() -> list[Kernel]:
    """Every kernel defined so far (for the ahead-of-time build)."""
    return list(_kernels)


__all__ = ["Kernel", "all_kernels", "matches", "njit", "numba_in_use", "set_compiled_loader"]
