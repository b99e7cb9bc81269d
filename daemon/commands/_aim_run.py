"""The parts of ``flagtrack aim`` that open things: the event source (a recording or the rig's camera),
the chain and grid to draw, the Rerun sink, and the loop that feeds the accumulator."""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flagtrack.daemon.core.aim import AimAccumulator, AimFrame
from flagtrack.daemon.core.aim_overlay import AimOverlays, chain_overlay, plane_grid
from flagtrack.daemon.core.chain import ChainParams
from flagtrack.daemon.core.events import empty_events
from flagtrack.daemon.errors import ConfigError, FormatError
from flagtrack.daemon.services.runner import StopEvent, stop_on_signals
from flagtrack.drivers.camera.base import Camera, CameraData, CameraInfo, EndOfStream
from flagtrack.drivers.formats.codec import Decoder, make_decoder
from flagtrack.drivers.formats.packets import decode_packet

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    from flagtrack.daemon.rig.config import RigConfig
    from flagtrack.daemon.services.viewer.config import ViewerConfig
    from flagtrack.daemon.tracking.section import TrackingConfig


@dataclass
class Source:
    """An opened camera (or replayed recording) and what to say about it.

    Attributes:
        camera: the adapter, opened.
        info: what it reported when opened.
        description: e.g. ``recording run.raw`` or ``camera cam0 (simulated)``.
        live: a camera (stops on the wall clock) rather than a recording (stops on camera time).
    """

    camera: Camera
    info: CameraInfo
    description: str
    live: bool


def check_input_file(path: Path, option: str) -> Path:
    """``path`` if it is an existing file, else ConfigError naming ``option``."""
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a folder, not a file")
    if not path.is_file():
        raise ConfigError(f"{option} {path}: no such file")
    return path


def open_source(
    rig: RigConfig | None, replay: Path | None, speed: float, sensor: tuple[int, int] | None = None
) -> Source:
    """Open ``replay`` (decoded, at ``speed``; 0: as fast as possible; ``sensor``: its size if the file
    does not say) or else the rig's camera."""
    from flagtrack.drivers.camera.replay import ReplayCamera, ReplayConfig
    from flagtrack.drivers.formats import open_events

    if replay is not None:
        with open_events(check_input_file(replay, "--replay")) as reader:
            sized = reader.info.width and reader.info.height
        if not sized and sensor is None:
            raise ConfigError(f"--replay {replay}: the recording does not give the sensor size: give --sensor W H")
        width, height = sensor if sensor is not None else (None, None)
        recording = ReplayCamera(ReplayConfig(replay, speed=speed, native=False, width=width, height=height))
        return Source(recording, recording.open(), f"recording {replay}", live=False)
    if rig is None:
        raise ConfigError("give a rig config (-c RIG.yaml) or a recording (--replay REC)")
    from flagtrack.daemon.rig.build import open_camera, open_hardware_camera

    cfg = rig.camera
    if cfg.adapter == "replay" and cfg.replay is not None:  # decoded: aim reads events, not bytes
        cfg = dataclasses.replace(cfg, replay=dataclasses.replace(cfg.replay, native=False))
    opened = open_hardware_camera(rig, check_root=False)  # (aim is where a wrong root is seen and fixed)
    if opened is not None:
        return Source(opened, opened.open(), f"camera {cfg.id} ({cfg.adapter})", live=True)
    camera = open_camera(cfg, rig_path=rig.path)
    return Source(camera, camera.open(), f"camera {cfg.id} ({cfg.adapter})", live=cfg.adapter != "replay")


class CameraEvents:
    """Decoded events of the camera's data, whatever form they come in (events, the device's bytes,
    or self-contained packets)."""

    def __init__(self, info: CameraInfo) -> None:
        self.info = info
        self._decoder: Decoder | None = None

    def __call__(self, data: CameraData) -> np.ndarray:
        pieces = [data.events] if len(data.events) else []
        if data.raw is not None:
            if self._decoder is None:
                self._decoder = make_decoder(
                    self.info.encoding, width=self.info.width, height=self.info.height,
                    t_offset_us=self.info.t_offset_us, strict=False, source=self.info.serial or "camera",
                )  # fmt: skip
            pieces.append(self._decoder.decode(data.raw)[0])
        for packet in data.packets or ():
            pieces.append(decode_packet(self.info.encoding, packet.data, packet.t_offset_us, source="camera packet")[0])
        if not pieces:
            return empty_events()
        return pieces[0] if len(pieces) == 1 else np.concatenate(pieces)


def overlays_for(tracker: TrackingConfig, info: CameraInfo, config_path: str | None) -> tuple[AimOverlays, Any]:
    """The chain (if the ``tracker:`` section or the options give a root and a length) and the
    calibration's grid (if it names one), in pixels; and the calibration's mapping (or None)."""
    mapping = None
    if tracker.calibration is not None:
        from flagtrack.calibration.calfile import load_mapping

        check_input_file(Path(tracker.calibration), "tracker.calibration")
        mapping = load_mapping(tracker.calibration)
        if tuple(mapping.image_size) != (info.width, info.height):
            log.warning(
                "the calibration %s was made on a %dx%d image, the camera gives %dx%d: its grid and the "
                "chain may be drawn in the wrong place", tracker.calibration, *mapping.image_size, info.width, info.height,
            )  # fmt: skip
    units = "px" if mapping is None else mapping.units
    chain = None
    if tracker.root is not None and tracker.length is not None:
        try:
            params = ChainParams(
                root=(float(tracker.root[0]), float(tracker.root[1])),
                length=float(tracker.length),
                n_joints=tracker.joints,
                direction_deg=tracker.direction_deg,
                link_lengths=tracker.link_lengths,
                alpha=tracker.alpha,
                angle_limit_deg=tracker.angle_limit_deg,
            )
        except ValueError as exc:
            raise ConfigError(str(exc), key="tracker", path=config_path) from exc
        chain = chain_overlay(params, mapping)
    grid = plane_grid(mapping, info.width, info.height) if mapping is not None else None
    return AimOverlays(chain=chain, grid=grid, units=units), mapping


