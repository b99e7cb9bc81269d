"""``flagtrack bench geometry``: how well ``flagtrack geometry`` finds a flag's root, rest direction
and length, on simulated recordings whose truth is known.

The grid (drawn from ``--seed``, the same every run): VGA and HD sensors; any root and rest
direction (the flag and its motion inside the sensor); lengths from 30 to 55 % of the sensor's
short side; small (2A/L 0.085-0.2) and larger (0.2-1.05) amplitudes of the paper's kinematics
family; a flag tapped by hand (its motion dying out over two periods); shot noise of 0, 1 and
5 Hz per pixel; hot pixels at 1-5 kHz, two of them just behind the root and just beyond the tip;
and the paper's tilted camera with its exact plane mapping (a calibration that is not a similarity).
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # numpy is imported where it is used: `flagtrack bench --help` stays cheap
    import numpy as np

COMMAND = "geometry"
HELP = "accuracy of `flagtrack geometry` (root, direction, length) on simulated recordings"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Grid size, seed, duration, output."""
    add_grid_arguments(parser)
    parser.set_defaults(run=run)


def add_grid_arguments(parser: argparse.ArgumentParser) -> None:
    """The grid's size, seed and duration, the processes, --json (also ``bench reach``'s)."""
    parser.add_argument("--n", type=int, default=36, help="recordings in the grid (default 36)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the grid (default 0)")
    parser.add_argument("--duration", type=float, default=0.3, help="seconds per recording (default 0.3)")
    parser.add_argument("--jobs", type=int, default=1, help="processes (default 1)")
    parser.add_argument("--json", action="store_true", help="print one JSON object (cases and summary)")


@dataclass(frozen=True)
class Case:
    """One simulated recording of the grid."""

    seed: int
    width: int
    height: int
    root: tuple[float, float]
    direction_deg: float
    length: float
    peak_to_peak: tuple[float, float]
    shot_noise_hz: float
    hot_pixels: int
    tilted: bool
    tapped: bool
    duration_s: float


