"""The sweep's state machine fed facts, with no bus: a fake clock, a tunnel speaking SafeTunnel's API
that records its set-points, a recorder that answers at once and writes real files, and the facts
each point's measure finds. The run log and the point files are real."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from flagtrack.daemon.errors import DriverError
from flagtrack.daemon.schema import RecorderCommand, RecorderStatus
from flagtrack.daemon.services.runner import StopEvent
from flagtrack.daemon.sweep.plan import Point, SweepConfig
from flagtrack.daemon.sweep.ports import Report
from flagtrack.daemon.sweep.runlog import PointResult, read_run
from flagtrack.daemon.sweep.runner import SweepRunner, SweepSettings
from flagtrack.daemon.sweep.session import Limits, Monitoring, Session
from flagtrack.daemon.sweep.summary import SUMMARY_CSV, summary_points, write_summary_csv
from flagtrack.drivers.tunnel.base import TunnelStatus
from flagtrack.drivers.tunnel.safe import TunnelAborted

UP_DOWN = SweepConfig(speeds=(4.0, 5.5), settle_s=0.5, record_s=1.0)  # 000-up-4.00, 001-up-5.50, 002-down-4.00
SECOND = "001-up-5.50"


class FakeClock:
    """Monotonic time that moves only when the run waits."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def monotonic(self) -> float:
        return self.now_s

    def time(self) -> float:
        return 1.8e9 + self.now_s

    def wait(self, stop: threading.Event, timeout_s: float) -> bool:
        self.now_s += timeout_s
        return stop.is_set()


class FakeTunnel:
    """SafeTunnel's API: a set-point is reached at once; while set-point number ``n`` (1-based) of
    ``stalled`` is in force, the readback is ``stall_mps``. ``on_set(n)`` runs before set-point n."""

    def __init__(self, stalled: tuple[int, ...] = (), stall_mps: float = 4.2) -> None:
        self.stall_now = False  # stalled whatever the set-point
        self.speeds: list[float] = []
        self.calls: list[str] = []
        self.stalled, self.stall_mps = stalled, stall_mps
        self.on_set: Callable[[int], None] = lambda n: None
        self.aborted = threading.Event()
        self._setpoint_mps = math.nan

    @property
    def setpoint_mps(self) -> float:
        return self._setpoint_mps

    def start(self) -> float:
        self.calls.append("start")
        self._setpoint_mps = 0.0
        return 0.0

    def set_speed_mps(self, speed_mps: float) -> None:
        self.speeds.append(speed_mps)
        self.on_set(len(self.speeds))
        if self.aborted.is_set():
            raise TunnelAborted("set aborted", device="fake")
        self._setpoint_mps = speed_mps

    def status(self) -> TunnelStatus:
        stalled = self.stall_now or len(self.speeds) in self.stalled
        return TunnelStatus("fake", self._setpoint_mps, self.stall_mps if stalled else self._setpoint_mps, None, True)

    def safe_stop(self) -> None:
        self.calls.append("safe_stop")
        self._setpoint_mps = 0.0

    def abort(self) -> None:
        self.aborted.set()

    def close(self) -> None:
        self.calls.append("close")

    def heartbeat(self) -> None:
        pass


