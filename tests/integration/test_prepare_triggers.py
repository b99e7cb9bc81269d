"""The demo's rig now has a sync generator on the twin's trigger input and a point sensor that reads the pulses
back from each point's raw file: those take kernels of their own (a first run compiled them for 2 s while the rig
ran, and the twin fell behind real time). After the preparation, running that path compiles nothing more."""

from __future__ import annotations

import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow

CODE = """
import sys, tempfile
from pathlib import Path
from flagtrack.daemon.commands.demo import demo_rig
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.rig.run import prepare_services
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.daemon.validation.collect import raw_triggers
from flagtrack.drivers.camera.simulated import SimulatedCamera
from flagtrack.drivers.formats import _evt2_kernels, _evt3_kernels, _packet_kernels, open_writer
from flagtrack.drivers.formats.packets import PacketParams, Packetizer

def signatures():
    return sum(len(getattr(f, "signatures", ())) for m in (_evt2_kernels, _evt3_kernels, _packet_kernels)
               for f in vars(m).values())

warm = sys.argv[1] == "warm"
rig = from_mapping(RigConfig, demo_rig(Path(tempfile.mkdtemp()), True, True), key="demo")
prepare_services(rig, list(rig.services) if warm else ["tracker", "supervisor"])  # cold: no trigger warm-up
before = signatures()
camera = SimulatedCamera(rig.camera.simulated)  # the camera service's path: read, packetize (pulses included)
info = camera.open()
packetizer = Packetizer(info.encoding, info.width, info.height, PacketParams(rig.camera.packet_us))
packets, pulses = [], 0
while pulses == 0 or len(packets) < 30:
    data = camera.read(0.05)
    if data is not None:
        pulses += len(data.triggers)
        packets += packetizer.push(data.events, data.triggers, data.t_until_us)
        if len(data.triggers):
            with_pulses = data
path = Path(tempfile.mkdtemp()) / "point.raw"  # the recorder's file, read back by the point's sensor check
with open_writer(path, width=info.width, height=info.height, encoding=info.encoding) as writer:
    writer.write(with_pulses.events, with_pulses.triggers)
assert len(raw_triggers(path)) == len(with_pulses.triggers) > 0
print(before, signatures(), pulses)
"""


@pytest.mark.parametrize("prepared", ["warm", "cold"])
def test_the_trigger_path_is_compiled_before_the_rig_runs(prepared: str) -> None:
    done = subprocess.run([sys.executable, "-c", CODE, prepared], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    before, after, pulses = map(int, done.stdout.split())
    assert pulses > 0
    if prepared == "warm":
        assert after == before, "kernels loaded while the rig ran"
    else:  # without the trigger warm-up (the rig as it was), the same path loads kernels as it runs
        assert after > before
