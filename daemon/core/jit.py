"""``njit`` that imports numba only when a kernel is first run, and can run ahead-of-time builds.

Importing numba and loading its CPU target (about 0.9 s on this machine, scipy.linalg included)
was most of the start-up of ``flagtrack reconstruct``. The kernel modules decorate with this
:func:`njit` instead of numba's: the decorator records the function and its options, and returns a
:class:`LazyKernel`. A call of a lazy kernel from Python

- runs the matching native function of an ahead-of-time (AOT) module when one was installed with
  :func:`install_native` (``daemon/core/aot.py`` builds and loads them; no numba import at all);
- otherwise imports numba, turns every registered kernel into a real numba dispatcher (same
  function, same options, same on-disk cache: ``cache=True`` still applies), teaches numba to
  type a lazy kernel as its dispatcher (so kernels calling kernels compile as before), and runs
  the dispatcher.

Both paths run the same compiled code of the same source, so results do not depend on the path.
Native functions match a call only when every argument has exactly the type of the signature they
were built for (dtype, dimensions, layout, writeability); any other call goes to numba.
"""

from __future__ import annotations

import functools
import sys
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

_REGISTRY: list[LazyKernel] = []
_NATIVE: dict[str, list[tuple[tuple[Any, ...], Callable[..., Any]]]] = {}
_LOCK = threading.RLock()
_state = {"materialized": False, "record": False}


def njit(*args: Any, **options: Any) -> Any:
    """Drop-in for ``numba.njit`` (keyword options only): a :class:`LazyKernel`, or a numba
    dispatcher when numba is already loaded for the kernels."""
    if args and callable(args[0]):
        return _make(args[0], options)
    return lambda func: _make(func, options)


def _make(func: Callable[..., Any], options: dict[str, Any]) -> Any:
    with _LOCK:
        if _state["materialized"]:
            import numba

            return numba.njit(**options)(func)
        kernel = LazyKernel(func, options)
        _REGISTRY.append(kernel)
        return kernel


def arg_key(value: Any) -> tuple[Any, ...]:
    """The type of one argument as native signatures see it (numba's ``typeof``, roughly)."""
    if isinstance(value, np.ndarray):
        flags = value.flags
        layout = "C" if flags.c_contiguous else "F" if flags.f_contiguous else "A"
        return ("a", value.dtype.str if value.dtype.fields is None else repr(value.dtype), value.ndim, layout,
                bool(flags.writeable), bool(flags.aligned))
    if isinstance(value, bool | np.bool_):
        return ("b",)
    if isinstance(value, int):
        return ("i8",)
    if isinstance(value, float):
        return ("f8",)
    if isinstance(value, np.generic):
        return ("s", value.dtype.str)
    return ("?", type(value).__name__)


def _matches(expected: tuple[Any, ...], args: tuple[Any, ...]) -> bool:
    if len(expected) != len(args):
        return False
    for want, value in zip(expected, args):
        got = arg_key(value)
        if want[0] == "a" and got[0] == "a":
            if want[1] != got[1] or want[2] != got[2] or want[4] != got[4] or want[5] != got[5]:
                return False
            if want[3] != "A" and want[3] != got[3]:
                return False
        elif want != got:
            return False
    return True


class LazyKernel:
    """A kernel function: native (AOT) when installed, numba dispatcher otherwise (made on demand)."""

    def __init__(self, func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = func
        self.options = options
        self.key = f"{func.__module__}:{func.__qualname__}"
        self.calls: dict[tuple[Any, ...], tuple[Any, ...]] = {}  # arg keys -> numba types (when recording)
        self._jit: Any = None
        functools.update_wrapper(self, func)

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        native = _NATIVE.get(self.key)
        if native is not None and not kwargs:
            for expected, func in native:
                if _matches(expected, args):
                    return func(*args)
        dispatcher = self.dispatcher
        if _state["record"] and not kwargs:
            keys = tuple(arg_key(a) for a in args)
            if keys not in self.calls:
                self.calls[keys] = tuple(dispatcher.typeof_pyval(a) for a in args)
        return dispatcher(*args, **kwargs)

    @property
    def dispatcher(self) -> Any:
        """The numba dispatcher of this kernel (imports numba on first use)."""
        if self._jit is None:
            materialize()
        return self._jit

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name in ("_jit", "py_func", "options", "key", "calls"):
            raise AttributeError(name)
        return getattr(self.dispatcher, name)

    def __repr__(self) -> str:
        return f"<LazyKernel {self.key}>"


def materialize() -> None:
    """Import numba and make every registered kernel a numba dispatcher (idempotent)."""
    with _LOCK:
        if _state["materialized"]:
            return
        import numba

        from numba.core import types
        from numba.extending import typeof_impl

        @typeof_impl.register(LazyKernel)
        def _typeof_lazy(value: LazyKernel, context: Any) -> Any:  # kernels calling kernels
            return types.Dispatcher(value.dispatcher)

        for kernel in _REGISTRY:
            kernel._jit = numba.njit(**kernel.options)(kernel.py_func)
        _state["materialized"] = True


def kernels() -> list[LazyKernel]:
    """Every kernel registered so far."""
    return list(_REGISTRY)


def record_calls(enabled: bool = True) -> None:
    """Record the argument types of kernels called from Python through numba (to build AOT modules)."""
    _state["record"] = enabled


def install_native(key: str, expected: tuple[Any, ...], func: Callable[..., Any]) -> None:
    """Run ``func`` for calls of kernel ``key`` whose arguments match ``expected`` (see :func:`arg_key`)."""
    with _LOCK:
        _NATIVE.setdefault(key, []).append((expected, func))


def uninstall_natives() -> None:
    """Remove every native function (later calls go through numba)."""
    with _LOCK:
        _NATIVE.clear()


def native_count() -> int:
    """How many native functions are installed."""
    return sum(len(v) for v in _NATIVE.values())
