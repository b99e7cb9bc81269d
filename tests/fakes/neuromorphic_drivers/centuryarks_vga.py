"""Fake ``neuromorphic_drivers.centuryarks_vga`` (SilkyEvCam VGA, 640x480): the fields of 0.18's generated module."""

from __future__ import annotations

import dataclasses

from ._models import Bounds, RateLimiter, RingConfiguration  # noqa: F401 - part of the module's API

WIDTH, HEIGHT = 640, 480
DEVICE_BOUNDS = {name: (0, 1800) for name in ("diff_on", "diff", "diff_off", "fo", "hpf", "pr", "refr")}


@dataclasses.dataclass
class Biases:
    diff_on: int = 384
    diff: int = 296
    diff_off: int = 222
    fo: int = 1477
    hpf: int = 1499
    pr: int = 1250
    refr: int = 1500


@dataclasses.dataclass
class Configuration:
    biases: Biases = dataclasses.field(default_factory=Biases)
    x_mask: tuple = (0,) * 10
    y_mask: tuple = (0,) * 8
    mask_intersection_only: bool = False
    rate_limiter: RateLimiter | None = None

    @staticmethod
    def type() -> str:
        return "centuryarks_vga"


@dataclasses.dataclass(frozen=True)
class BiasesBounds:
    diff_on: Bounds = Bounds()
    diff: Bounds = Bounds()
    diff_off: Bounds = Bounds()
    fo: Bounds = Bounds()
    hpf: Bounds = Bounds()
    pr: Bounds = Bounds()
    refr: Bounds = Bounds()


@dataclasses.dataclass(frozen=True)
class Properties:
    width: int = WIDTH
    height: int = HEIGHT
