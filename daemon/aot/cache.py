"""Where the kernels compiled ahead of time live, and loading them (no numba import).

A build is a folder ``<cache>/<key>/`` holding the extension module and ``manifest.json``; ``key``
names the Python version, the machine, its CPU and the installation's folder (two checkouts keep
two builds). The manifest lists the hash of every kernel
module's source: when any differs from the installed sources (an upgrade, an edit), the build is
stale and is not used (numba takes over, as without a build).
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import json
import logging
import os
import platform
import sys
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

MODULE_NAME = "_flagtrack_kernels"
MANIFEST = "manifest.json"
FORMAT_VERSION = 1
ENV_CACHE = "FLAGTRACK_KERNEL_CACHE"
ENV_MODE = "FLAGTRACK_KERNELS"
"""``numba``: never load a build (every kernel through numba, as before builds existed)."""


def cache_root() -> Path:
    """The folder of the builds: ``$FLAGTRACK_KERNEL_CACHE``, else ``$XDG_CACHE_HOME/flagtrack/kernels``
    (``~/.cache/flagtrack/kernels``)."""
    if os.environ.get(ENV_CACHE):
        return Path(os.environ[ENV_CACHE])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "flagtrack" / "kernels"


def _cpu_id() -> str:
    """The CPU model and its feature flags (a build runs only on the CPU it was compiled for)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            text = f.read(16384)
    except OSError:
        return platform.processor()
    picked = [line for line in text.splitlines() if line.startswith(("model name", "flags"))][:2]
    return "\n".join(picked) or platform.processor()


def build_key() -> str:
    """The folder name of this interpreter's, CPU's and installation's build."""
    ident = f"{sys.implementation.cache_tag}|{platform.machine()}|{_cpu_id()}|{FORMAT_VERSION}|{package_root()}"
    return f"{sys.implementation.cache_tag}-{platform.machine()}-{hashlib.sha256(ident.encode()).hexdigest()[:16]}"


def package_root() -> Path:
    """The folder holding flagtrack's ``daemon/`` and ``drivers/`` (sources are named relative to it)."""
    import flagtrack.daemon

    return Path(flagtrack.daemon.__file__).resolve().parent.parent


def source_hashes(paths: list[str], root: Path | None = None) -> dict[str, str]:
    """SHA-256 of each source file (relative to :func:`package_root`); a missing file hashes to ''."""
    root = root or package_root()
    hashes = {}
    for rel in paths:
        try:
            hashes[rel] = hashlib.sha256((root / rel).read_bytes()).hexdigest()
        except OSError:
            hashes[rel] = ""
    return hashes


def build_dir() -> Path:
    """The folder of this machine's build."""
    return cache_root() / build_key()


def read_manifest(folder: Path) -> dict[str, Any] | None:
    """The build's manifest, or None when absent, unreadable or stale (sources changed)."""
    try:
        manifest = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT_VERSION:
        return None
    sources = manifest.get("sources", {})
    if not isinstance(sources, dict) or source_hashes(list(sources)) != sources:
        return None
    return manifest


def _spec(arg: list[Any]) -> tuple[Any, ...]:
    import numpy as np

    dtype = np.lib.format.descr_to_dtype(arg[1]) if isinstance(arg[1], list) else np.dtype(arg[1])
    if arg[0] == "a":
        return ("a", dtype, int(arg[2]), bool(arg[3]), bool(arg[4]), bool(arg[5]))
    return ("s", dtype.name)


def load() -> dict[str, list[tuple[tuple[Any, ...], Any]]] | None:
    """The compiled kernels of this machine's build (kernel name -> [(argument specs, function)]),
    or None when there is no usable build (then numba compiles or loads every kernel, as before)."""
    if os.environ.get(ENV_MODE, "").lower() == "numba":
        return None
    folder = build_dir()
    manifest = read_manifest(folder)
    if manifest is None:
        return None
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    spec = importlib.util.spec_from_file_location(MODULE_NAME, folder / f"{MODULE_NAME}{suffix}")
    if spec is None or spec.loader is None:
        return None
    try:
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    except (ImportError, OSError) as exc:
        log.info("kernels compiled ahead of time not loaded (%s): numba compiles them", exc)
        return None
    table: dict[str, list[tuple[tuple[Any, ...], Any]]] = {}
    for entry in manifest.get("exports", []):
        function = getattr(module, entry["export"], None)
        if function is not None:
            table.setdefault(entry["kernel"], []).append((tuple(_spec(a) for a in entry["args"]), function))
    return table
