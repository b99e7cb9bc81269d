"""Every message type on the bus (the key expressions are :mod:`.keys`', the encoding :mod:`.codec`'s)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch


class MessageType(enum.IntEnum):
    """Type byte of each message on the wire."""

    EVENT_PACKET = 1
    CAMERA_STATUS = 2
    EVENT_RATE = 3
    CENTRELINES = 4
    TRACKER_STATUS = 5
    TUNNEL_STATE = 6
    TUNNEL_COMMAND = 7
    SUPERVISOR_STATE = 8
    RECORDER_COMMAND = 9
    RECORDER_STATUS = 10
    SENSOR_SAMPLES = 11
    FLAG_STATE = 12
    SPEED_REQUEST = 13
    SPEED_REPLY = 14


@dataclass(frozen=True)
class EventPacket:
    """About 1 ms of one camera's events in its native encoding (EVT 3.0 / 2.0 bytes).

    Every packet decodes alone (it starts with the stream's time base), and the packets of a
    stream concatenate into one valid stream (what the recorder writes). ``t_offset_us`` is the
    stream's encoder offset (a whole number of the encoding's time loops) added back on decoding.
    ``sent_ns`` is the wall-clock time (ns) at which the adapter received the data, for latency.
    ``t_last_us`` is the completeness horizon: every event with ``t <= t_last_us`` is in this packet
    or an earlier one (an empty packet carries it forward while the scene is still).
    ``end_of_stream`` marks the last packet of a stream (end of a replayed file). ``stream_id``
    names the stream (drawn when the camera service starts; 0 from older peers): packets of
    another id are a restarted camera, a lower ``seq`` with the same id a duplicate or late packet.
    ``native``: ``data`` is the camera's own words (cut, not re-encoded), after ``preamble_bytes`` of
    state words that make the packet decode alone (a recorder leaves them out; older peers: 0, False).
    ``device_drops`` counts the drops the camera or its driver reported in this stream so far (a
    full host ring, a cleared backlog, a simulated camera's skip ahead), this packet's included;
    the packet right after a drop says what was lost just before it: ``drop_count`` of ``drop_unit``
    (``usb_packets``, ``us``, ``words``; 0: unknown) and why (``drop_reason``). Older peers: 0, "".
    """

    TYPE: ClassVar[MessageType] = MessageType.EVENT_PACKET
    camera_id: str
    seq: int
    t_first_us: int
    t_last_us: int
    n_events: int
    width: int
    height: int
    encoding: str
    sent_ns: int
    t_offset_us: int = 0
    n_triggers: int = 0
    end_of_stream: bool = False
    stream_id: int = 0
    preamble_bytes: int = 0
    native: bool = False
    data: bytes = b""
    device_drops: int = 0
    drop_count: int = 0
    drop_unit: str = ""
    drop_reason: str = ""


@dataclass(frozen=True)
class CameraStatus:
    """State of a camera adapter and its settings as read back from the device; ``device_drops``
    the drops the device reported so far (:class:`EventPacket`), ``drop_reason`` the latest's
    reason (added later: older peers decode as 0, "")."""

    TYPE: ClassVar[MessageType] = MessageType.CAMERA_STATUS
    camera_id: str
    state: str  # starting | streaming | stopped | eof | error
    adapter: str
    width: int
    height: int
    encoding: str
    settings: dict[str, Any] = field(default_factory=dict)
    message: str = ""
    packets: int = 0
    events: int = 0
    device_drops: int = 0
    drop_reason: str = ""


@dataclass(frozen=True)
class EventRate:
    """Event-rate statistics over one interval of camera time."""

    TYPE: ClassVar[MessageType] = MessageType.EVENT_RATE
    camera_id: str
    t_us: int
    interval_s: float
    events: int
    rate_hz: float
    on_fraction: float
    bytes: int = 0


def _not_said() -> np.ndarray:
    return np.zeros(0, dtype=np.uint8)


def _none_shed() -> np.ndarray:
    return np.zeros(0, dtype=np.float32)


@dataclass(frozen=True)
class CentrelineMessage:
    """A batch of tracker updates: t, joints, smoothed centreline, tip, Δ_RMS, events used.

    Shapes (checked by :func:`decode`): ``t_s``, ``tip_x``, ``tip_y``, ``delta_rms``, ``n_events``,
    ``source_ns`` (n_t,); ``s`` (n_s,), n_s >= 1; ``x``, ``y`` (n_t, n_s); ``joints_x``, ``joints_y``
    (n_t, N_j+1), N_j >= 1. ``n_events`` and ``source_ns`` are integers, the rest real numbers.
    ``source_ns`` (n_t,) is the ``sent_ns`` of the newest packet each update used (for latency).
    ``final`` marks the last message of a stream (after the camera's end of stream).
    ``published_ns`` is the wall-clock time (ns) the tracker published the message (0: not said).
    ``stream`` numbers the camera streams the tracker has tracked (0 for the first; one more after
    each end of stream or camera restart), so a recorder knows which stream's file the updates go to.
    ``lost`` (n_t,) uint8: 1 where the flag was not found in the update (optional: a message without
    it, from an older tracker, decodes as all found). ``stale`` (n_t,) uint8: 1 where the shape rests
    on no recent evidence (remembered, not measured; optional: a message without it, from an older
    tracker, decodes as all 0). ``shed`` (n_t,) float32 in [0, 1]: the fraction of the camera's data
    since the previous update that the tracker shed to stay within its latency budget
    (``tracker.max_lag_ms``; optional: a message without it decodes as all 0, nothing shed).
    """

    TYPE: ClassVar[MessageType] = MessageType.CENTRELINES
    source: str
    seq: int
    units: str
    t_s: np.ndarray
    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    joints_x: np.ndarray
    joints_y: np.ndarray
    tip_x: np.ndarray
    tip_y: np.ndarray
    delta_rms: np.ndarray
    n_events: np.ndarray
    source_ns: np.ndarray
    final: bool = False
    published_ns: int = 0
    stream: int = 0
    lost: np.ndarray = field(default_factory=_not_said)
    stale: np.ndarray = field(default_factory=_not_said)
    shed: np.ndarray = field(default_factory=_none_shed)

    def __post_init__(self) -> None:
        for name in ("lost", "stale"):  # not said (an older tracker): all 0
            if len(getattr(self, name)) == 0 and len(self.t_s) > 0:
                object.__setattr__(self, name, np.zeros(len(self.t_s), dtype=np.uint8))
        if len(self.shed) == 0 and len(self.t_s) > 0:  # not said (an older tracker): nothing shed
            object.__setattr__(self, "shed", np.zeros(len(self.t_s), dtype=np.float32))

    @classmethod
    def from_batch(
        cls,
        batch: CentrelineBatch,
        *,
        source: str,
        seq: int,
        units: str,
        source_ns: np.ndarray,
        final: bool = False,
        published_ns: int = 0,
        stream: int = 0,
    ) -> CentrelineMessage:
        """Wrap a tracker batch for the wire."""
        return cls(
            final=final,
            published_ns=published_ns,
            stream=stream,
            source=source,
            seq=seq,
            units=units,
            t_s=batch.t_s,
            s=batch.s,
            x=batch.x,
            y=batch.y,
            joints_x=batch.joints_x,
            joints_y=batch.joints_y,
            tip_x=batch.tip_x,
            tip_y=batch.tip_y,
            delta_rms=batch.delta_rms,
            n_events=batch.n_events,
            source_ns=np.asarray(source_ns, np.int64),
            lost=batch.lost,
            stale=batch.stale,
            shed=batch.shed,
        )

    def batch(self) -> CentrelineBatch:
        """The updates as a :class:`CentrelineBatch`."""
        return CentrelineBatch(
            t_s=self.t_s,
            s=self.s,
            x=self.x,
            y=self.y,
            joints_x=self.joints_x,
            joints_y=self.joints_y,
            delta_rms=self.delta_rms,
            n_events=self.n_events,
            lost=self.lost,
            stale=self.stale,
            shed=self.shed,
        )


@dataclass(frozen=True)
class TrackerStatus:
    """Tracker health, published about once a second.

    ``missing_packets``: sequence gaps; ``malformed_packets``: messages or EVT bytes that could not be
    used; ``dropped_packets``: packets its full queue turned away (they also show as gaps);
    ``restarts``: new camera streams that began without the end of the last one (a restarted camera);
    ``late_packets``: duplicates and late packets of the stream, dropped.
    ``lost_updates``, ``lost_stretches``: updates that did not find the flag, and runs of them
    (since the service started).
    ``shed_fraction``: of the camera's events of the last interval, those the tracker shed to stay
    within its latency budget (0: all tracked); ``shed_packets``, ``shed_events``: the packets it
    skipped for it and their events (since the service started; they are not missing: the recorder
    and the rates have them).
    ``chain_reach``: where the flag's events ended along the chain over the last span judged (10 s
    of camera time), a fraction of L (1: at its tip; -1 before the first span, or when it had too
    few events to judge).
    """

    TYPE: ClassVar[MessageType] = MessageType.TRACKER_STATUS
    source: str
    state: str  # waiting | tracking | stopped
    events_per_s: float
    updates_per_s: float
    lag_s: float
    packets: int
    missing_packets: int
    malformed_packets: int
    t_s: float = 0.0
    dropped_packets: int = 0
    restarts: int = 0
    late_packets: int = 0
    lost_updates: int = 0
    lost_stretches: int = 0
    shed_fraction: float = 0.0
    shed_packets: int = 0
    shed_events: int = 0
    chain_reach: float = -1.0


@dataclass(frozen=True)
class TunnelState:
    """Wind-tunnel speed as read back, its set-point and state."""

    TYPE: ClassVar[MessageType] = MessageType.TUNNEL_STATE
    speed_mps: float
    setpoint_mps: float
    state: str  # idle | ramping | steady | stopping | fault
    fault: str = ""
    t_wall_s: float = 0.0


@dataclass(frozen=True)
class TunnelCommand:
    """A request to the tunnel owner: ``set`` a speed or ``stop`` (ramp to zero)."""

    TYPE: ClassVar[MessageType] = MessageType.TUNNEL_COMMAND
    action: str
    speed_mps: float = 0.0


@dataclass(frozen=True)
class SupervisorState:
    """Flag state from event rates, and sweep progress.

    The fields after ``message`` were added later with defaults (a peer of the previous version
    ignores them; its messages decode as "no sweep progress"). A number that is not known is
    ``-1.0`` (none of them can be negative; no NaN on the wire, as in :class:`TunnelState`):

    - the plan: ``point_index`` the 1-based position in the plan of ``point``, the point being
      measured (0: none); ``points_total`` the plan's points (0: no sweep); ``points_done`` those
      finished (done, failed or lossy; a redone point counts once), the ones of earlier sessions
      of a resumed run included; ``point_records`` the point records of this session (one per
      finished point, two for a redone one: a view draws a line per record; 0 from an older peer);
      ``elapsed_s`` since this session's sweep began; ``eta_s`` estimated seconds to its end;
    - the last finished point (``last_point`` its id, ``""`` before the first): ``last_index``
      (1-based position), ``last_speed_mps``, ``last_branch``, ``last_state`` (still | flapping |
      unknown), ``last_status`` (done | failed | lossy), ``amplitude_over_l``, ``frequency_hz``,
      ``lost_fraction`` (updates the tracker flagged lost: -1 until the tracker has a lost flag),
      ``sensor_error_rms_over_l`` (RMS |e|/L against the point sensor: -1 without one),
      ``stale_fraction`` (updates whose shape rests on no recent events: -1 when not known),
      ``chain_reach`` (where the flag's events ended along the chain, a fraction of L: -1 when not
      judged), ``last_suspect`` (its numbers may not be the flag's: the run log says why).
    """

    TYPE: ClassVar[MessageType] = MessageType.SUPERVISOR_STATE
    flag_state: str  # still | flapping | unknown
    rate_hz: float
    mode: str = "idle"  # idle | sweep | feedback | safe
    point: str = ""
    branch: str = ""
    speed_mps: float = 0.0
    message: str = ""
    point_index: int = 0
    points_total: int = 0
    points_done: int = 0
    elapsed_s: float = 0.0
    eta_s: float = -1.0
    last_point: str = ""
    last_index: int = 0
    last_speed_mps: float = -1.0
    last_branch: str = ""
    last_state: str = ""
    last_status: str = ""
    amplitude_over_l: float = -1.0
    frequency_hz: float = -1.0
    lost_fraction: float = -1.0
    sensor_error_rms_over_l: float = -1.0
    stale_fraction: float = -1.0
    point_records: int = 0
    chain_reach: float = -1.0
    last_suspect: bool = False


@dataclass(frozen=True)
class RecorderCommand:
    """Start, stop or rotate a recording of one camera (``path`` without extension)."""

    TYPE: ClassVar[MessageType] = MessageType.RECORDER_COMMAND
    action: str  # start | stop | rotate
    path: str = ""
    camera_id: str = ""
    centrelines: bool = False
    request_id: str = ""


@dataclass(frozen=True)
class RecorderStatus:
    """What the recorder is writing (counts of the recording ``path``; ``dropped_packets``: turned
    away by the recorder's full queue since it started, whatever file was open; ``device_drops``:
    drops the camera reported during the recording, ``device_drop_reason`` what they were, in one
    line; added later: older peers decode as 0, "")."""

    TYPE: ClassVar[MessageType] = MessageType.RECORDER_STATUS
    state: str  # idle | recording | error
    path: str = ""
    bytes: int = 0
    packets: int = 0
    missing_packets: int = 0
    request_id: str = ""
    message: str = ""
    malformed_packets: int = 0
    dropped_packets: int = 0
    device_drops: int = 0
    device_drop_reason: str = ""


@dataclass(frozen=True)
class FlagState:
    """The flag's state at one tracker update: published once per flapping cycle (at the update that
    completes it) and every ``flag_state.interval_s`` of camera time between cycles.

    The figures are over the last cycle (a still flag: over the last interval): ``amplitude_over_l``
    (half the tip's lateral peak-to-peak over L), ``frequency_hz`` (one over the cycle's duration),
    ``twi`` (travelling-wave index), ``lost_fraction`` and ``stale_fraction`` (of the updates they are
    over, those the tracker did not find or did not measure anew), over ``cycle_start_s`` to
    ``cycle_end_s`` (``updates`` updates). ``t_s`` is the update's camera time, ``tip_x``, ``tip_y``
    (``units``) and ``tip_lateral_over_l`` its tip, ``phase_rad`` its phase in the cycle (0 at the
    tip's upward crossing of its centre). ``speed_mps`` is the tunnel's last readback.
    ``source_ns``: the wall time (ns) the camera adapter received the packet that completed that
    update (for the loop's latency); ``published_ns``: when this was published. A number that is not
    known is ``-1.0`` (none of those can be negative: no NaN on the wire); ``frequency_hz``,
    ``phase_rad`` and ``twi`` are not known while the flag is still.
    """

    TYPE: ClassVar[MessageType] = MessageType.FLAG_STATE
    source: str
    seq: int
    t_s: float
    tip_x: float
    tip_y: float
    tip_lateral_over_l: float
    flapping: bool
    amplitude_over_l: float
    frequency_hz: float
    phase_rad: float
    twi: float
    lost_fraction: float
    stale_fraction: float
    speed_mps: float
    cycle_start_s: float
    cycle_end_s: float
    updates: int
    completes_cycle: bool
    units: str = "px"
    source_ns: int = 0
    published_ns: int = 0


@dataclass(frozen=True)
class SpeedRequest:
    """A request to the tunnel's owner for a wind speed, m/s, on :meth:`Keys.speed_request` of the
    identity asking (``requester``: that identity, as the sender says it; the key is what counts)."""

    TYPE: ClassVar[MessageType] = MessageType.SPEED_REQUEST
    speed_mps: float
    request_id: str
    requester: str = ""
    note: str = ""
    sent_ns: int = 0


@dataclass(frozen=True)
class SpeedReply:
    """The tunnel owner's answer to a :class:`SpeedRequest` (``request_id``; ``requester``: the identity
    its key named): whether it was taken, what was asked and the speed applied (``-1.0``: none), and
    why they differ (``reason``); ``setpoint_mps`` and ``speed_mps`` the tunnel's set-point and
    readback when it answered (``-1.0``: not known)."""

    TYPE: ClassVar[MessageType] = MessageType.SPEED_REPLY
    request_id: str
    requester: str
    accepted: bool
    asked_mps: float
    applied_mps: float
    reason: str = ""
    setpoint_mps: float = -1.0
    speed_mps: float = -1.0
    t_wall_s: float = 0.0


def _no_pulses() -> np.ndarray:
    return np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class SensorSamples:
    """Point-sensor samples: times on the sensor clock (µs), values (sensor units), NaN = missing.

    ``t_us`` (n,) int64 and ``value`` (n,) float64. Fields after ``value`` were added later with
    defaults, so messages without them still decode: ``trigger_t_us`` (m,) int64 the trigger pulses
    the sensor drove or recorded, on its clock; ``missing`` samples lost in this message's span (its
    NaN values included); ``clock`` ``sensor`` (the device's own clock) or ``host`` (stamped by the
    host on arrival, wall-clock µs); ``wall_ns`` the wall time the newest sample arrived (with
    ``t_us[-1]``, a rough link to the camera clock).
    """

    TYPE: ClassVar[MessageType] = MessageType.SENSOR_SAMPLES
    sensor_id: str
    seq: int
    units: str
    t_us: np.ndarray
    value: np.ndarray
    trigger_t_us: np.ndarray = field(default_factory=_no_pulses)
    missing: int = 0
    clock: str = "sensor"
    wall_ns: int = 0


MESSAGE_TYPES: dict[MessageType, type] = {
    cls.TYPE: cls
    for cls in (
        EventPacket,
        CameraStatus,
        EventRate,
        CentrelineMessage,
        TrackerStatus,
        TunnelState,
        TunnelCommand,
        SupervisorState,
        RecorderCommand,
        RecorderStatus,
        SensorSamples,
        FlagState,
        SpeedRequest,
        SpeedReply,
    )
}
