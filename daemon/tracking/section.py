"""The ``tracker:`` section of a flagtrack config: every parameter of the centreline tracker.

Shared by ``flagtrack reconstruct -c`` and the live tracker service. Lengths are in the events'
units (pixels, or metres with a calibration), angles in degrees from +x towards +y, times in
seconds on the recording's clock. Defaults are the paper's (N_j = 10, alpha = 0.6, ds = L/50,
dt = tau) and, for the robust method, the measured ones of docs/tracking.md.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flagtrack.daemon.core.denoise_params import DenoiseParams
from flagtrack.daemon.core.lost_params import LostParams
from flagtrack.daemon.core.windows import WindowSegment
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.typed_yaml import from_mapping, load_yaml, to_mapping

SECTION = "tracker"


class Method(enum.Enum):
    """``paper``: the update as published; ``robust``: denoised, refined arcs, minimum evidence."""

    ROBUST = "robust"
    PAPER = "paper"


@dataclass(frozen=True)
class DenoiseSection(DenoiseParams):
    """The ``denoise:`` section: the core filter's parameters (:class:`DenoiseParams`, defined there
    once) and whether the robust method filters at all (``enabled``)."""

    enabled: bool = True


ROBUST_DENOISE = DenoiseSection(max_neighbours=3, max_window_us=50_000)
"""The robust method's filter: adaptive, 1 to 3 supporting neighbours (measured in docs/benchmark.md;
``max_neighbours: 1`` is the classic filter, the core's default)."""


@dataclass(frozen=True)
class LostSection(LostParams):
    """The ``lost:`` section: loss-of-track detection and re-acquisition (:class:`LostParams`, defined
    there once) and whether the robust method detects at all (``enabled``)."""

    enabled: bool = True


