"""Where the process says how to find the kernels compiled ahead of time (no import beyond this one).

``flagtrack``'s ``main`` sets :data:`loader` before a command runs; :mod:`.jit` calls it once, at the
first kernel call. Left at ``None`` (tests, library use), every kernel goes through numba.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

loader: Callable[[], Any] | None = None
