"""A hardware camera opens after the rig is prepared and streams into its host buffer from then on:
the kernels that cut its words and encode its events into packets are compiled (the first run after
installing: about 5 s) or loaded in the preparation, so the camera service's first reads wait on no
compile. Run in a fresh process, with no kernels built ahead of time."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

CODE = """
import sys
import numpy as np
from flagtrack.daemon.core.events import make_events
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.rig.run import prepare_services
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.drivers.formats import _native_kernels, _packet_kernels
from flagtrack.drivers.formats.native import NativeCutter
from flagtrack.drivers.formats.packets import Packetizer

def signatures():
    return sum(len(getattr(f, "signatures", ())) for m in (_native_kernels, _packet_kernels) for f in vars(m).values())

rig = from_mapping(RigConfig, {"camera": {"adapter": "prophesee"}, "services": ["camera"]}, key="rig")
if sys.argv[1] == "prepared":
    prepare_services(rig, ["camera"])
before = signatures()
events = make_events(np.arange(0, 4000, 10), np.arange(400) % 640, np.arange(400) % 480, np.arange(400) % 2)
for encoding in ("evt3", "evt2"):  # what the camera service does with a device's words or decoded events
    packets = Packetizer(encoding, 640, 480).push(events, t_until_us=5000)
    words = b"".join(p.data[p.preamble_bytes :] for p in packets)
    NativeCutter(encoding).push(words)
print(before, signatures())
"""


@pytest.mark.parametrize("prepared", ["prepared", "not prepared"])
def test_a_hardware_cameras_packet_kernels_are_ready_before_it_opens(prepared: str, tmp_path: Path) -> None:
    env = {**os.environ, "FLAGTRACK_KERNEL_CACHE": str(tmp_path / "no-build")}  # numba's own kernels only
    done = subprocess.run([sys.executable, "-c", CODE, prepared], capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stderr
    before, after = map(int, done.stdout.split())
    if prepared == "prepared":
        assert before > 0 and after == before, "kernels compiled or loaded after the preparation"
    else:  # the check can fail: without the preparation, the same path loads them
        assert after > before
