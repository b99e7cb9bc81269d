"""Ahead-of-time (AOT) builds of the kernels a run used: native start-up without numba.

Loading numba and its CPU target costs about 0.9 s per process, most of the start-up of
``flagtrack reconstruct`` (the kernels themselves load from numba's cache in a few ms). This module,
like numba's own on-disk cache, keeps compiled code between runs, as one extension module
built with ``numba.pycc``: a process that :func:`enable` s it runs the kernels natively through
:mod:`flagtrack.daemon.core.jit` without importing numba at all.

- :func:`enable` loads the module built for the current sources (a digest of ``daemon/core`` and
  ``drivers/formats`` sources, numba's version, the Python ABI and the CPU), if there is one, and
  starts recording the kernel signatures that still go through numba.
- :func:`build_recorded` (after a run) builds, in a child process with an empty numba cache (pycc
  links LLVM IR, not cached object code), one exported trampoline per (kernel, signature) that went
  through numba in this process, plus those of the loaded module. Each trampoline calls the numba
  dispatcher of the kernel, compiled with the kernel's own options (``error_model``, ``fastmath``),
  for the host CPU, so native and JIT runs compute the same thing.

Files live in ``$FLAGTRACK_AOT_DIR`` (default ``~/.cache/flagtrack/aot``); ``FLAGTRACK_AOT=0``
disables both loading and building. Stale builds (other digest) are left for the user to clean.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import logging
import os
import pickle
import sys
import sysconfig
import time
from pathlib import Path
from typing import Any

from flagtrack.daemon.core import jit

log = logging.getLogger(__name__)

_SOURCES = (Path(__file__).parent, Path(__file__).parent.parent.parent / "drivers" / "formats")
_loaded: dict[str, Any] = {"exports": [], "types": None}


def enabled() -> bool:
    """False when ``FLAGTRACK_AOT=0``."""
    return os.environ.get("FLAGTRACK_AOT", "1") != "0"


def cache_dir() -> Path:
    """Folder of the AOT builds."""
    env = os.environ.get("FLAGTRACK_AOT_DIR")
    return Path(env) if env else Path.home() / ".cache" / "flagtrack" / "aot"


def digest() -> str:
    """Digest of everything the compiled code depends on (sources, numba, Python ABI, CPU)."""
    h = hashlib.sha256()
    for folder in _SOURCES:
        for path in sorted(folder.glob("*.py")):
            h.update(path.name.encode())
            h.update(path.read_bytes())
    spec = importlib.util.find_spec("numba")
    if spec is not None and spec.origin:
        version = Path(spec.origin).with_name("_version.py")
        h.update(version.read_bytes() if version.is_file() else spec.origin.encode())
    h.update(str(sysconfig.get_config_var("EXT_SUFFIX")).encode())
    h.update(_cpu_flags().encode())
    return h.hexdigest()[:16]


def _cpu_flags() -> str:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith(("flags", "Features")):
                    return line
    except OSError:
        pass
    import platform

    return platform.processor() or platform.machine()


def _manifest_path(tag: str) -> Path:
    return cache_dir() / f"flagtrack_aot_{tag}.pkl"


def enable() -> int:
    """Load the AOT module of the current sources if built; record what still runs through numba.

    Returns:
        The number of native functions installed (0 if none was built or AOT is disabled).
    """
    if not enabled():
        return 0
    jit.record_calls(True)
    manifest_path = _manifest_path(digest())
    if not manifest_path.is_file():
        return 0
    try:
        manifest = pickle.loads(manifest_path.read_bytes())
        so_path = manifest_path.with_name(manifest["file"])
        loader = importlib.machinery.ExtensionFileLoader(manifest["module"], str(so_path))
        spec = importlib.util.spec_from_loader(loader.name, loader)
        module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
        loader.exec_module(module)
    except Exception as exc:  # noqa: BLE001 - a broken cache must not stop a run
        log.warning("ignoring the AOT kernels of %s: %s", manifest_path, exc)
        return 0
    for entry in manifest["exports"]:
        jit.install_native(entry["key"], entry["arg_keys"], getattr(module, entry["name"]))
    _loaded.update(exports=manifest["exports"], types=manifest_path.with_name(manifest["types"]))
    log.debug("%d AOT kernels from %s", len(manifest["exports"]), so_path)
    return len(manifest["exports"])


def disable() -> None:
    """End of a command: stop recording signatures and drop the native functions, so that code
    running later in the same process (tests, services) uses numba's dispatchers as before."""
    jit.record_calls(False)
    jit.uninstall_natives()
    _loaded.update(exports=[], types=None)