def has_display() -> bool:
    """Whether a window can be shown (X11 or Wayland)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def rerun_config(base: ViewerConfig, rrd: Path | None, sink: str | None, headless_use: bool) -> ViewerConfig | None:
    """The viewer section aim's Rerun view goes to, or None for no Rerun at all.

    ``--rrd FILE`` writes a file; ``--viewer SINK`` is taken as it is; otherwise a snapshot or JSON
    run has none, and the rig's sink is used (``rrd`` and ``auto`` become a window where a display
    exists, else none: aim never writes the rig's own .rrd file).
    """
    if rrd is not None:
        return dataclasses.replace(base, sink="rrd", rrd_path=rrd)
    chosen = sink or ("none" if headless_use else base.sink)
    if chosen in ("auto", "rrd"):
        chosen = "spawn" if has_display() else "none"
    return None if chosen == "none" else dataclasses.replace(base, sink=chosen)  # type: ignore[arg-type]  # one of the sinks


@dataclass(frozen=True)
class Cadence:
    """When to stop and how often to draw.

    Attributes:
        duration_s: stop after this long (a camera: wall clock; a recording: camera time); None: never.
        frame_s: draw a frame every this much camera time (None: only at the end).
        status_s: call the status callback every this much camera time (None: never).
    """

    duration_s: float | None = None
    frame_s: float | None = None
    status_s: float | None = None


class _Drawing:
    """Frames and status lines when their camera time comes (a frame at once, the first status line
    ``status_s`` after the first data); the latest frame is kept for the next that is due."""

    def __init__(self, cadence: Cadence, on_frame: Callable[[AimFrame], None] | None,
                 on_status: Callable[[AimFrame], None] | None) -> None:  # fmt: skip
        self.frame_s = cadence.frame_s if on_frame is not None else None
        self.status_s = cadence.status_s if on_status is not None else None
        self.on_frame, self.on_status = on_frame, on_status
        self.next_frame, self.next_status = -math.inf, math.inf
        self.latest: AimFrame | None = None

    def __call__(self, acc: AimAccumulator) -> None:
        t_s = (acc.t_end_us or 0) * 1e-6
        if self.status_s is not None and self.next_status == math.inf:
            self.next_status = t_s + self.status_s
        if self.frame_s is not None and self.on_frame is not None and t_s >= self.next_frame:
            self.on_frame(self.frame(acc))
            self.next_frame = t_s + self.frame_s
        if self.status_s is not None and self.on_status is not None and t_s >= self.next_status:
            self.on_status(self.frame(acc))
            self.next_status = t_s + self.status_s

    def frame(self, acc: AimAccumulator) -> AimFrame:
        """The frame of now (the latest one if nothing came since)."""
        if self.latest is None or self.latest.t_end_us != acc.t_end_us:
            self.latest = acc.frame()
        return self.latest


def feed(
    source: Source,
    acc: AimAccumulator,
    cadence: Cadence,
    on_frame: Callable[[AimFrame], None] | None = None,
    on_status: Callable[[AimFrame], None] | None = None,
) -> AimFrame:
    """Feed the source's events to ``acc`` until the recording ends, ``duration_s`` has passed or
    Ctrl-C; draw frames and status on the way; return the last frame."""
    events_of = CameraEvents(source.info)
    draw = _Drawing(cadence, on_frame, on_status)
    wall0: float | None = None  # a camera's duration counts from its first answer taken in (the first
    # read or decode may compile)
    # the first Ctrl-C (or SIGTERM) ends the run after the step under way (a kernel compile is never
    # cut in the middle): the last frame is still drawn
    try:
        with stop_on_signals(StopEvent()) as stop:
            while not stop.is_set() and (
                cadence.duration_s is None or not _elapsed(source, acc, wall0, cadence.duration_s)
            ):
                try:
                    data = source.camera.read(0.1)
                except EndOfStream:
                    break
                if data is not None:
                    try:
                        acc.push(events_of(data), data.t_until_us)
                    except FormatError as exc:
                        raise FormatError(f"{source.description}: {exc}") from exc
                    draw(acc)
                wall0 = time.monotonic() if wall0 is None else wall0
    finally:
        source.camera.close()
    return draw.frame(acc)


def _elapsed(source: Source, acc: AimAccumulator, wall0: float | None, duration_s: float) -> bool:
    if source.live:
        return wall0 is not None and time.monotonic() - wall0 >= duration_s
    return (
        acc.t_first_us is not None and acc.t_end_us is not None and (acc.t_end_us - acc.t_first_us) >= duration_s * 1e6
    )
