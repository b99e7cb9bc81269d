"""flagtrack.daemon.core.jit: a compiled signature is used only for the argument types numba would give it."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core import jit

ARRAY_C = ("a", np.dtype("<i8"), 1, True, True, False)  # int64[::1], writeable, any alignment
ARRAY_A_READONLY = ("a", np.dtype("<u2"), 1, False, False, False)  # readonly uint16[:] (any layout)
INT, FLOAT, BOOL = ("s", "int64"), ("s", "float64"), ("s", "bool")

_readonly = np.frombuffer(b"\x01\x00\x02\x00", dtype="<u2")
_records = np.zeros(4, dtype=[("t", "<i8"), ("x", "<u2")])


@pytest.mark.parametrize(
    ("args", "specs", "expected"),
    [
        ((np.arange(3), 1, 2.0, True), (ARRAY_C, INT, FLOAT, BOOL), True),
        ((np.arange(3), np.int64(1), np.float64(2.0), np.bool_(True)), (ARRAY_C, INT, FLOAT, BOOL), True),
        ((np.arange(3, dtype=np.int32),), (ARRAY_C,), False),  # another dtype
        ((np.arange(6).reshape(2, 3),), (ARRAY_C,), False),  # another ndim
        ((np.arange(6)[::2],), (ARRAY_C,), False),  # strided where contiguous was compiled
        ((_records["t"],), (("a", np.dtype("<i8"), 1, False, True, False),), True),  # a field view, layout A
        ((_readonly,), (ARRAY_C,), False),  # readonly where the kernel may write
        ((_readonly,), (ARRAY_A_READONLY,), True),
        ((np.arange(2, dtype="<u2"),), (ARRAY_A_READONLY,), True),  # writeable where readonly was compiled
        ((1.0,), (INT,), False),  # float for an int: numba would compile another signature
        ((1,), (FLOAT,), False),
        ((True,), (INT,), False),
        ((np.int32(1),), (INT,), False),
        (([1, 2],), (ARRAY_C,), False),
        ((np.arange(3),), (ARRAY_C, INT), False),  # arity
    ],
)
def test_matches(args, specs, expected) -> None:
    assert jit.matches(args, specs) is expected


def test_kernel_calls_the_compiled_function_for_matching_types_and_numba_otherwise() -> None:
    def double(a):
        return a * 2

    kernel = jit.Kernel(double, {"cache": False})
    calls = []
    kernel._compiled = [((INT,), lambda a: calls.append(a) or -1)]
    assert kernel(3) == -1 and calls == [3]  # the "compiled" function, not the Python one
    assert kernel(1.5) == 3.0  # no compiled float signature: numba's dispatcher
    assert kernel.signatures  # numba compiled one
