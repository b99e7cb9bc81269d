"""The pure algorithm core: numpy/scipy/numba and the standard library only; no clock, no I/O."""
