"""The metavision adapter on the real OpenEB HAL, which opens a RAW file as a device.

Each real RAW recording, read through the adapter (in hundreds of HAL buffers), gives exactly the
events flagtrack's own reader gives, and the HAL's log of the device's bytes (``raw_log_dir``) is
the recording's EVT stream byte for byte; one goes through the camera service and out of its packets
unchanged. A recording flagtrack simulated opens in the HAL too, which reports flagtrack as its
integrator; flagtrack-written triggers come through. The fake ``metavision_hal`` has the real
module's names, method names, event dtypes and buffer type.

The HAL runs in a child Python (tests/integration/openeb_child.py): where ``metavision_hal`` already
imports, or with the OpenEB build that ``FLAGTRACK_OPENEB`` names (a folder holding its ``lib/`` and
``py3/``, or an install prefix with ``lib/python3/dist-packages``). Elsewhere the tests skip with the
reason. The HAL writes an index beside a RAW file it indexes: the children open copies, with indexing off.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.core.events import TRIGGER_DTYPE, make_events
from flagtrack.drivers.formats import read_events, write_events
from flagtrack.drivers.formats.raw_file import read_header_bytes
from flagtrack.drivers.formats.raw_header import parse_raw_header
from flagtrack.drivers.sim.simulate import write_events_file
from tests.conftest import REPO, SHARED_REAL

RAW_FILES = sorted(p.name for p in SHARED_REAL.glob("*.raw")) or ["(no real recordings)"]


def _openeb_env() -> dict[str, str]:
    """This process's environment, plus the OpenEB build FLAGTRACK_OPENEB names (if it does)."""
    env = dict(os.environ)
    root = env.get("FLAGTRACK_OPENEB")
    if root:
        lib = Path(root) / "lib"
        plugins = lib / "metavision" / "hal" / "plugins"
        env["LD_LIBRARY_PATH"] = os.pathsep.join(p for p in (str(lib), env.get("LD_LIBRARY_PATH")) if p)
        env.setdefault("MV_HAL_PLUGIN_PATH", str(plugins if plugins.is_dir() else lib))
        python = [Path(root) / "py3", lib / "python3" / "dist-packages"]
        paths = [str(p) for p in python if p.is_dir()] + [str(REPO)] + [env.get("PYTHONPATH", "")]
        env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
    return env


@pytest.fixture(scope="module")
def openeb() -> dict[str, str]:
    """The environment in which a child Python imports the real metavision_hal (else skip, saying why)."""
    env = _openeb_env()
    probe = subprocess.run(
        [sys.executable, "-c", "import metavision_hal"], env=env, capture_output=True, text=True, timeout=120
    )
    if probe.returncode != 0:
        why = (probe.stderr.strip().splitlines() or ["no error text"])[-1]
        pytest.skip(
            f"metavision_hal does not import ({why}); set FLAGTRACK_OPENEB to an OpenEB build (docs/cameras.md)"
        )
    return env