class FakeOutside:
    """The bus side: every service there; a recorder that writes ``<path>.raw`` on start and answers
    at once, or ``stop_delay_s`` after a stop on ``clock`` (the stops numbered in ``lossy_stops``
    report missing packets)."""

    def __init__(
        self, lossy_stops: tuple[int, ...] = (), stop_delay_s: float = 0.0, clock: FakeClock | None = None
    ) -> None:
        self.clock, self.stop_delay_s = clock, stop_delay_s
        self.sent: list[tuple[str, float]] = []  # (action, when on the clock)
        self._due_s: dict[str, float] = {}
        self.reports: list[Report] = []
        self.finished: list[str] = []  # the last finished point's id, as each report said it
        self.on_publish: Callable[[Report], None] = lambda report: None
        self.commands: list[RecorderCommand] = []
        self.lossy_stops = lossy_stops
        self.failed_starts: tuple[int, ...] = ()  # the starts numbered here fail (a read-only folder)
        self._starts = 0
        self.problem_text: str | None = None
        self._replies: dict[str, RecorderStatus] = {}
        self._stops = 0

    def pump(self) -> None:
        pass

    def beat(self, mode: str) -> None:
        pass

    def publish(self, report: Report, tunnel: TunnelStatus) -> None:
        self.reports.append(report)
        last = None if report.progress is None else report.progress.last
        self.finished.append("" if last is None else last.point_id)
        self.on_publish(report)

    def waiting_for(self) -> str | None:
        return None

    def watch_from_now(self) -> None:
        pass

    def problem(self) -> str | None:
        return self.problem_text

    def recorder_error(self) -> str:
        return ""

    def send(self, command: RecorderCommand) -> None:
        self.commands.append(command)
        self.sent.append((command.action, self.clock.now_s if self.clock is not None else math.nan))
        missing = 0
        if command.action == "start":
            self._starts += 1
            if self._starts in self.failed_starts:
                why = f"start failed: [Errno 30] Read-only file system: '{command.path}.raw'"
                self._replies[command.request_id] = RecorderStatus("error", message=why)
                return
            Path(command.path + ".raw").write_bytes(b"\0" * 4000)
        else:
            self._stops += 1
            missing = 3 if self._stops in self.lossy_stops else 0
            if self.clock is not None:
                self._due_s[command.request_id] = self.clock.now_s + self.stop_delay_s
        self._replies[command.request_id] = RecorderStatus("idle", bytes=4000, missing_packets=missing)

    def reply(self, request_id: str) -> RecorderStatus | None:
        if self.clock is not None and self.clock.now_s < self._due_s.get(request_id, 0.0):
            return None
        return self._replies.pop(request_id, None)


class FakeMeasure:
    """The facts a point's recording found: flapping above 5 m/s, still below."""

    def __init__(self, fail_at: str = "") -> None:
        self.gathering = False
        self.fail_at = fail_at

    def begin(self) -> None:
        self.gathering = True

    def end(self) -> None:
        self.gathering = False

    def result(self, point: Point, run_dir: Path, previous_state: str) -> PointResult:
        if point.point_id == self.fail_at:
            raise ValueError("the analysis broke")
        flapping = point.speed_mps > 5.0
        return PointResult.planned(
            point, state="flapping" if flapping else "still", amplitude_over_l=0.25 if flapping else 0.01
        )


def csv_only(run_dir: Path) -> None:
    """The summary CSV alone (the figures are the summary module's tests)."""
    write_summary_csv(summary_points(read_run(run_dir)), run_dir / SUMMARY_CSV)


def sweep(
    tmp_path: Path,
    tunnel: FakeTunnel | None = None,
    outside: FakeOutside | None = None,
    measure: FakeMeasure | None = None,
    stop: StopEvent | None = None,
    resume_dir: Path | None = None,
    clock: FakeClock | None = None,
    **settings: Any,
) -> tuple[SweepRunner, Session, FakeTunnel, FakeOutside]:
    """Run a sweep of ``UP_DOWN`` (unless ``settings`` say otherwise) to its end."""
    tunnel, outside, stop = tunnel or FakeTunnel(), outside or FakeOutside(), stop or StopEvent()
    values = {"runs_dir": tmp_path / "runs", "run_name": "run", "sweep": UP_DOWN, "readback_grace_s": 0.2, **settings}
    runner = SweepRunner(SweepSettings(**values), measure or FakeMeasure(), {"rig": "test"}, resume_dir, csv_only)
    session = Session(tunnel, outside, Limits(), clock or FakeClock())
    try:
        session.run(runner, stop)
    finally:
        stop.set()  # ends the session's abort watcher
    return runner, session, tunnel, outside


