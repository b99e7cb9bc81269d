"""Kernels compiled ahead of time: built once (``flagtrack kernels build``), loaded without numba.

:mod:`.cache` finds and checks a built module (standard library and numpy only); :mod:`.build` runs
the kernels under numba on a small workload to learn their signatures and compiles them with
``numba.pycc`` into the cache. docs/tracking.md ("Start-up") has the figures.
"""