def pending() -> list[dict[str, Any]]:
    """Kernel signatures that went through numba in this process (candidates for a build)."""
    out = []
    for kernel in jit.kernels():
        for arg_keys, types in kernel.calls.items():
            out.append({"key": kernel.key, "module": kernel.py_func.__module__, "qualname": kernel.py_func.__qualname__,
                        "arg_keys": arg_keys, "types": types})
    return out


def build_recorded(timeout_s: float = 600.0) -> Path | None:
    """Build the AOT module of the current sources for the recorded and loaded signatures.

    The module file is named after its content and the manifest (named after the sources' digest)
    is replaced atomically, so concurrent runs and builds always see a consistent pair.

    Returns:
        The module path, or None if there was nothing new to build or the build failed (logged).
    """
    import subprocess
    import tempfile

    new = pending()
    if not enabled() or not new:
        return None
    old = list(_loaded["exports"])
    if old:
        types = pickle.loads(_loaded["types"].read_bytes())
        old = [{**e, "types": t} for e, t in zip(old, types)]
    entries = old + new
    tag = digest()
    content = hashlib.sha256(repr([(e["key"], e["arg_keys"]) for e in entries]).encode()).hexdigest()[:8]
    name = f"flagtrack_aot_{tag}_{content}"
    folder = cache_dir()
    folder.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="flagtrack-aot-") as tmp:
        request = Path(tmp) / "request.pkl"
        request.write_bytes(pickle.dumps({"entries": entries, "name": name, "out_dir": tmp}))
        env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(tmp) / "numba-cache")}
        proc = subprocess.run([sys.executable, "-m", "flagtrack.daemon.core.aot", str(request)], env=env,
                              capture_output=True, text=True, timeout=timeout_s, check=False)
        so_name = name + str(sysconfig.get_config_var("EXT_SUFFIX"))
        built = Path(tmp) / so_name
        if proc.returncode != 0 or not built.is_file():
            log.warning("AOT build failed (%d): %s", proc.returncode, proc.stderr.strip()[-2000:])
            return None
        types_name = f"{name}.types.pkl"
        (Path(tmp) / types_name).write_bytes(pickle.dumps([e["types"] for e in entries]))
        manifest = {"module": name, "file": so_name, "types": types_name,
                    "exports": [{k: e[k] for k in ("key", "module", "qualname", "arg_keys")} | {"name": f"k{i}"}
                                for i, e in enumerate(entries)]}
        (Path(tmp) / "manifest.pkl").write_bytes(pickle.dumps(manifest))
        for file in (so_name, types_name):  # same file system or not: copy, then rename in place
            part = folder / f"{file}.{os.getpid()}.part"
            part.write_bytes((Path(tmp) / file).read_bytes())
            os.replace(part, folder / file)
        part = folder / f"manifest.{os.getpid()}.part"
        part.write_bytes((Path(tmp) / "manifest.pkl").read_bytes())
        os.replace(part, _manifest_path(tag))
    log.info("built %d AOT kernels in %.1f s: %s", len(entries), time.perf_counter() - started, folder / so_name)
    _prune(folder, keep=(so_name, types_name, _manifest_path(tag).name))
    return folder / so_name


def _prune(folder: Path, keep: tuple[str, ...], max_age_s: float = 86400.0) -> None:
    """Remove the builds of other sources or export sets not used for ``max_age_s``."""
    now = time.time()
    for path in folder.glob("flagtrack_aot_*"):
        try:
            if path.name not in keep and now - path.stat().st_atime > max_age_s:
                path.unlink()
        except OSError:
            pass


def _build(request_path: Path) -> None:
    """Child process: compile the requested trampolines into an extension module."""
    import importlib
    import warnings

    from numba.core.typing import signature

    request = pickle.loads(request_path.read_bytes())
    name, out_dir = request["name"], request["out_dir"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from numba.pycc import CC

        cc = CC(name)
    cc.output_dir = out_dir
    cc.target_cpu = "host"
    for i, entry in enumerate(request["entries"]):
        module = importlib.import_module(entry["module"])
        kernel = getattr(module, entry["qualname"])
        dispatcher = kernel.dispatcher if isinstance(kernel, jit.LazyKernel) else kernel
        types = tuple(entry["types"])
        dispatcher.compile(types)
        cres = dispatcher.overloads[types]
        names = ", ".join(f"a{j}" for j in range(len(types)))
        namespace: dict[str, Any] = {"_kernel": dispatcher}
        exec(f"def k{i}({names}):\n    return _kernel({names})\n", namespace)  # noqa: S102 - generated trampoline
        cc.export(f"k{i}", signature(cres.signature.return_type, *types))(namespace[f"k{i}"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cc.compile()


if __name__ == "__main__":
    jit.materialize()
    _build(Path(sys.argv[1]))
