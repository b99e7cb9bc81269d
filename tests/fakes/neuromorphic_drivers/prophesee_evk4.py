"""Fake ``neuromorphic_drivers.prophesee_evk4`` (IMX636, 1280x720): the fields of 0.18's generated module."""

from __future__ import annotations

import dataclasses
import enum

from ._models import Bounds, RateLimiter, RingConfiguration  # noqa: F401 - part of the module's API

WIDTH, HEIGHT = 1280, 720
DEVICE_BOUNDS = {"diff_on": (-85, 140), "diff_off": (-35, 190), "fo": (-35, 55), "hpf": (0, 120), "refr": (-20, 235)}
"""Bounds the fake device reports (other biases: fixed at 0), like the IMX636's allowed offsets."""


@dataclasses.dataclass
class Biases:
    pr: int = 0
    fo: int = 0
    hpf: int = 0
    diff_on: int = 0
    diff: int = 0
    diff_off: int = 0
    inv: int = 0
    refr: int = 0
    reqpuy: int = 0
    reqpux: int = 0
    sendreqpdy: int = 0
    unknown_1: int = 0
    unknown_2: int = 0


class Clock(enum.Enum):
    INTERNAL = 0
    INTERNAL_WITH_OUTPUT_ENABLED = 1
    EXTERNAL = 2


@dataclasses.dataclass
class Configuration:
    biases: Biases = dataclasses.field(default_factory=Biases)
    x_mask: tuple = (0,) * 20
    y_mask: tuple = (0,) * 12
    pixel_mask: tuple = (0,) * 21
    mask_intersection_only: bool = False
    enable_external_trigger: bool = True
    clock: Clock = Clock.INTERNAL
    rate_limiter: RateLimiter | None = None
    enable_output: bool = True

    @staticmethod
    def type() -> str:
        return "prophesee_evk4"


@dataclasses.dataclass(frozen=True)
class BiasesBounds:
    pr: Bounds = Bounds()
    fo: Bounds = Bounds()
    hpf: Bounds = Bounds()
    diff_on: Bounds = Bounds()
    diff: Bounds = Bounds()
    diff_off: Bounds = Bounds()
    inv: Bounds = Bounds()
    refr: Bounds = Bounds()
    reqpuy: Bounds = Bounds()
    reqpux: Bounds = Bounds()
    sendreqpdy: Bounds = Bounds()
    unknown_1: Bounds = Bounds()
    unknown_2: Bounds = Bounds()


@dataclasses.dataclass(frozen=True)
class Properties:
    width: int = WIDTH
    height: int = HEIGHT