def test_the_plan_runs_point_by_point_and_the_tunnel_ends_at_zero(tmp_path: Path) -> None:
    runner, session, tunnel, outside = sweep(tmp_path)
    assert tunnel.speeds == [4.0, 5.5, 4.0, 0.0]  # each point's speed, then the end of the sweep
    assert tunnel.calls == ["start", "safe_stop", "close"]
    assert session.stop_reason == "finished"
    record = read_run(tmp_path / "runs" / "run")
    assert [(p.point_id, p.status, p.state) for p in record.points] == [
        ("000-up-4.00", "done", "still"),
        ("001-up-5.50", "done", "flapping"),
        ("002-down-4.00", "done", "still"),
    ]
    assert record.stop is not None and record.stop["reason"] == "finished"
    first = record.points[0]
    assert first.raw_file == "points/000-up-4.00.raw" and first.raw_bytes == 4000
    assert first.speed_readback_mps == 4.0 and first.t_stop_unix - first.t_start_unix == pytest.approx(1.0, abs=0.05)
    assert [c.action for c in outside.commands] == ["start", "stop"] * 3 + ["stop"]  # the last: the safe state's
    assert outside.reports[-1].mode == "safe" and outside.reports[-1].stop_reason == "finished"
    assert (tmp_path / "runs" / "run" / SUMMARY_CSV).read_text().count("\n") == 4
    assert runner.run_dir == tmp_path / "runs" / "run" and len(runner.points_done) == 3


def test_each_finished_point_is_published_with_its_facts_at_once(tmp_path: Path) -> None:
    _, _, _, outside = sweep(tmp_path)
    firsts = [outside.finished.index(pid) for pid in ("000-up-4.00", "001-up-5.50", "002-down-4.00")]
    assert firsts == sorted(firsts) and all(outside.reports[i].point_id == "" for i in firsts)
    assert {r.point_id for r in outside.reports} == {"", "000-up-4.00", "001-up-5.50", "002-down-4.00"}


def test_a_point_out_of_tolerance_is_failed_set_aside_and_measured_again(tmp_path: Path) -> None:
    tunnel = FakeTunnel(stalled=(2,))  # the fan stalls at 4.2 m/s under the second set-point (5.5 m/s)
    sweep(tmp_path, tunnel=tunnel)
    record = read_run(tmp_path / "runs" / "run")
    second = [p for p in record.points if p.point_id == SECOND]
    assert [p.status for p in second] == ["failed", "done"]
    assert "tunnel left its tolerance: readback 4.20 m/s, set-point 5.50" in (second[0].reason or "")
    assert tunnel.speeds == [4.0, 5.5, 5.5, 4.0, 0.0]
    assert record.stop is not None and record.stop["reason"] == "finished"


def test_a_lossy_recording_is_kept_beside_the_good_one(tmp_path: Path) -> None:
    sweep(tmp_path, outside=FakeOutside(lossy_stops=(1,)))
    record = read_run(tmp_path / "runs" / "run")
    first = [p for p in record.points if p.point_id == "000-up-4.00"]
    assert [p.status for p in first] == ["lossy", "done"]
    assert first[0].reason == "recording lost packets (3 missing in sequence)"
    assert first[0].raw_file == "points/000-up-4.00.bad1.raw" and first[1].raw_file == "points/000-up-4.00.raw"
    points = tmp_path / "runs" / "run" / "points"
    assert (points / "000-up-4.00.bad1.raw").stat().st_size == (points / "000-up-4.00.raw").stat().st_size == 4000


def test_a_fan_stalling_as_a_recording_ends_keeps_its_files_while_the_recorder_is_slow_to_stop(
    tmp_path: Path,
) -> None:
    clock, tunnel = FakeClock(), FakeTunnel()
    outside = FakeOutside(stop_delay_s=0.5, clock=clock)  # longer than the tunnel's grace and publish period

    def stall_late_in_the_second_recording(report: Report) -> None:  # and until the retry's set-point
        starts = [t_s for action, t_s in outside.sent if action == "start"]
        tunnel.stall_now = len(tunnel.speeds) == 2 and len(starts) == 2 and clock.now_s - starts[1] >= 0.9

    outside.on_publish = stall_late_in_the_second_recording
    sweep(tmp_path, tunnel=tunnel, outside=outside, clock=clock)
    second = [p for p in read_run(tmp_path / "runs" / "run").points if p.point_id == SECOND]
    assert [p.status for p in second] == ["failed", "done"]
    assert "left its tolerance" in (second[0].reason or "") and second[0].raw_file == f"points/{SECOND}.bad1.raw"


