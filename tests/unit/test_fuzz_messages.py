"""Property-based fuzzing of what arrives on the bus: the wire-schema decoder (any bytes, damaged valid
messages: a message or a SchemaError, in bounded memory) and the packet decoder (any bytes, encoding
and time offset: events or a FormatError). `flagtrack bench fuzz` runs the same properties longer."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flagtrack.daemon.bench.fuzz_targets import (
    MEMORY_LIMIT_BYTES,
    check_message,
    check_packet,
    damaged,
    sample_messages,
)

SAMPLES = sample_messages()
edits = st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 255)), min_size=1, max_size=4)


@settings(max_examples=150, deadline=None)
@given(data=st.one_of(st.binary(max_size=2048), st.builds(lambda i, e, c: damaged(SAMPLES[i], e, c, False),
       st.integers(0, len(SAMPLES) - 1), edits, st.one_of(st.none(), st.floats(0, 1)))))  # fmt: skip
def test_any_bytes_decode_to_a_message_or_a_schema_error(data: bytes) -> None:
    check_message(data)


def test_the_memory_bound_would_catch_a_huge_allocation(monkeypatch: pytest.MonkeyPatch) -> None:
    """The property's own check fails where a decoder allocates beyond the bound (the defence seen failing)."""
    import numpy as np

    import flagtrack.daemon.schema as schema

    def greedy(data: bytes, *args: object, **kwargs: object) -> None:
        np.ones(MEMORY_LIMIT_BYTES // 8 + (1 << 20))  # what trusting a message's declared shape would cost

    monkeypatch.setattr(schema, "decode", greedy)
    with pytest.raises(AssertionError, match="allocated"):
        check_message(b"FT")


offsets = st.one_of(
    st.integers(-(1 << 63), (1 << 63) - 1),
    st.builds(lambda k, n: k * n, st.integers(0, 500), st.sampled_from([1 << 24, 1 << 34])),
)


@settings(max_examples=150, deadline=None)
@given(encoding=st.sampled_from(["evt2", "evt21", "evt3", "evt4"]), data=st.binary(max_size=4096), t_offset_us=offsets)
def test_any_packet_decodes_or_is_a_format_error(encoding: str, data: bytes, t_offset_us: int) -> None:
    check_packet(encoding, data, t_offset_us)
