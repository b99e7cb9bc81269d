"""The numbers of a sweep point: one name, one unit, one statistic each, wherever they are shown.

A program reads a point's numbers under their keys (``run.jsonl``, ``run.json``, ``summary.csv``): a
fraction of L where the key ends in ``_over_l``. A person reads them under their label, errors and
distances in % of L (as the paper quotes them), the tip amplitude A/L as a ratio (as the paper plots
it). The terminal lines, ``README.txt`` and the figures take label, unit and digits from
:data:`QUANTITIES`, so the same value reads the same everywhere.

The tip error (``flagtrack metrics compare``'s ``tip_error_rms_over_l``, the paper's delta) and the
event-cloud distance (``/delta_rms`` of a centreline file, the paper's Delta_RMS, here
``cloud_distance_*``) are different numbers with different names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Keys the point records had before the cloud distance had a name of its own (old -> new). Records
#: written before are read under the new names; ``run.jsonl``, ``run.json`` and ``summary.csv`` still
#: carry the old keys too, with the same values, for the programs that read them.
POINT_ALIASES = {
    "delta_rms_over_l": "cloud_distance_mean_over_l",
    "delta_rms_std_over_l": "cloud_distance_std_over_l",
}


@dataclass(frozen=True)
class Quantity:
    """One number of a point as a person reads it.

    Attributes:
        key: its key in the run's files (a fraction of L where it ends in ``_over_l``).
        label: its name for a person (``e/L RMS``).
        unit: the unit shown (``%`` of L for errors and distances, ``Hz``, ``m/s``, ``""`` for a ratio).
        scale: shown value = value under ``key`` times this (100 for % of L).
        digits: decimals shown.
        meaning: what it is, its statistic stated.
    """

    key: str
    label: str
    unit: str
    scale: float
    digits: int
    meaning: str

    def number(self, value: float | None) -> str:
        """The shown number without its unit: ``0.36`` (``-`` for a number not known)."""
        return "-" if value is None or not math.isfinite(value) else f"{value * self.scale:.{self.digits}f}"

    def text(self, value: float | None, *, with_label: bool = True) -> str:
        """``e/L RMS 0.36 %`` (``-`` for a number not known)."""
        number = self.number(value)
        shown = f"{number} {self.unit}".rstrip() if number != "-" else number
        return f"{self.label} {shown}" if with_label else shown

    @property
    def heading(self) -> str:
        """``e/L RMS (%)``: a column heading or an axis label."""
        return f"{self.label} ({self.unit})" if self.unit else self.label


QUANTITIES: dict[str, Quantity] = {
    q.key: q
    for q in (
        Quantity("speed_mps", "U", "m/s", 1.0, 2, "wind speed set-point"),
        Quantity("amplitude_over_l", "A/L", "", 1.0, 3,
                 "tip amplitude over L: half the peak-to-peak of the tip's lateral displacement over the point"),
        Quantity("amplitude_std_over_l", "A/L std", "", 1.0, 3, "standard deviation of A/L measured cycle by cycle"),
        Quantity("frequency_hz", "f", "Hz", 1.0, 1, "flapping frequency"),
        Quantity("lost_fraction", "lost", "%", 100.0, 1, "updates in which the tracker did not find the flag"),
        Quantity("stale_fraction", "stale", "%", 100.0, 1,
                 "updates whose shape rests on no recent events in the flag's region (remembered, not measured)"),
        Quantity("shed_fraction", "shed", "%", 100.0, 1,
                 "share of the point's camera time the live tracker skipped to keep within its latency budget"),
        Quantity("chain_reach", "reach", "", 1.0, 3,
                 "where the flag's events ended along the live chain, a fraction of L (1: at its tip)"),
        Quantity("sensor_error_rms_over_l", "e/L RMS", "%", 100.0, 2,
                 "RMS over the point of e/L, e = camera minus point sensor at the beam"),
        Quantity("sensor_error_max_over_l", "|e|/L max", "%", 100.0, 2, "maximum over the point of |e|/L"),
        Quantity("sensor_error_mean_over_l", "|e|/L mean", "%", 100.0, 2, "time mean of |e|/L (paper fig. 5g)"),
        Quantity("sensor_error_std_over_l", "|e|/L std", "%", 100.0, 2, "standard deviation of |e|/L over time"),
        Quantity("cloud_distance_mean_over_l", "Delta_RMS/L mean", "%", 100.0, 2,
                 "time mean of the event-cloud distance Delta_RMS/L (/delta_rms of the centreline file)"),
        Quantity("cloud_distance_std_over_l", "Delta_RMS/L std", "%", 100.0, 2,
                 "standard deviation of Delta_RMS/L over the point's updates"),
        Quantity("event_rate_mev_s", "event rate", "Mev/s", 1.0, 3, "mean event rate of the camera"),
    )
}  # fmt: skip


def quantity(key: str) -> Quantity:
    """The :class:`Quantity` of ``key`` (an old key of :data:`POINT_ALIASES` too)."""
    return QUANTITIES[POINT_ALIASES.get(key, key)]


def show(key: str, value: float | None, *, with_label: bool = True) -> str:
    """``value`` (under ``key`` in the files) as a person reads it: ``e/L RMS 0.36 %``."""
    return quantity(key).text(value, with_label=with_label)
