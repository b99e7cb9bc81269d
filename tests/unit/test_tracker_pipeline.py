"""The tracker on two threads (prepare | advance): exactly the updates of ``Tracker.feed``."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.chain import ChainParams
from flagtrack.daemon.core.denoise import DenoiseParams
from flagtrack.daemon.core.mapping import AffineMapping
from flagtrack.daemon.core.tracker import Tracker, TrackerParams
from flagtrack.daemon.core.windows import WindowSchedule
from flagtrack.daemon.tracking.pipeline import TrackerPipeline
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag()
FIELDS = ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms", "n_events")


@pytest.fixture(scope="module")
def events() -> np.ndarray:
    params = QuickLineParams(events_per_px2=5, noise_rate_hz=2e5, drop_fraction=0.1)
    events = np.concatenate(list(line_events(FLAG, 1_000_000, 1_040_000, 640, 480, params, seed=3)))
    rng = np.random.default_rng(3)
    jittered = events.copy()  # a sensor whose times step back by up to 5 us: sorted in, counted
    jittered["t"] -= rng.integers(0, 6, len(events))
    return jittered


def _params(denoise: bool) -> TrackerParams:
    chain = ChainParams(root=FLAG.root, length=FLAG.length, min_events=5, refine_deg=10.0)
    return TrackerParams(
        chain=chain, schedule=WindowSchedule.uniform(2.5e-4), denoise=DenoiseParams() if denoise else None
    )


def _assert_same(a: CentrelineBatch, b: CentrelineBatch) -> None:
    assert len(a) == len(b) > 100
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("denoise", [True, False])
@pytest.mark.parametrize("mapped", [False, True])
def test_pipeline_gives_exactly_what_feed_gives(events, denoise, mapped) -> None:
    cuts = np.sort(np.random.default_rng(1).choice(len(events), 40, replace=False))
    chunks = np.split(events, cuts)
    horizons = [int(chunk["t"].max()) if len(chunk) else None for chunk in chunks]
    mapping = AffineMapping(((0.5, 0.1), (-0.1, 0.5)), (3.0, -2.0)) if mapped else None

    alone = Tracker(_params(denoise), mapping=mapping)
    expected = [alone.feed(chunk, horizon) for chunk, horizon in zip(chunks, horizons)] + [alone.finish()]

    piped = Tracker(_params(denoise), mapping=mapping)
    got: list[tuple[CentrelineBatch, object]] = []
    with TrackerPipeline(piped, lambda batch, tag: got.append((batch, tag)), depth=2) as pipeline:
        for i, (chunk, horizon) in enumerate(zip(chunks, horizons)):
            pipeline.feed(chunk, horizon, tag=i)
        pipeline.finish(tag="end")
    assert [tag for _, tag in got] == [*range(len(chunks)), "end"]  # every chunk's updates, in order
    _assert_same(CentrelineBatch.concatenate(expected), CentrelineBatch.concatenate([b for b, _ in got]))
    assert piped.stats == alone.stats
    assert alone.stats.events_out_of_order > 0  # the jitter path (sorting in) was exercised


def test_an_error_on_the_worker_is_raised_in_the_callers_thread(events) -> None:
    def emit(batch: CentrelineBatch, tag: object) -> None:
        if tag == 3:
            raise ValueError("the sink is full")

    with pytest.raises(ValueError, match="the sink is full"):
        with TrackerPipeline(Tracker(_params(True)), emit) as pipeline:
            for i, chunk in enumerate(np.array_split(events, 20)):
                pipeline.feed(chunk, tag=i)
            pipeline.finish()
