"""What the accuracy benchmark runs: presets, tracking methods, and one task per simulated recording.

Parts (Raynaud & Mulleners 2024, section 3):

- ``family``: N kinematics of the family, 3-6 periods each, clean, at the paper's parameters
  (N_j = 10, tau/T = 5e-3, dt = tau, alpha = 0.6);
- ``leak``: a few kinematics (the first ones of the family) for ``cycles`` periods at leak rates
  f_lr/f;
- ``shot``: the same kinematics at shot-noise levels given as the paper's f_snr/f; the paper's
  N_evs/N_evs,0 grows linearly, reaching 2 at f_snr/f = 37, so level x adds x/37 N_evs,0 noise events
  (our per-pixel rate is derived from the clean recording's event count);
- ``params``: N_j and tau sweeps on the clean recording and on the noisy one at f_snr/f = 20 (fig. 6);
- ``lost``: each sweep kinematics through occlusions, crossing objects, reflections and a chain
  started 90 degrees off (issue 19, :mod:`.disruptions`).

Seeds derive from the benchmark seed alone, so results do not depend on ``--jobs`` or on the order
in which tasks finish.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

PAPER_NOISE_PER_LEVEL = 1.0 / 37.0
"""Noise events per clean event added per unit of the paper's f_snr/f (N/N0 = 2 at f_snr/f = 37)."""

START_ON_TRUTH = True
"""Every reconstruction starts from the chain through the truth's first centreline (the paper does not
say how its chains start; from a straight chain, a noisy stream can lose the paper's update in the
first windows, before any tracking, which would hide how long it keeps the flag)."""

SETTLE_PERIODS = 0.0
"""Errors are measured from this many periods on (0: from the first update)."""

LOSS_THRESHOLD = 0.1
"""t_loss: first time the tip error delta(t)/L exceeds this (paper, section 3.1)."""

PAPER_TAU_OVER_T = 5e-3
PAPER_JOINTS = 10

METHODS: dict[str, dict[str, Any]] = {
    "paper": {"method": "paper"},
    "robust-classic": {"method": "robust", "denoise": {"max_neighbours": 1}},
    "robust": {"method": "robust"},
}
"""Tracking methods compared: the paper's update; the robust method with the classic one-neighbour
filter (before this benchmark); the robust default with the adaptive filter (ours)."""


@dataclass(frozen=True)
class Preset:
    """Sizes of a benchmark run.

    Attributes:
        n_family: kinematics of part (a).
        n_sweep: kinematics of parts (b)-(d).
        cycles: flapping periods of each sweep recording.
        leak_levels: f_lr/f of part (b) (0 is the clean recording).
        shot_levels: the paper's f_snr/f of part (c) (0 is the clean recording; 20 is also fig. 6's).
        joints: N_j of part (d).
        tau_over_t: tau/T of part (d).
        width, height: sensor size (the flag is 300 px on 640 x 480, scaled with the sensor).
    """

    n_family: int = 400
    n_sweep: int = 4
    cycles: float = 10.0
    leak_levels: tuple[float, ...] = (0.3, 0.6, 1.2, 1.6, 2.4, 3.6, 4.8)
    shot_levels: tuple[float, ...] = (10.0, 20.0, 35.0, 50.0, 70.0, 100.0, 140.0)
    joints: tuple[int, ...] = (3, 4, 6, 8, 10, 15, 20, 30)
    tau_over_t: tuple[float, ...] = (2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2)
    width: int = 640
    height: int = 480


PRESETS: dict[str, Preset] = {
    "full": Preset(),
    "quick": Preset(
        n_family=24,
        n_sweep=2,
        cycles=4.0,
        leak_levels=(0.6, 1.2, 2.4, 3.6),
        shot_levels=(10.0, 20.0, 35.0, 70.0),
        joints=(4, 6, 10, 20),
        tau_over_t=(2e-4, 1e-3, 5e-3, 2e-2),
    ),
}


@dataclass(frozen=True)
class Variant:
    """One tracking run of a recording."""

    method: str
    joints: int = PAPER_JOINTS
    tau_over_t: float = PAPER_TAU_OVER_T