def test_a_bad_point_with_no_retries_left_stops_the_sweep_safe(tmp_path: Path) -> None:
    runner, session, tunnel, _ = sweep(tmp_path, outside=FakeOutside(lossy_stops=(2, 3)))  # the retry is lossy too
    assert session.stop_reason == f"point {SECOND} lossy: recording lost packets (3 missing in sequence)"
    assert tunnel.speeds == [4.0, 5.5, 5.5] and tunnel.calls[-2:] == ["safe_stop", "close"]
    record = read_run(tmp_path / "runs" / "run")
    assert [p.status for p in record.points] == ["done", "lossy", "lossy"]
    assert [p.raw_file for p in record.points[1:]] == [f"points/{SECOND}.bad1.raw", f"points/{SECOND}.bad2.raw"]
    assert record.stop is not None and record.stop["reason"] == session.stop_reason


def test_a_recording_that_cannot_start_fails_its_point_and_stops_the_sweep_safe(tmp_path: Path) -> None:
    """The recorder answers a start with an error (a read-only or full disk): the point is failed, not
    done with 0 bytes (a resumed run measures it), and the sweep stops with the tunnel at zero."""
    outside = FakeOutside()
    outside.failed_starts = (2,)
    _, session, tunnel, _ = sweep(tmp_path, outside=outside)
    assert session.stop_reason.startswith(f"point {SECOND} failed: recorder: start failed: [Errno 30]")
    assert tunnel.speeds == [4.0, 5.5] and tunnel.calls[-2:] == ["safe_stop", "close"]
    record = read_run(tmp_path / "runs" / "run")
    assert [(p.point_id, p.status) for p in record.points] == [("000-up-4.00", "done"), (SECOND, "failed")]
    assert not (tmp_path / "runs" / "run" / "points" / f"{SECOND}.raw").exists()


def test_on_bad_point_stop_measures_no_point_again(tmp_path: Path) -> None:
    plan = SweepConfig(speeds=(4.0, 5.5), settle_s=0.5, record_s=1.0, on_bad_point="stop")
    _, session, tunnel, _ = sweep(tmp_path, tunnel=FakeTunnel(stalled=(2,)), sweep=plan)
    assert tunnel.speeds == [4.0, 5.5] and session.stop_reason.startswith(f"point {SECOND} failed")


def test_a_stop_request_aborts_the_ramp_and_the_run_resumes_where_it_stopped(tmp_path: Path) -> None:
    stop, tunnel = StopEvent(), FakeTunnel()

    def sigterm_during_second_ramp(n: int) -> None:
        if n == 2:
            stop.request("SIGTERM")
            assert tunnel.aborted.wait(5), "the session's watcher did not abort the ramp"

    tunnel.on_set = sigterm_during_second_ramp
    _, session, _, _ = sweep(tmp_path, tunnel=tunnel, stop=stop)
    assert session.stop_reason == "SIGTERM" and tunnel.calls[-2:] == ["safe_stop", "close"]
    run_dir = tmp_path / "runs" / "run"
    stopped = read_run(run_dir).stop
    assert stopped is not None and stopped["reason"] == "SIGTERM" and stopped["error"] is None

    _, session, tunnel, _ = sweep(tmp_path, resume_dir=run_dir)
    assert session.stop_reason == "finished" and tunnel.speeds == [5.5, 4.0, 0.0]
    record = read_run(run_dir)
    assert record.resumes[0]["done"] == ["000-up-4.00"]
    assert [p.status for p in record.latest_points().values()] == ["done"] * 3


