"""The fuzzing targets of ``flagtrack bench fuzz`` and of ``tests/unit/test_fuzz_*.py``: each a property
(whatever the input, it is parsed or refused with flagtrack's own error type, naming the file, key or
device, within a time limit and a bounded allocation) and a hypothesis strategy of inputs.

Hypothesis (the ``dev`` extra) is imported only by the strategies and :func:`run_target`.
"""

from __future__ import annotations

import json
import tracemalloc
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.errors import ConfigError, DriverError, FlagtrackError, FormatError, SchemaError

REAL = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real"
FILE_FORMATS = ("evt3.raw", "evt2.raw", "dat", "npy", "csv", "aedat4")
MEMORY_LIMIT_BYTES = 64 << 20  # + 16 per input byte: what one decode may allocate at most


# -- the properties ------------------------------------------------------------------------------


@cache
def originals(folder: str) -> dict[str, bytes]:
    """One small valid file of each format (a few thousand events; AEDAT4: a real sample, if there)."""
    from flagtrack.drivers.formats import write_events
    from flagtrack.drivers.sim.quickline import WavyFlag, line_events

    events = np.concatenate(list(line_events(WavyFlag(length=200.0, root=(100.0, 240.0)), 0, 3_000, 640, 480)))
    files = {}
    for name in FILE_FORMATS[:-1]:
        path = Path(folder) / f"ok.{name}"
        encoding = {"evt3.raw": "evt3", "evt2.raw": "evt2"}.get(name)
        write_events(path, events, width=640, height=480, encoding=encoding)
        files[name] = path.read_bytes()
    sample = REAL / "tonic_sample.aedat4"
    if sample.is_file():
        files["aedat4"] = sample.read_bytes()
    return files


def damaged(original: bytes, edits: list[tuple[float, int]], cut: float | None, in_header: bool) -> bytes:
    """``original`` with bytes replaced (``edits``: where as a fraction, new value), then cut at ``cut``."""
    data = bytearray(original)
    span = min(len(data), 160) if in_header else len(data)  # the header and the first words, or anywhere
    for where, value in edits:
        data[int(where * span)] = value
    if cut is not None:
        data = data[: int(cut * len(data))]
    return bytes(data)


def check_file(path: Path) -> int:
    """Read ``path`` whole, by default and strictly: events, or a FlagtrackError naming the file.

    The default reader's skipped ranges must lie in the file, in order, with a bound >= 0.
    """
    from flagtrack.drivers.formats import open_events

    events = 0
    for strict in (False, True):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                with open_events(path, strict=strict) as reader:
                    events = sum(len(chunk.events) for chunk in reader)
                    ends = [0] + [x for r in reader.skipped for x in (r.start, r.end)]
                    assert ends == sorted(ends) and ends[-1] <= path.stat().st_size, reader.skipped
                    assert all(r.events_at_most >= 0 for r in reader.skipped)
        except FlagtrackError as exc:
            assert str(path) in str(exc), f"the error does not name the file: {exc}"
    return events


def check_packet(encoding: str, data: bytes, t_offset_us: int) -> None:
    """A packet's bytes decode or raise FormatError."""
    from flagtrack.drivers.formats.packets import decode_packet

    try:
        decode_packet(encoding, data, t_offset_us)
    except FormatError:
        pass


def check_message(data: bytes) -> None:
    """Any bytes on a bus key: a message or a SchemaError, allocating at most 64 MB + 16 per byte."""
    from flagtrack.daemon.schema import decode

    tracemalloc.start()
    try:
        decode(data)
    except SchemaError:
        pass
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peak <= MEMORY_LIMIT_BYTES + 16 * len(data), f"decoding {len(data)} bytes allocated {peak} bytes"


def check_rig_text(folder: Path, text: str) -> None:
    """A rig file's text loads or raises ConfigError naming the file."""
    from flagtrack.daemon.rig.config import load_rig

    path = folder / "rig.yaml"
    path.write_bytes(text.encode("utf-8", errors="surrogatepass"))  # a lone surrogate: bytes that are not UTF-8
    try:
        load_rig(path, services=())
    except ConfigError as exc:
        assert str(path) in str(exc), f"the error does not name the file: {exc}"


def check_tunnel_reply(reply: bytes) -> None:
    """What a line-protocol tunnel controller answers: a value, or a DriverError naming the port."""
    import serial

    from flagtrack.drivers.serial.adapter import SerialAdapter
    from flagtrack.drivers.tunnel.ascii import AsciiTunnel

    for ask in ("read_speed_mps", "read_fault", "write_setpoint_mps", "keep_alive"):
        port = serial.serial_for_url("loop://", timeout=0.001)
        port.write(reply + b"\n")  # the controller's reply waits in the line before the command comes back
        tunnel = AsciiTunnel(SerialAdapter("loop://fuzz", timeout_s=0.001, port_obj=port))
        try:
            value = getattr(tunnel, ask)(*((1.0,) if ask == "write_setpoint_mps" else ()))
            assert value is None or isinstance(value, float | str), value
        except DriverError as exc:
            assert "loop://fuzz" in str(exc), f"the error does not name the port: {exc}"
        finally:
            port.close()


def check_sensor_line(line: str) -> None:
    """A point sensor's reply line is sorted into a kind, whatever it holds (never raises)."""
    from flagtrack.drivers.sensor.ascii import AsciiSensorProtocol, LineParser

    for protocol in (AsciiSensorProtocol(), AsciiSensorProtocol(mode="stream", time_wrap_counts=1 << 16)):
        kind, value, t_us = LineParser(protocol).parse(line)
        assert kind in ("sample", "untimed", "trigger", "error", "other"), kind
        assert t_us is None or isinstance(t_us, int)


