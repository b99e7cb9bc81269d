"""Kernels compiled ahead of time (``flagtrack kernels build``): loaded without numba, same results,
stale builds ignored."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.aot import cache
from flagtrack.daemon.aot.build import build

PACKETS = """
import hashlib, sys
import numpy as np
from flagtrack.daemon.core.events import make_events
from flagtrack.drivers.formats.packets import Packetizer, decode_packet
n = 3000
t = np.arange(n, dtype=np.int64) * 7
events = make_events(t, 10 + (np.arange(n) % 50), 10 + (np.arange(n) // 50), np.arange(n) % 2)
digest = hashlib.sha256()
packetizer = Packetizer("evt3", 64, 128)
for packet in packetizer.push(events) + packetizer.flush():
    decoded, _ = decode_packet("evt3", packet.data, packet.t_offset_us)
    digest.update(packet.data + decoded.tobytes())
"""
SCRIPT = (
    "from flagtrack.daemon.core import jit_hook\nfrom flagtrack.daemon.aot.cache import load\njit_hook.loader = load\n"
    + PACKETS
    + """
print("digest", digest.hexdigest())
print("numba_after_packets", "numba" in sys.modules)
from flagtrack.daemon.core.tracker import track
from flagtrack.daemon.tracking.section import TrackingConfig
batch = track(events, TrackingConfig(root=(10.0, 40.0), length=30.0).tracker_params())
print("numba_after_tracking", "numba" in sys.modules, len(batch.t_s) > 0)
"""
)


# The build runs in a fresh process: one exports every signature its process compiled, so a build
# run here would also take the kernels earlier tests compiled (the tracker's, say).
BUILD = (
    "from flagtrack.daemon.aot.build import build\n"
    f"result = build(workload=lambda folder: exec({PACKETS!r}, {{}}))\n"
    "print('exports', result.exports)\nprint('folder', result.folder)\n"
)


def _run(env: dict[str, str], script: str = SCRIPT) -> dict[str, str]:
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300, check=True, env=env
    )
    return dict(line.split(" ", 1) for line in out.stdout.splitlines())


@pytest.mark.slow
@pytest.mark.skipif(not (shutil.which("cc") or shutil.which("gcc")), reason="numba.pycc needs a C compiler to link")
def test_a_build_loads_without_numba_gives_the_same_bytes_and_is_ignored_when_stale(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv(cache.ENV_CACHE, str(tmp_path))
    env = {**os.environ, cache.ENV_CACHE: str(tmp_path)}
    built = _run(env, BUILD)
    folder = Path(built["folder"])
    assert int(built["exports"]) >= 4 and (folder / cache.MANIFEST).is_file()

    compiled = _run(env)
    assert compiled["numba_after_packets"] == "False"  # the packet path ran on the build alone
    assert compiled["numba_after_tracking"] == "True True"  # the tracker, not built, fell back to numba
    numba_only = _run({**env, cache.ENV_MODE: "numba"})
    assert numba_only["numba_after_packets"] == "True"
    assert compiled["digest"] == numba_only["digest"]  # the same packets, decoded to the same events

    manifest_path = folder / cache.MANIFEST
    manifest = json.loads(manifest_path.read_text())
    some_source = next(iter(manifest["sources"]))
    manifest["sources"][some_source] = "0" * 64  # as if that kernel's source had changed since the build
    manifest_path.write_text(json.dumps(manifest))
    assert cache.read_manifest(folder) is None
    assert _run(env)["numba_after_packets"] == "True"  # a stale build is not used


def test_no_build_means_numba(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv(cache.ENV_CACHE, str(tmp_path))
    assert cache.load() is None
    assert not np.any([p.name == cache.MANIFEST for p in tmp_path.rglob("*")])


@pytest.mark.filterwarnings("ignore::numba.core.errors.NumbaPendingDeprecationWarning")  # numba.pycc's own
def test_a_build_that_cannot_compile_is_one_clear_error_and_leaves_nothing(tmp_path, monkeypatch) -> None:
    from numba.pycc import CC

    from flagtrack.daemon.errors import FlagtrackError

    def no_compiler(self) -> None:
        raise OSError("no C compiler found")

    monkeypatch.setenv(cache.ENV_CACHE, str(tmp_path))
    monkeypatch.setattr(CC, "compile", no_compiler)
    with pytest.raises(FlagtrackError, match="cannot compile the kernels ahead of time .*no C compiler found"):
        build(workload=lambda folder: None)
    assert list(tmp_path.rglob("*.json")) == [] and cache.load() is None
