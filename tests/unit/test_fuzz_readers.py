"""Property-based fuzzing of the event-file readers: damaged files give flagtrack's own errors only.

Each case starts from a valid small file of one format and damages it (bytes replaced, a cut, a
header byte changed); reading it whole must either work or raise a ``FlagtrackError`` (a
``FormatError`` naming the file), never another exception. ``flagtrack bench fuzz`` runs the same
properties for longer.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flagtrack.daemon.errors import FlagtrackError
from flagtrack.drivers.formats import open_events, write_events
from flagtrack.drivers.sim.quickline import WavyFlag, line_events

FORMATS = {"evt3.raw": {"encoding": "evt3"}, "evt2.raw": {"encoding": "evt2"}, "npy": {}, "csv": {}}


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


@pytest.mark.parametrize("name", sorted(FORMATS))
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(damage=damage)
def test_a_damaged_file_is_read_or_refused_with_our_error(
    originals: dict[str, bytes], tmp_path: Path, name: str, damage: tuple
) -> None:
    edits, cut, in_header = damage
    data = bytearray(originals[name])
    span = min(len(data), 160) if in_header else len(data)  # the header and the first words, or anywhere
    for where, value in edits:
        data[int(where * span)] = value
    if cut is not None:
        data = data[: int(cut * len(data))]
    path = tmp_path / f"damaged.{name}"
    path.write_bytes(bytes(data))
    try:
        read_whole(path)
    except FlagtrackError as exc:
        assert str(path) in str(exc)  # the error names the file


def test_an_unbalanced_npy_header_is_a_format_error(tmp_path: Path) -> None:
    """What the fuzzer found: numpy's header parser raised tokenize.TokenError (a traceback for the user)."""
    header = b"{'descr': [('t', '<i8')], 'fortran_order': False, 'shape': ([10,), }\n"
    path = tmp_path / "bad.npy"
    path.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header)
    with pytest.raises(FlagtrackError, match="garbage .npy header"):
        read_whole(path)