def check_rtu_frame(frame: bytes) -> None:
    """A Modbus RTU request frame (the simulated drive's parser): a Request or ValueError."""
    from flagtrack.drivers.serial import modbus_rtu as rtu

    length = rtu.frame_length(frame)
    assert length is None or length >= 0
    try:
        request = rtu.parse_request(frame)
    except ValueError:
        return
    assert 0 <= request.device_id <= 255 and len(request.values) <= 0xFFFF


# -- hypothesis strategies (hypothesis is imported only here) ------------------------------------


@dataclass
class Target:
    """One fuzzing target: a strategy of inputs and the property they must keep."""

    name: str
    strategy: Callable[[], Any]
    check: Callable[[Any], None]
    cases: int = 0
    failures: list[str] = field(default_factory=list)


def rig_texts() -> Any:
    """Valid rig files with one value replaced by anything YAML can say, or a few characters changed."""
    from hypothesis import strategies as st

    base = (Path(__file__).resolve().parents[2] / "deploy" / "rig-sim.yaml").read_text()
    lines = base.splitlines()
    scalars = st.one_of(
        st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=20), st.just("{a: [1, {b: c}]}")
    )
    values = st.recursive(
        scalars, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3)
    )
    key_lines = [i for i, line in enumerate(lines) if ":" in line and not line.lstrip().startswith("#")]

    def replace_value(i: int, value: Any) -> str:
        out = list(lines)
        key = out[i].split(":", 1)[0]
        out[i] = f"{key}: {json.dumps(value, default=str)}"
        return "\n".join(out)

    def edit(positions: list[tuple[float, str]]) -> str:
        text = list(base)
        for where, char in positions:
            text[int(where * (len(text) - 1))] = char
        return "".join(text)

    return st.one_of(
        st.builds(replace_value, st.sampled_from(key_lines), values),
        st.builds(edit, st.lists(st.tuples(st.floats(0, 1), st.characters()), min_size=1, max_size=4)),
        st.text(max_size=200),
    )


def sample_messages() -> list[bytes]:
    """Valid messages of several types (scalars, bytes and arrays), for the schema target to damage."""
    from flagtrack.daemon.schema import (
        CentrelineMessage,
        EventPacket,
        EventRate,
        RecorderCommand,
        SensorSamples,
        encode,
    )

    one, two = np.ones((2, 5)), np.ones(2)
    lines = CentrelineMessage("t", 0, "px", np.arange(2.0), np.arange(5.0), one, one, np.ones((2, 3)), np.ones((2, 3)),
                              two, two, two, np.ones(2, np.int64), np.ones(2, np.int64))  # fmt: skip
    return [
        encode(EventRate("cam0", 10, 0.1, 5, 50.0, 0.5, 99)),
        encode(RecorderCommand("start", path="x", request_id="r")),
        encode(EventPacket("cam0", 3, 1, 2, 4, 640, 480, "evt3", 7, data=bytes(range(64)))),
        encode(SensorSamples("s", 1, "mm", np.arange(4, dtype=np.int64), np.ones(4))),
        encode(lines),
    ]


def targets(folder: Path) -> list[Target]:
    """Every target, its inputs drawn by hypothesis; ``folder`` holds the files written."""
    from hypothesis import strategies as st

    files = originals(str(folder))
    edits = st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 255)), min_size=1, max_size=4)
    damage = st.tuples(edits, st.one_of(st.none(), st.floats(0, 1)), st.booleans())
    out = []
    for name in sorted(files):

        def check_damaged(case: tuple, name: str = name) -> None:
            path = folder / f"damaged.{name}"
            path.write_bytes(damaged(files[name], *case))
            check_file(path)

        out.append(Target(f"file {name}", lambda: damage, check_damaged))

    def packets() -> Any:
        loops = st.sampled_from([1 << 24, 1 << 34])
        offsets = st.one_of(
            st.integers(-(1 << 63), (1 << 63) - 1), st.builds(lambda k, n: k * n, st.integers(0, 1000), loops)
        )
        return st.tuples(st.sampled_from(["evt2", "evt21", "evt3", "evt4"]), st.binary(max_size=4096), offsets)

    out.append(Target("packet decoder", packets, lambda case: check_packet(*case)))
    samples = sample_messages()

    def messages() -> Any:
        mutated = st.builds(lambda i, e: damaged(samples[i], *e), st.integers(0, len(samples) - 1), damage)
        return st.one_of(st.binary(max_size=2048), mutated)

    out.append(Target("wire schema", messages, check_message))
    out.append(Target("rig YAML", rig_texts, lambda text: check_rig_text(folder, text)))
    out.append(Target("tunnel replies", lambda: st.binary(max_size=80), check_tunnel_reply))
    out.append(Target("sensor lines", lambda: st.text(max_size=80), check_sensor_line))
    out.append(Target("Modbus RTU frames", lambda: st.binary(max_size=300), check_rtu_frame))
    return out


def run_target(target: Target, examples: int, deadline_s: float, seed: int) -> None:
    """Run ``examples`` hypothesis cases of ``target``; a failure is recorded, not raised."""
    from datetime import timedelta

    from hypothesis import HealthCheck, given, settings
    from hypothesis import seed as hypothesis_seed

    def counted(case: Any) -> None:
        target.cases += 1
        target.check(case)

    test = hypothesis_seed(seed)(
        settings(
            max_examples=examples,
            deadline=timedelta(seconds=deadline_s),
            database=None,
            suppress_health_check=list(HealthCheck),
            print_blob=False,
        )(given(target.strategy())(counted))
    )
    try:
        test()
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:  # noqa: BLE001 - a finding (a Rust panic is a BaseException): recorded
        target.failures.append(f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"[:300])
