"""The configs docs/cameras.md tells users to write are valid rig files and open (on the fake SDKs)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from flagtrack.daemon.rig.build import open_camera
from flagtrack.daemon.rig.config import load_rig

DOC = Path(__file__).resolve().parents[2] / "docs" / "cameras.md"
YAML = re.findall(r"```yaml\n(.*?)```", DOC.read_text(), re.S)
BLOCKS = {re.search(r"adapter: (\w+)", b).group(1): b for b in YAML if "roi: auto" not in b}
(AUTO,) = [b for b in YAML if "roi: auto" in b]


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


def test_the_doc_auto_config_works_out_the_roi_and_the_rate_limiter(fake_nd, tmp_path: Path) -> None:
    from flagtrack.daemon.rig.build import open_hardware_camera

    cam = fake_nd._fake.plug(fake_nd.FakeCamera())
    path = tmp_path / "rig.yaml"
    path.write_text(AUTO)
    opened = open_hardware_camera(load_rig(path))
    assert opened is not None
    info = opened.open()
    opened.close()
    assert sorted(info.settings["auto"]) == ["rate_limiter", "roi"]
    assert info.settings["roi"] == {"x": 120, "y": 0, "width": 457, "height": 667}
    assert cam.applied.rate_limiter.maximum_events_per_period == 2000