@dataclass(frozen=True)
class Task:
    """One simulated recording and the tracking runs made on it.

    Attributes:
        name: file stem, unique in the run.
        part: ``family``, ``clean`` (sweep kinematics without defects), ``leak`` or ``shot``.
        kinematics: index of the kinematics in the family (seed = family seed of that index).
        seed: recording seed (draws the kinematics, thresholds and noise).
        level: leak f_lr/f or the paper's f_snr/f (0 for clean recordings).
        cycles: duration in periods; ``None``: 3-6 periods drawn from the seed.
        leak_over_f: leak rate over the flapping frequency.
        shot_noise_hz: shot noise per pixel (computed from the clean recording's events).
        variants: tracking runs.
        width, height: sensor size.
    """

    name: str
    part: str
    kinematics: int
    seed: int
    level: float = 0.0
    cycles: float | None = None
    leak_over_f: float = 0.0
    shot_noise_hz: float = 0.0
    variants: tuple[Variant, ...] = field(default_factory=tuple)
    width: int = 640
    height: int = 480


def level_tag(level: float) -> str:
    """A level as a file-name part without dots (``1.6`` -> ``1p6``: a dot would read as a suffix)."""
    return f"{level:g}".replace(".", "p").replace("-", "m")


def kinematics_seed(seed: int, index: int) -> int:
    """Seed of kinematics ``index`` of a benchmark run with seed ``seed``."""
    return seed * 100_000 + index


def paper_variants(methods: tuple[str, ...]) -> tuple[Variant, ...]:
    """The paper's parameters for each method."""
    return tuple(Variant(m) for m in methods)


def param_variants(methods: tuple[str, ...], preset: Preset) -> tuple[Variant, ...]:
    """Part (d): every N_j at tau/T = 5e-3 and every tau/T at N_j = 10, for each method."""
    out = [Variant(m, joints=j) for m in methods for j in preset.joints]
    out += [Variant(m, tau_over_t=r) for m in methods for r in preset.tau_over_t if r != PAPER_TAU_OVER_T]
    return tuple(dict.fromkeys(out + list(paper_variants(methods))))


def family_tasks(seed: int, preset: Preset, methods: tuple[str, ...]) -> list[Task]:
    """Part (a): one clean recording of 3-6 periods per kinematics."""
    return [
        Task(
            f"family_{i:04d}",
            "family",
            i,
            kinematics_seed(seed, i),
            variants=paper_variants(methods),
            width=preset.width,
            height=preset.height,
        )
        for i in range(preset.n_family)
    ]


def sweep_clean_tasks(seed: int, preset: Preset, methods: tuple[str, ...], params: bool) -> list[Task]:
    """The clean recordings of the sweep kinematics (level 0 of (b) and (c), clean curves of (d))."""
    variants = param_variants(methods, preset) if params else paper_variants(methods)
    return [
        Task(
            f"clean_{k:02d}",
            "clean",
            k,
            kinematics_seed(seed, k),
            cycles=preset.cycles,
            variants=variants,
            width=preset.width,
            height=preset.height,
        )
        for k in range(preset.n_sweep)
    ]


def lost_tasks(seed: int, preset: Preset, methods: tuple[str, ...]) -> list[Task]:
    """Part ``lost``: one recording per sweep kinematics (its scenarios are applied to its events)."""
    return [
        Task(
            f"lost_{k:02d}",
            "lost",
            k,
            kinematics_seed(seed, k),
            cycles=preset.cycles,
            variants=paper_variants(methods),
            width=preset.width,
            height=preset.height,
        )
        for k in range(preset.n_sweep)
    ]


def leak_tasks(clean: list[Task], preset: Preset, methods: tuple[str, ...]) -> list[Task]:
    """Part (b): each sweep kinematics at each leak level (same seed as its clean recording)."""
    return [
        replace(
            task,
            name=f"leak_{task.kinematics:02d}_{level_tag(level)}",
            part="leak",
            level=level,
            leak_over_f=level,
            variants=paper_variants(methods),
        )
        for task in clean
        for level in preset.leak_levels
    ]


def shot_tasks(
    task: Task, clean_events: int, duration_s: float, preset: Preset, methods: tuple[str, ...], params: bool
) -> list[Task]:
    """Part (c) for one kinematics, from its clean recording's event count N_evs,0."""
    out = []
    pixels = task.width * task.height
    for level in preset.shot_levels:
        rate = level * PAPER_NOISE_PER_LEVEL * clean_events / (duration_s * pixels)
        variants = param_variants(methods, preset) if params and level == 20.0 else paper_variants(methods)
        out.append(
            replace(
                task,
                name=f"shot_{task.kinematics:02d}_{level_tag(level)}",
                part="shot",
                level=level,
                shot_noise_hz=rate,
                variants=variants,
            )
        )
    return out
