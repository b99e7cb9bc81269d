"""Argument types for options that take a time in seconds: argparse refuses anything else in one line."""

from __future__ import annotations

import argparse
import math

MAX_SECONDS = 7 * 24 * 3600.0
"""Longest time an option takes (a week: longer is a typo, and ``inf`` never ends)."""


def seconds(text: str) -> float:
    """A finite time in [0, a week], s (``nan``, ``inf`` and negative times are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not (math.isfinite(value) and 0 <= value <= MAX_SECONDS):
        raise argparse.ArgumentTypeError(f"must be a time in [0, {MAX_SECONDS:g}] s, got {text}")
    return value


def positive_seconds(text: str) -> float:
    """As :func:`seconds`, and above 0."""
    value = seconds(text)
    if value == 0:
        raise argparse.ArgumentTypeError(f"must be above 0 s, got {text}")
    return value
