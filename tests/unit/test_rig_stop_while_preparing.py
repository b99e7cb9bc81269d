"""Ctrl-C while the services prepare (kernels load or compile: up to a minute on a first run) ends the
run cleanly after that step, before anything opens (it was swallowed inside numba, or became a
SystemError traceback)."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from flagtrack.daemon.rig import run as rig_run
from flagtrack.daemon.rig.config import load_rig

REPO = Path(__file__).resolve().parents[2]


def test_a_signal_while_preparing_ends_the_run_before_any_service_starts(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = load_rig(REPO / "deploy" / "rig-sim.yaml")
    prepared: list[str] = []

    def preparing(rig: object, names: list[str], say: object, *, tracker: object = None) -> None:
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C in the middle of the warm-up
        prepared.append("done")  # the warm-up still goes on to its end

    def no_camera(rig: object) -> None:
        raise AssertionError("the camera opened after the stop")

    monkeypatch.setattr(rig_run, "prepare_services", preparing)
    monkeypatch.setattr(rig_run, "open_hardware_camera", no_camera)
    result = rig_run.run_rig(rig, ["camera", "tracker"])
    assert prepared == ["done"]
    assert result.code == 130 and result.services == [] and result.report.signal_count == 1
    assert "stopped by SIGINT before the services started" in capsys.readouterr().err