def test_a_restart_takes_up_an_interrupted_run_and_holds_a_stopped_one(tmp_path: Path) -> None:
    stop = StopEvent()
    tunnel = FakeTunnel()
    tunnel.on_set = lambda n: stop.request("SIGTERM") if n == 3 else None  # before the down branch
    sweep(tmp_path, tunnel=tunnel, stop=stop)
    _, session, tunnel, _ = sweep(tmp_path)  # a stop record: held, the tunnel never set
    assert "not resumed on its own" in session.stop_reason and tunnel.speeds == []
    log = tmp_path / "runs" / "run" / "run.jsonl"
    log.write_text("".join(log.read_text().splitlines(keepends=True)[:-1]))  # as if the power went
    _, session, tunnel, _ = sweep(tmp_path)
    assert session.stop_reason == "finished" and tunnel.speeds == [5.5, 4.0, 0.0]  # down-branch re-entry from the top
    assert [p.point_id for p in read_run(tmp_path / "runs" / "run").points][-1] == "002-down-4.00"


def test_an_exception_still_ends_with_the_tunnel_at_zero_and_a_stop_record(tmp_path: Path) -> None:
    tunnel = FakeTunnel()
    with pytest.raises(ValueError, match="the analysis broke"):
        sweep(tmp_path, tunnel=tunnel, measure=FakeMeasure(fail_at=SECOND))
    assert tunnel.calls[-2:] == ["safe_stop", "close"]
    stop = read_run(tmp_path / "runs" / "run").stop
    assert stop is not None and stop["reason"] == "error" and stop["error"] == "ValueError: the analysis broke"


def test_a_tunnel_error_is_the_stop_reason(tmp_path: Path) -> None:
    tunnel = FakeTunnel()

    def fault(n: int) -> None:
        if n == 2:
            raise DriverError("no reply within 0.5 s", device="fake")

    tunnel.on_set = fault
    _, session, _, _ = sweep(tmp_path, tunnel=tunnel)
    assert session.stop_reason == "error" and tunnel.calls[-2:] == ["safe_stop", "close"]
    stop = read_run(tmp_path / "runs" / "run").stop
    assert stop is not None and stop["error"] == "DriverError: fake: no reply within 0.5 s"


def test_a_service_gone_while_a_point_is_under_way_stops_the_run(tmp_path: Path) -> None:
    outside = FakeOutside()
    tunnel = FakeTunnel()

    def tracker_gone(n: int) -> None:
        if n == 2:
            outside.problem_text = "the tracker service went away (liveliness lost)"

    tunnel.on_set = tracker_gone
    _, session, _, _ = sweep(tmp_path, tunnel=tunnel, outside=outside)
    assert session.stop_reason == "the tracker service went away (liveliness lost)"
    assert [p.point_id for p in read_run(tmp_path / "runs" / "run").points] == ["000-up-4.00"]


def test_a_disk_too_small_for_the_next_point_stops_before_it(tmp_path: Path) -> None:
    _, session, tunnel, _ = sweep(tmp_path, free_space_margin_mb=1e12)
    assert session.stop_reason.startswith("point 000-up-4.00 not started: not enough free space")
    assert tunnel.speeds == [] and tunnel.calls == ["start", "safe_stop", "close"]


def test_watching_alone_publishes_until_stopped_and_ends_safe() -> None:
    stop, tunnel, outside = StopEvent(), FakeTunnel(), FakeOutside()
    clock = FakeClock()
    session = Session(tunnel, outside, Limits(publish_interval_s=0.2), clock)
    outside.on_publish = lambda report: stop.request("SIGINT") if clock.now_s > 1.0 else None
    session.run(Monitoring(), stop)
    assert session.stop_reason == "SIGINT" and tunnel.speeds == [] and tunnel.calls == ["start", "safe_stop", "close"]
    assert {r.mode for r in outside.reports} == {"monitor", "safe"} and len(outside.reports) >= 5


def test_the_eta_before_the_first_point_counts_the_ramps(tmp_path: Path) -> None:
    """The first ETA counted each point's settle and record only: `sweep` said 0:20 for a plan whose
    `config check` estimate (ramps counted) was 44 s."""
    _, session, _, _ = sweep(tmp_path, ramp_mps2=1.0)
    # ramps 0 -> 4 -> 5.5 -> 4 -> 0 m/s at 1 m/s^2 (11 s), and 3 x (0.5 + 1.0) s, over 3 points
    assert session.progress is not None and session.progress.planned_point_s == pytest.approx(15.5 / 3)
