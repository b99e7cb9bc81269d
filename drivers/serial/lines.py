"""Line protocols over a serial link (the tunnel's and the point sensor's): received bytes split into
lines, and the pieces of configurable reply patterns."""

from __future__ import annotations

import re

NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
"""A decimal number as devices print it (sign, decimals, exponent optional), for reply patterns."""
MAX_LINE_BYTES = 256
"""A partial line longer than this is dropped (a device that sends no end of line)."""


def compile_pattern(name: str, pattern: str) -> re.Pattern[str]:
    """``re.compile(pattern)``; a bad pattern raises ValueError naming the setting ``name``."""
    try:
        return re.compile(pattern)
    except re.error as exc:
        raise ValueError(f"{name} is not a valid regular expression: {exc}") from None


def split_lines(buffer: bytes) -> tuple[list[str], bytes, bool]:
    """The complete non-empty lines of ``buffer`` (stripped), the partial rest, and whether that rest
    grew over ``MAX_LINE_BYTES`` (then it is dropped: returned empty)."""
    *complete, rest = buffer.split(b"\n")
    lines = [line for raw in complete if (line := raw.decode("ascii", errors="replace").strip())]
    if len(rest) > MAX_LINE_BYTES:
        return lines, b"", True
    return lines, rest, False
