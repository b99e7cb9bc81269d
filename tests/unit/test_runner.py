"""Service runner: a finishing service ends the group, a failing one stops all, shutdown reports stragglers."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import threading
from dataclasses import dataclass, field

import pytest

from flagtrack.daemon.services.runner import ServiceGroup, StartError, run_services


class Bare:
    """Opens nothing (a service's start() opens its subscriptions, devices, files)."""

    def start(self) -> None:
        pass


@dataclass
class Looping(Bare):
    name: str
    stopped: bool = False
    ticks: int = 0

    def run(self, stop: threading.Event) -> None:
        while not stop.wait(0.001):
            self.ticks += 1
        self.stopped = True


@dataclass
class Finishing(Bare):
    name: str
    after: int = 3
    done: list = field(default_factory=list)

    def run(self, stop: threading.Event) -> None:
        for i in range(self.after):
            self.done.append(i)


@dataclass
class Failing(Bare):
    name: str

    def run(self, stop: threading.Event) -> None:
        raise RuntimeError("device unplugged")


@dataclass
class Stubborn(Bare):
    name: str
    release: threading.Event = field(default_factory=threading.Event)

    def run(self, stop: threading.Event) -> None:
        self.release.wait(5.0)


def test_finishing_service_stops_the_others() -> None:
    loop, fin = Looping("tracker"), Finishing("camera")
    report = run_services([loop, fin], stop_when_any_finishes=["camera"], handle_signals=False)
    assert loop.stopped and fin.done == [0, 1, 2]
    assert sorted(report.finished) == ["camera", "tracker"] and not report.errors


def test_failure_stops_everything_and_is_reported() -> None:
    loop = Looping("tracker")
    report = run_services([loop, Failing("camera")], handle_signals=False)
    assert loop.stopped
    assert isinstance(report.errors["camera"], RuntimeError)


@dataclass
class Opening:
    """Opens a device in start() (``fail``: cannot), closes it in close(); records what it was asked."""

    name: str
    fail: str = ""
    calls: list[str] = field(default_factory=list)

    def start(self) -> None:
        self.calls.append("start")
        if self.fail:
            raise OSError(self.fail)

    def close(self) -> None:
        self.calls.append("close")

    def run(self, stop: threading.Event) -> None:
        self.calls.append("run")


def test_a_service_that_cannot_start_stops_the_group_with_one_line_and_closes_those_started() -> None:
    tunnel, quiet = Opening("supervisor"), Looping("recorder")
    broken = Opening("viewer", fail="[Errno 98] Address already in use\n(the port of viewer.grpc_port)")
    after = Opening("camera/cam0")
    with pytest.raises(StartError) as caught:
        run_services([tunnel, quiet, broken, after], handle_signals=False)
    assert str(caught.value) == "the viewer service could not start: OSError: [Errno 98] Address already in use"
    assert caught.value.service == "viewer" and isinstance(caught.value.__cause__, OSError)
    assert tunnel.calls == ["start", "close"] and broken.calls == ["start"] and after.calls == []
    assert quiet.ticks == 0 and not quiet.stopped  # started (it opens nothing to close), never run


def test_shutdown_names_services_that_do_not_stop() -> None:
    stubborn = Stubborn("recorder")
    group = ServiceGroup([stubborn, Looping("tracker")])
    group.start()
    report = group.shutdown(timeout_s=0.2)
    assert report.abandoned == ["recorder"]
    stubborn.release.set()


_GROWING_ARRAYS = """
import resource, sys
import numpy as np
from flagtrack.daemon.process import keep_freed_memory
applied = keep_freed_memory() if sys.argv[1] == "keep" else None
np.ones(1)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for i in range(100):  # a packet's arrays: a little larger each time, written, then freed
    a = np.empty(25_000 + 1_250 * i)  # 200 KB, then 10 KB more each time
    a[:] = 1.0
    del a
print(applied, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


@pytest.mark.skipif(sys.platform != "linux" or platform.libc_ver()[0] != "glibc", reason="glibc's allocator only")
def test_kept_freed_memory_stops_arrays_faulting_in_again() -> None:
    """By default each new, larger array is mapped afresh (~50 page faults for 200 KB); with the
    services' allocator settings freed memory is reused and only the growth faults in."""
    plain_allocator = {
        name: value
        for name, value in os.environ.items()  # glibc's own defaults
        if not name.startswith("MALLOC_") and name not in ("LD_PRELOAD", "GLIBC_TUNABLES")
    }
    runs = {}
    for mode in ("default", "keep"):
        out = subprocess.run(
            [sys.executable, "-c", _GROWING_ARRAYS, mode],
            capture_output=True,
            text=True,
            check=True,
            env=plain_allocator,
        ).stdout.split()
        runs[mode] = (out[0], int(out[1]))
    assert runs["keep"][0] == "True"
    assert runs["default"][1] > 100 * 30
    assert runs["keep"][1] < 100 * 10


def test_end_hook_runs_as_each_service_ends_before_the_group_reacts() -> None:
    """The hook (the bus's undeclare_alive in `up`) runs as soon as a service's run returns or raises,
    before its end or failure stops the others."""
    for ending in (Finishing("camera"), Failing("camera")):
        seen: list[tuple[str, bool]] = []
        group = ServiceGroup(
            [Looping("tracker"), ending],
            stop_when_any_finishes=["camera"],
            on_service_end=lambda name: seen.append((name, group.stop.is_set())),  # noqa: B023 - this iteration's
        )
        group.start()
        group.wait(timeout_s=5.0)
        assert group.stop.is_set()
        group.shutdown(timeout_s=5.0)
        assert seen == [("camera", False), ("tracker", True)], ending


def test_a_failing_end_hook_does_not_hide_the_services_outcome() -> None:
    def hook(name: str) -> None:
        raise OSError("session closed")

    report = run_services([Finishing("camera"), Failing("recorder")], handle_signals=False, on_service_end=hook)
    assert report.finished == ["camera"] and isinstance(report.errors["recorder"], RuntimeError)


def test_signal_handlers_are_restored_after_the_run() -> None:
    """The runner takes SIGINT/SIGTERM only while its services run (uvicorn's capture_signals)."""
    import signal

    def mine(signum: int, frame: object) -> None:  # a handler the host program had
        pass

    before = {s: signal.signal(s, mine) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        seen: dict[int, object] = {}

        @dataclass
        class Peeking(Bare):
            name: str = "camera"

            def run(self, stop: threading.Event) -> None:
                seen.update({s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)})

        run_services([Peeking()], stop_when_any_finishes=["camera"], handle_signals=True)
        assert all(handler is not mine for handler in seen.values())  # the runner's own during the run
        assert signal.getsignal(signal.SIGINT) is mine and signal.getsignal(signal.SIGTERM) is mine
    finally:
        for s, old in before.items():
            signal.signal(s, old)


def test_a_signal_inside_stop_on_signals_asks_the_stop_and_raises_nothing() -> None:
    """Work under the capture is never cut by a KeyboardInterrupt (a compile, a numba unpickle: cut,
    they end in a SystemError traceback); the first signal asks the stop, counted, and the previous
    handler is back afterwards."""
    import os
    import signal

    from flagtrack.daemon.services.runner import StopEvent, stop_on_signals

    counts: list[int] = []
    before = signal.getsignal(signal.SIGINT)
    with stop_on_signals(StopEvent(), on_signal=counts.append) as stop:
        os.kill(os.getpid(), signal.SIGINT)  # the handler runs at the next bytecode: no exception
        finished = sum(range(1000))  # the work under way goes on to its end
    assert finished == 499500 and stop.is_set() and stop.reason == "stopped by SIGINT" and counts == [1]
    assert signal.getsignal(signal.SIGINT) is before
