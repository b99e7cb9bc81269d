"""The lazy ``njit`` of daemon/core/jit.py: numba on demand, native functions only on exact types."""

import numpy as np

from flagtrack.daemon.core import jit
from flagtrack.daemon.core.kernels import run_updates
from flagtrack.daemon.core.smoothing import smooth_batch


@jit.njit(cache=False, error_model="numpy")
def _scaled_sum(a, k):  # noqa: ANN001, ANN202
    return a.sum() * k


@jit.njit(cache=False)
def _calls_other(a):  # noqa: ANN001, ANN202
    return _scaled_sum(a, 2.0) + 1.0  # a lazy kernel called from a kernel


def test_kernels_are_lazy_and_keep_their_names() -> None:
    assert isinstance(run_updates, jit.LazyKernel)
    assert run_updates.__name__ == "run_updates"
    assert smooth_batch.key.endswith("smoothing:smooth_batch")


def test_lazy_kernel_runs_through_numba_and_kernels_call_kernels() -> None:
    a = np.arange(4.0)
    assert _scaled_sum(a, 3.0) == 18.0
    assert _calls_other(a) == 13.0
    assert _scaled_sum.dispatcher.signatures  # a real numba dispatcher behind it


@jit.njit(cache=False)
def twice(a):  # noqa: ANN001, ANN202
    return a * 2


def test_native_function_used_only_for_its_exact_argument_types() -> None:
    calls = []
    expected = (jit.arg_key(np.zeros(3)),)
    jit.install_native(twice.key, expected, lambda a: calls.append(a) or "native")
    assert twice(np.ones(3)) == "native"
    np.testing.assert_array_equal(twice(np.ones(3, dtype=np.float32)), 2.0)  # other dtype: numba
    np.testing.assert_array_equal(twice(np.ones(6)[::2]), 2.0)  # not contiguous: numba
    readonly = np.ones(3)
    readonly.flags.writeable = False
    np.testing.assert_array_equal(twice(readonly), 2.0)
    assert len(calls) == 1


def test_arg_key_of_scalars_and_records() -> None:
    assert jit.arg_key(3) == ("i8",)
    assert jit.arg_key(3.0) == ("f8",)
    assert jit.arg_key(True) == ("b",)
    assert jit.arg_key(np.int32(3)) == ("s", "<i4")
    rec = np.zeros(2, dtype=[("t", "<i8"), ("c", "u1")])
    assert jit.arg_key(rec)[1] != jit.arg_key(np.zeros(2, dtype=[("t", "<i8"), ("d", "u1")]))[1]


def test_uninstalled_natives_are_not_used() -> None:
    jit.install_native(twice.key, (jit.arg_key(np.zeros(2)),), lambda a: "native")
    assert twice(np.ones(2)) == "native"
    jit.uninstall_natives()
    np.testing.assert_array_equal(twice(np.ones(2)), 2.0)
