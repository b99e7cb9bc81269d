"""Property-based fuzzing of the event-file readers: damaged files give flagtrack's own errors only.

Each case starts from a valid small file of one format and damages it (bytes replaced, a cut, a
header byte changed), or puts any bytes after a valid RAW header; reading it whole must either work
or raise a ``FlagtrackError`` (a ``FormatError`` naming the file), never another exception.
``flagtrack bench fuzz`` runs the same properties (daemon/bench/fuzz.py) for longer.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flagtrack.daemon.bench.fuzz_targets import check_file, damaged
from flagtrack.daemon.errors import FlagtrackError
from flagtrack.drivers.formats import open_events, write_events
from flagtrack.drivers.sim.quickline import WavyFlag, line_events

FORMATS = {"evt3.raw": {"encoding": "evt3"}, "evt2.raw": {"encoding": "evt2"}, "npy": {}, "csv": {}, "dat": {}}
REAL_AEDAT4 = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real" / "tonic_sample.aedat4"


@pytest.fixture(scope="module")
def originals(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """One small valid file of each format written by flagtrack (a few thousand events)."""
    folder = tmp_path_factory.mktemp("fuzz")
    events = np.concatenate(list(line_events(WavyFlag(length=200.0, root=(100.0, 240.0)), 0, 3_000, 640, 480)))
    files = {}
    for name, options in FORMATS.items():
        path = folder / f"ok.{name}"
        write_events(path, events, width=640, height=480, **options)
        files[name] = path.read_bytes()
    if REAL_AEDAT4.is_file():  # flagtrack writes no AEDAT4: a real sample, where the shared data is
        files["aedat4"] = REAL_AEDAT4.read_bytes()
    return files


def read_whole(path: Path) -> int:
    """Events in ``path``, read as ``flagtrack reconstruct`` reads it (warnings about skipped words allowed)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with open_events(path) as reader:
            return sum(len(chunk.events) for chunk in reader)


damage = st.tuples(
    st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 255)), min_size=1, max_size=4),
    st.one_of(st.none(), st.floats(0, 1)),
    st.booleans(),
)


@pytest.mark.parametrize("name", [*sorted(FORMATS), "aedat4"])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(damage=damage)
def test_a_damaged_file_is_read_or_refused_with_our_error(
    originals: dict[str, bytes], tmp_path: Path, name: str, damage: tuple
) -> None:
    """Read by default (resynchronised, its skipped ranges in the file and in order) and strictly:
    events or a FlagtrackError naming the file (daemon/bench/fuzz.py's property, also `bench fuzz`)."""
    if name not in originals:
        pytest.skip(f"no AEDAT4 sample ({REAL_AEDAT4} is absent)")
    path = tmp_path / f"damaged.{name}"
    path.write_bytes(damaged(originals[name], *damage))
    check_file(path)


@pytest.mark.parametrize("encoding", ["evt2", "evt21", "evt21 legacy", "evt3"])
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(body=st.binary(max_size=3000))
def test_any_body_after_a_valid_raw_header_is_read_or_refused(tmp_path: Path, encoding: str, body: bytes) -> None:
    """Every EVT decoder, EVT 2.1 included (flagtrack writes none), on bytes of any kind."""
    name, _, legacy = encoding.partition(" ")
    fmt = {"evt2": "EVT2", "evt21": "EVT21", "evt3": "EVT3"}[name]
    header = f"% format {fmt};height=480;width=640{';endianness=legacy' if legacy else ''}\n% end\n"
    path = tmp_path / f"any-{name}.raw"
    path.write_bytes(header.encode() + body)
    check_file(path)


def test_an_unbalanced_npy_header_is_a_format_error(tmp_path: Path) -> None:
    """What the fuzzer found: numpy's header parser raised tokenize.TokenError (a traceback for the user)."""
    header = b"{'descr': [('t', '<i8')], 'fortran_order': False, 'shape': ([10,), }\n"
    path = tmp_path / "bad.npy"
    path.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header)
    with pytest.raises(FlagtrackError, match="garbage .npy header"):
        read_whole(path)


def test_a_dat_size_in_other_digits_is_ignored(tmp_path: Path) -> None:
    """What `bench fuzz` found: '% Width 6²0' passed str.isdigit and int() raised ValueError (a traceback)."""
    path = tmp_path / "odd.dat"
    path.write_bytes("% Width 6²0\n% Height 480\n".encode("latin-1") + bytes([12, 8]) + bytes(16))
    with open_events(path) as reader:
        assert reader.info.width is None and reader.info.height is None
        assert sum(len(c.events) for c in reader) == 2


def test_an_npy_field_that_is_a_sub_array_is_a_format_error(tmp_path: Path) -> None:
    """What `bench fuzz` found: a damaged descr gave field t the shape (0,), and the copy into the
    event array raised numpy's ValueError (a traceback)."""
    header = b"{'descr': [('t', '<i8', (0,)), ('x', '<u2'), ('y', '<u2'), ('p', 'u1')], 'fortran_order': False, 'shape': (3,), }\n"
    path = tmp_path / "sub.npy"
    path.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + bytes(15))
    with pytest.raises(FlagtrackError, match="field 't'"):
        read_whole(path)