def child(env: dict[str, str], command: str, source: Path, target: Path) -> dict:
    """Run openeb_child ``command``; its info.json (or the JSON file it wrote)."""
    done = subprocess.run(
        [sys.executable, "-m", "tests.integration.openeb_child", command, str(source), str(target)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, f"openeb_child {command} {source.name} failed:\n{done.stderr[-3000:]}"
    return json.loads((target if target.suffix == ".json" else target / "info.json").read_text())


def copy_in(source: Path, folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    return Path(shutil.copy(source, folder / source.name))


def body_offset(data: bytes) -> int:
    """Where the EVT stream of a RAW file's bytes starts."""
    return parse_raw_header(data[: 1 << 16])[1]


def adapter_output(out: Path) -> tuple[np.ndarray, np.ndarray]:
    return np.load(out / "events.npy"), np.load(out / "triggers.npy")


@pytest.mark.shared_data
@pytest.mark.parametrize("name", RAW_FILES)
def test_the_adapter_hands_over_every_event_of_a_real_recording(
    name: str, shared_real: Path, openeb: dict[str, str], tmp_path: Path
) -> None:
    raw = copy_in(shared_real / name, tmp_path / "in")
    (out := tmp_path / "out").mkdir()
    info = child(openeb, "read", raw, out)
    events, triggers = adapter_output(out)
    rec = read_events(raw, strict=True)
    assert (info["adapter"], info["encoding"], info["settings"]["data_path"]) == ("metavision", "evt2", "hal_decoder")
    assert (info["width"], info["height"]) == (rec.info.width, rec.info.height)
    assert info["reads"] >= len(rec.events) // 2000  # hundreds of buffers, each cut anywhere
    np.testing.assert_array_equal(events, rec.events)
    np.testing.assert_array_equal(triggers, rec.triggers)
    horizons = [h for h in info["horizons"] if h is not None]
    assert horizons == sorted(horizons) and horizons[-1] >= rec.events["t"][-1]
    assert sorted(p.name for p in raw.parent.iterdir()) == [name]  # no index file written beside it
    logged = Path(info["settings"]["raw_log"]).read_bytes()  # the HAL's copy of the device's bytes
    source = raw.read_bytes()
    assert logged[body_offset(logged) :] == source[body_offset(source) :]


@pytest.mark.shared_data
def test_the_camera_service_publishes_a_real_recording_read_through_the_hal(
    shared_real: Path, openeb: dict[str, str], tmp_path: Path
) -> None:
    name = max(RAW_FILES, key=lambda n: (shared_real / n).stat().st_size)
    raw = copy_in(shared_real / name, tmp_path / "in")
    (out := tmp_path / "out").mkdir()
    info = child(openeb, "service", raw, out)
    events, _ = adapter_output(out)
    assert info["packets"] == info["sent"] >= 10 and info["encodings"] == ["evt2"] and info["end_of_stream"]
    np.testing.assert_array_equal(events, read_events(raw, strict=True).events)


def _synthetic(n: int = 20_000, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, 3_000_000, n))
    events = make_events(t, rng.integers(0, 640, n), rng.integers(0, 480, n), rng.integers(0, 2, n))
    triggers = np.zeros(60, TRIGGER_DTYPE)
    triggers["t"] = np.sort(rng.choice(3_000_000, 60, replace=False))
    triggers["channel"], triggers["edge"] = rng.integers(0, 2, 60), np.arange(60) % 2
    return events, triggers


def test_the_hal_opens_a_simulated_recording_which_says_flagtrack_made_it(
    openeb: dict[str, str], tmp_path: Path
) -> None:
    events, _ = _synthetic()
    (tmp_path / "in").mkdir()
    raw, _ = write_events_file(tmp_path / "in" / "sim", [events[:5000], events[5000:]], 640, 480)
    fields, _ = parse_raw_header(read_header_bytes(raw))
    assert fields["camera_integrator_name"] == fields["integrator_name"] == "flagtrack" and "plugin_name" not in fields
    assert fields["simulator"].startswith("flagtrack ")
    (out := tmp_path / "out").mkdir()
    info = child(openeb, "read", raw, out)
    assert info["settings"]["integrator"] == "flagtrack" and info["settings"]["device_encoding"] == "EVT3"
    np.testing.assert_array_equal(adapter_output(out)[0], events)


@pytest.mark.parametrize("encoding", ["evt3", "evt2"])
def test_triggers_come_through_the_hal(encoding: str, openeb: dict[str, str], tmp_path: Path) -> None:
    events, triggers = _synthetic(seed=2)
    (tmp_path / "in").mkdir()
    write_events(raw := tmp_path / "in" / "t.raw", events, width=640, height=480, encoding=encoding, triggers=triggers)
    (out := tmp_path / "out").mkdir()
    child(openeb, "read", raw, out)
    got_events, got_triggers = adapter_output(out)
    np.testing.assert_array_equal(got_events, events)
    np.testing.assert_array_equal(got_triggers, triggers)


def test_the_fake_bindings_have_the_real_names_and_types(
    openeb: dict[str, str], tmp_path: Path, fake_hal: object
) -> None:
    (tmp_path / "in").mkdir()
    events, _ = _synthetic(n=2000)
    write_events(raw := tmp_path / "in" / "s.raw", events, width=640, height=480, encoding="evt3")
    real = child(openeb, "surface", raw, tmp_path / "surface.json")
    fake = vars(fake_hal)
    classes = {k: v for k, v in fake.items() if isinstance(v, type) and not k.startswith("_")}
    mirrored = {k: v for k, v in classes.items() if k not in fake_hal.TEST_CONTROLS}
    assert {"RawBuffer", "I_EventsStream", "I_Decoder", "I_EventDecoder_EventCD", "Device"} <= set(mirrored)
    for name, cls in mirrored.items():
        assert name in real["names"], f"the fake has {name}, the bindings do not"
        members = {m for m in dir(cls) if not m.startswith("_")}
        assert members <= set(real["names"][name]), f"{name}: the bindings lack {members - set(real['names'][name])}"
        for inner in (m for m in members if isinstance(getattr(cls, m), type)):
            inner_members = {m for m in dir(getattr(cls, inner)) if not m.startswith("_")}
            assert inner_members <= set(real["names"][f"{name}.{inner}"]) | {"name", "value"}, f"{name}.{inner}"
    for name in ("RawBuffer", "I_EventsStream", "I_Decoder"):  # the data path: every method, no more, no less
        assert {m for m in dir(mirrored[name]) if not m.startswith("_")} == set(real["names"][name]), name
    assert real["buffer_type"] == "RawBuffer" and not any(real["buffer_readable"].values())
    hal_dtypes = {
        "EventCD": fake_hal._events_stream.EVENT_CD_DTYPE,
        "EventExtTrigger": fake_hal._events_stream.EVENT_EXT_TRIGGER_DTYPE,
    }
    for name, dtype in hal_dtypes.items():
        assert real["dtypes"][name] == {"descr": str(dtype.descr), "itemsize": dtype.itemsize}, name
