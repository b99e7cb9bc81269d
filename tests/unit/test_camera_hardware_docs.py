"""The configs docs/cameras.md tells users to write are valid rig files and open (on the fake SDKs)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from flagtrack.daemon.rig.build import open_camera
from flagtrack.daemon.rig.config import load_rig

DOC = Path(__file__).resolve().parents[2] / "docs" / "cameras.md"
BLOCKS = {re.search(r"adapter: (\w+)", b).group(1): b for b in re.findall(r"```yaml\n(.*?)```", DOC.read_text(), re.S)}


def test_the_doc_has_one_config_per_adapter() -> None:
    assert sorted(BLOCKS) == ["inivation", "metavision", "prophesee"]


@pytest.mark.parametrize("adapter", ["prophesee", "metavision", "inivation"])
def test_doc_config_loads_and_opens(adapter: str, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    if adapter == "prophesee":
        nd = request.getfixturevalue("fake_nd")
        nd._fake.plug(nd.FakeCamera(serial="00050423"))
    elif adapter == "metavision":
        hal = request.getfixturevalue("fake_hal")
        hal._fake.plug(hal.FakeHalCamera(serial="00ca0009"))
    else:
        dv = request.getfixturevalue("fake_dv")
        dv._fake.plug(dv.FakeDvCamera(serial="DXA00093"))
    path = tmp_path / "rig.yaml"
    path.write_text(BLOCKS[adapter])
    camera = open_camera(load_rig(path).camera)
    info = camera.open()
    camera.close()
    assert info.adapter == adapter and info.settings["roi"] is not None and info.settings["trigger_in"] is True