def plan(n: int, seed: int, duration_s: float) -> list[Case]:
    """The grid: ``n`` cases drawn from ``seed``."""
    import numpy as np

    cases = []
    for i in range(n):
        rng = np.random.default_rng([seed, i])
        width, height = (640, 480) if i % 2 == 0 else (1280, 720)
        tilted = i % 6 == 5
        small = i % 3 == 0
        ptp = (0.085, 0.2) if small else (0.2, 1.05)
        if tilted:
            length, direction = float(rng.uniform(0.15, 0.19)), float(rng.uniform(-25, 25))
            root = (float(rng.uniform(-0.01, 0.02)), float(rng.uniform(-0.02, 0.02)))
        else:
            length = float(rng.uniform(0.3, 0.55) * min(width, height))
            direction = float(rng.uniform(0.0, 360.0))
            root = _free_root(rng, width, height, length, direction)
        cases.append(
            Case(
                seed=seed * 1000 + i,
                width=width,
                height=height,
                root=root,
                direction_deg=direction,
                length=length,
                peak_to_peak=ptp,
                shot_noise_hz=(0.0, 1.0, 5.0)[(i // 3) % 3],
                hot_pixels=5 if i % 4 == 1 else 0,
                tilted=tilted,
                tapped=i % 6 == 3,
                duration_s=duration_s,
            )
        )
    return cases


def _free_root(rng: np.random.Generator, width: int, height: int, length: float, direction_deg: float) -> tuple:
    """A root that keeps the flag's reach (L along the axis, 0.55 L either side) 8 px inside the sensor."""
    import numpy as np

    d = math.radians(direction_deg)
    along, across = np.array([math.cos(d), math.sin(d)]), np.array([-math.sin(d), math.cos(d)])
    corners = np.array([a * length * along + b * 0.55 * length * across for a in (0, 1) for b in (-1, 1)])
    lo, hi = -corners.min(axis=0) + 8, np.array([width, height]) - 1 - corners.max(axis=0) - 8
    return (float(rng.uniform(lo[0], hi[0])), float(rng.uniform(lo[1], hi[1])))


@dataclass(frozen=True)
class TappedFlag:
    """A flag tapped once: the kinematics' motion dying out as exp(-t / tau_s)."""

    base: Any
    tau_s: float

    @property
    def length(self) -> float:
        return float(self.base.length)

    @property
    def frequency_hz(self) -> float:
        return float(self.base.frequency_hz)

    def positions_at_phase(self, phase_rad: np.ndarray, s: np.ndarray, amp_scale: float = 1.0) -> tuple:
        return self.base.positions_at_phase(phase_rad, s, amp_scale)

    def positions(self, t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        import numpy as np

        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        rows = [
            self.base.positions_at_phase(self.base.phase(t[i : i + 1]), s, math.exp(-t[i] / self.tau_s))
            for i in range(len(t))
        ]
        return np.concatenate([r[0] for r in rows]), np.concatenate([r[1] for r in rows])


def simulate(case: Case) -> tuple[np.ndarray, Any]:
    """The case's events (time-ordered) and the plane -> pixel optics."""
    import numpy as np

    from flagtrack.drivers.sim.dvs import DvsParams
    from flagtrack.drivers.sim.kinematics import KinematicsFamily, sample_kinematics
    from flagtrack.drivers.sim.optics import PlaneCamera, tilted_pinhole
    from flagtrack.drivers.sim.render import LaserLineScene
    from flagtrack.drivers.sim.scenes import simulate_events

    family = replace(KinematicsFamily(), peak_to_peak_over_l=case.peak_to_peak)
    kin: Any = sample_kinematics(case.seed, family, case.length, case.root, case.direction_deg)
    if case.tapped:
        kin = TappedFlag(kin, 2.0 / kin.frequency_hz)
    if case.tilted:
        optics = tilted_pinhole(case.width, case.height)
    else:
        optics = PlaneCamera(centre_px=(case.width / 2 - 0.5, case.height / 2 - 0.5))
    scene = LaserLineScene(kin, optics, case.width, case.height)
    dvs = DvsParams(shot_noise_hz=case.shot_noise_hz)
    events = np.concatenate(list(simulate_events(scene, 0, int(case.duration_s * 1e6), dvs, seed=case.seed)))
    return _with_hot_pixels(events, case, optics), optics


def _with_hot_pixels(events: np.ndarray, case: Case, optics: Any) -> np.ndarray:
    """``events`` plus ``case.hot_pixels`` pixels firing at 1-5 kHz: one just behind the root, one
    just beyond the tip, the others in the flag's reach."""
    import numpy as np

    if case.hot_pixels == 0:
        return events
    rng = np.random.default_rng([case.seed, 7])
    d = math.radians(case.direction_deg)
    axis = np.array([math.cos(d), math.sin(d)])
    spots = [np.array(case.root) - 0.04 * case.length * axis, np.array(case.root) + 1.04 * case.length * axis]
    spots += [np.array(case.root) + rng.uniform(0.1, 0.9) * case.length * axis for _ in range(case.hot_pixels - 2)]
    parts = [events]
    for spot in spots:
        px, py = optics.project(np.array([spot[0]]), np.array([spot[1]]))
        x, y = (
            int(np.clip(round(float(px[0])), 0, case.width - 1)),
            int(np.clip(round(float(py[0])), 0, case.height - 1)),
        )
        n = rng.poisson(rng.uniform(1000, 5000) * case.duration_s)
        hot = np.zeros(n, dtype=events.dtype)
        hot["t"], hot["x"], hot["y"], hot["p"] = np.sort(rng.integers(0, int(case.duration_s * 1e6), n)), x, y, 1
        parts.append(hot)
    merged = np.concatenate(parts)
    return merged[np.argsort(merged["t"], kind="stable")]


class _Unproject:
    """The tilted optics' exact pixel -> plane map (a perfect calibration, in metres)."""

    units = "m"

    def __init__(self, optics: Any) -> None:
        self.optics = optics

    def map(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        import numpy as np

        return self.optics.unproject(np.asarray(x_px, dtype=np.float64), np.asarray(y_px, dtype=np.float64))


def evaluate(case: Case) -> dict[str, Any]:
    """Simulate ``case``, find its geometry, compare with the truth."""
    from flagtrack.daemon.core.geometry import NoFlagError, find_geometry

    events, optics = simulate(case)
    row: dict[str, Any] = {**asdict(case), "events": len(events)}
    try:
        found = find_geometry(events, (case.width, case.height), _Unproject(optics) if case.tilted else None)
    except NoFlagError as exc:
        return {**row, "error": str(exc)}
    turn = (found.direction_deg - case.direction_deg + 180.0) % 360.0 - 180.0
    miss = math.hypot(found.root[0] - case.root[0], found.root[1] - case.root[1])
    return {
        **row,
        "root_error_over_l": miss / case.length,
        "direction_error_deg": turn,
        "length_error_pct": 100.0 * (found.length / case.length - 1.0),
        "root_gap_over_l": found.root_gap / case.length,
        "warnings": found.warnings(),
    }


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Max and 95th percentile of each error's magnitude over the rows that found a flag."""
    import numpy as np

    found = [r for r in rows if "error" not in r]
    out: dict[str, Any] = {"recordings": len(rows), "found": len(found)}
    for key in ("root_error_over_l", "direction_error_deg", "length_error_pct"):
        values = np.abs([r[key] for r in found]) if found else np.array([np.nan])
        out[key] = {
            "max": float(np.max(values)),
            "p95": float(np.percentile(values, 95)),
            "median": float(np.median(values)),
        }
    return out


def evaluate_grid(args: argparse.Namespace, evaluate: Callable[[Case], dict[str, Any]]) -> list[dict[str, Any]]:
    """``evaluate`` on every case of the grid the arguments name, on ``--jobs`` processes."""
    cases = plan(args.n, args.seed, args.duration)
    if args.jobs <= 1:
        return [evaluate(case) for case in cases]
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        return list(pool.map(evaluate, cases))


def run(args: argparse.Namespace) -> int:
    """Simulate the grid, evaluate each recording, print the figures."""
    rows = evaluate_grid(args, evaluate)
    figures = summary(rows)
    if args.json:
        print(json.dumps({"summary": figures, "cases": rows}))
        return 0
    for r in rows:
        what = f"{r['width']}x{r['height']} dir {r['direction_deg']:6.1f} L {r['length']:7.3f}"
        what += f" 2A/L {r['peak_to_peak'][0]:.2f}-{r['peak_to_peak'][1]:.2f} noise {r['shot_noise_hz']:.0f} Hz"
        what += f" hot {r['hot_pixels']}" + (" tilted" if r["tilted"] else "") + (" tapped" if r["tapped"] else "")
        if "error" in r:
            print(f"{what}: {r['error']}")
        else:
            print(
                f"{what}: root {100 * r['root_error_over_l']:5.2f} % L, direction {r['direction_error_deg']:+6.2f} deg, "
                f"length {r['length_error_pct']:+6.2f} %"
            )
    print(f"{figures['found']} of {figures['recordings']} recordings found")
    for key, unit in (("root_error_over_l", "L"), ("direction_error_deg", "deg"), ("length_error_pct", "%")):
        f = figures[key]
        scale = 100.0 if unit == "L" else 1.0
        name = "root error / L (%)" if unit == "L" else key
        print(f"{name}: median {scale * f['median']:.3f}, p95 {scale * f['p95']:.3f}, max {scale * f['max']:.3f}")
    return 0