@dataclass(frozen=True)
class TrackingConfig:
    """Parameters of a reconstruction (YAML section ``tracker:``).

    Attributes:
        root: (x, y) of the flag's fixed root; required.
        length: flag length L; required.
        direction_deg: rest direction of the flag (the initial straight chain).
        joints: number of links N_j.
        link_lengths: N_j link lengths summing to ``length`` (default equal).
        alpha: search radius parameter.
        angle_limit_deg: half-angle of each search arc around the link's previous direction.
        tau_s: update interval (window length).
        dt_s: time increment between updates (default ``tau_s``).
        schedule: optional segments changing dt and tau along the recording (override tau_s/dt_s).
        ds: step of the smoothed centreline (default L / 50).
        method: ``robust`` or ``paper`` (the paper's update: no denoising, no refining, any event).
        min_events: robust method: fewest events in an arc that move its link.
        refine_deg: robust method: half-angle of the refining arc around the first mean.
        denoise: robust method: background-activity filter.
        lost: robust method: loss-of-track detection and re-acquisition (``/lost`` of the files).
        t_start_s: first update time (default: first event + tau/2).
        t_stop_s: last update time (default: end of the events).
        max_gap_s: windows without events starting more than this after the last event are not
            written (null: every window).
        calibration: file of a pixel -> metre mapping (flagtrack.calibration); None: pixels.
        max_lag_ms: the live tracker's latency budget: packets whose updates it could not publish
            within this of their arrival at the camera are shed, whole, before decoding (their
            windows are gaps, the updates after them carry ``shed``; the recorder keeps every byte);
            null: track every packet however late. Not applied to a replay as fast as possible
            (``speed: 0``), nor offline. See docs/live.md.
    """

    root: tuple[float, float] | None = None
    length: float | None = None
    direction_deg: float = 0.0
    joints: int = 10
    link_lengths: tuple[float, ...] | None = None
    alpha: float = 0.6
    angle_limit_deg: float = 60.0
    tau_s: float = 2.5e-4
    dt_s: float | None = None
    schedule: tuple[WindowSegment, ...] = ()
    ds: float | None = None
    method: Method = Method.ROBUST
    min_events: int = 5
    refine_deg: float = 10.0
    denoise: DenoiseSection = ROBUST_DENOISE
    lost: LostSection = LostSection()
    t_start_s: float | None = None
    t_stop_s: float | None = None
    max_gap_s: float | None = 1.0
    calibration: Path | None = None
    max_lag_ms: float | None = 50.0

    def with_overrides(self, **values: Any) -> TrackingConfig:
        """A copy with the given (non-None) values replaced, e.g. from command-line flags."""
        return dataclasses.replace(self, **{k: v for k, v in values.items() if v is not None})

    def tracker_params(self, *, path: str | None = None) -> Any:
        """The core's :class:`~flagtrack.daemon.core.tracker.TrackerParams` (imports numba).

        Raises:
            ConfigError: a required value is missing or a value is out of range (names the key).
        """
        from flagtrack.daemon.core.chain import ChainParams
        from flagtrack.daemon.core.tracker import TrackerParams
        from flagtrack.daemon.core.windows import WindowSchedule
        from flagtrack.daemon.tracking.checks import check_tracking_config

        for name in ("root", "length"):
            if getattr(self, name) is None:
                raise ConfigError(
                    "required (give it in the config or on the command line)", key=f"{SECTION}.{name}", path=path
                )
        check_tracking_config(self, path=path)
        paper = self.method is Method.PAPER
        chain = _build(
            ChainParams,
            path,
            "",
            root=self.root,
            length=self.length,
            n_joints=self.joints,
            direction_deg=self.direction_deg,
            link_lengths=self.link_lengths,
            alpha=self.alpha,
            angle_limit_deg=self.angle_limit_deg,
            min_events=1 if paper else self.min_events,
            refine_deg=None if paper else self.refine_deg,
        )
        segments = self.schedule or (
            _build(WindowSegment, path, "schedule[0]", t_from_s=0.0, dt_s=self.dt_s or self.tau_s, tau_s=self.tau_s),
        )
        schedule = _build(
            WindowSchedule, path, "schedule", segments=tuple(segments), t_start_s=self.t_start_s, t_stop_s=self.t_stop_s
        )
        denoise = self.denoise if not paper and self.denoise.enabled else None
        if self.ds is not None and not self.ds > 0:
            raise ConfigError(f"must be positive, got {self.ds}", key=f"{SECTION}.ds", path=path)
        if self.max_gap_s is not None and not self.max_gap_s > 0:
            raise ConfigError(f"must be positive, got {self.max_gap_s}", key=f"{SECTION}.max_gap_s", path=path)
        if self.max_lag_ms is not None and not 0 < self.max_lag_ms < float("inf"):
            raise ConfigError(f"must be positive, got {self.max_lag_ms}", key=f"{SECTION}.max_lag_ms", path=path)
        fields = {f.name: getattr(self.lost, f.name) for f in dataclasses.fields(LostParams)}
        checked = _build(LostParams, path, "lost", **fields)
        lost = checked if not paper and self.lost.enabled else None
        return TrackerParams(
            chain=chain,
            schedule=schedule,
            ds=self.ds,
            denoise=denoise,
            max_gap_s=self.max_gap_s,
            lost=lost,
            stale_after_s=checked.stale_after_s,
        )

    def attrs(self) -> dict[str, Any]:
        """Every processing parameter as flat HDF5-friendly attributes (effective values).

        ``dt_s``/``tau_s`` are those of the first schedule segment; ``schedule_t_from_s``,
        ``schedule_dt_s`` and ``schedule_tau_s`` list every segment as numbers (MATLAB reads them
        as vectors). ``link_lengths`` are the effective lengths (equal ones by default); ``s_step``
        is the step of ``/s`` (``ds``, or a little less where ``L / ds`` is not a whole number).
        """
        from flagtrack.daemon.core.smoothing import REL_TOL, n_samples

        paper = self.method is Method.PAPER
        values = to_mapping(self)
        denoise = values.pop("denoise")
        values.update({f"denoise_{k}": v for k, v in denoise.items()})
        values["denoise_neighbourhood"] = "3x3 without the event's own pixel"
        lost = values.pop("lost")
        values.update({f"lost_{k}": v for k, v in lost.items()})
        if paper:
            values.update(min_events=1, refine_deg=None, denoise_enabled=False, lost_enabled=False)
        segments = [(seg.t_from_s, seg.dt_s, seg.tau_s) for seg in self.schedule]
        segments = segments or [(0.0, self.dt_s or self.tau_s, self.tau_s)]
        values["dt_s"], values["tau_s"] = segments[0][1], segments[0][2]
        values["schedule"] = [to_mapping(seg) for seg in self.schedule]
        for i, name in enumerate(("t_from_s", "dt_s", "tau_s")):
            values[f"schedule_{name}"] = [float(seg[i]) for seg in segments]
        length = self.length or 0.0
        values["ds"] = self.ds if self.ds is not None else length / 50
        if length > 0 and values["ds"] > 0:  # the step of /s: L / (ceil(L / ds)), at most ds
            values["s_step"] = length / (n_samples(length, values["ds"]) - 1)
        if self.link_lengths is None and self.length is not None and self.joints > 0:
            values["link_lengths"] = [self.length / self.joints] * self.joints
        values["rel_tol"] = REL_TOL
        return values


def _build(cls: type, path: str | None, key: str, **values: Any) -> Any:
    """Construct a core dataclass, turning its ValueError into a ConfigError naming the key."""
    try:
        return cls(**values)
    except (ValueError, TypeError) as exc:
        raise ConfigError(str(exc), key=f"{SECTION}.{key}".rstrip("."), path=path) from exc


def load_tracking_config(path: str | Path) -> TrackingConfig:
    """Read the ``tracker:`` section of a YAML file (other sections are ignored; none: the defaults).

    Raises:
        ConfigError: a bad key in the section; no section but a top-level key spelt nearly so, or
            the file is a calibration.
    """
    data = load_yaml(path)
    if SECTION not in data:
        from flagtrack.calibration.calfile import FORMAT as CALIBRATION_FORMAT

        if data.get("format") == CALIBRATION_FORMAT:
            raise ConfigError("a calibration file, not a config with a 'tracker:' section", path=str(path))
        near = difflib.get_close_matches(SECTION, [str(k) for k in data], n=1, cutoff=0.8)
        if near:
            raise ConfigError(f"unknown key (did you mean '{SECTION}'?)", key=near[0], path=str(path))
    return from_mapping(TrackingConfig, data.get(SECTION), path=str(path), key=SECTION)
