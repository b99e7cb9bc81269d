"""Build the kernels ahead of time: learn their signatures on a workload, compile them with ``numba.pycc``.

The workload runs what the commands and services run before their first event and on it: the
EVT 2.0/3.0 readers and packet codecs (bytes as read from a file and as received), the packetizer,
the native word scan,
the readers of .dat/.npy files, and ``reconstruct`` with both tracker methods, with and without the
noise filter. Every signature numba compiled for it is exported (numba's own flags per kernel:
``nogil``, ``fastmath``, ``error_model``) into one extension module for this CPU. A call with
other argument types still goes to numba.
"""

from __future__ import annotations

import json
import re
import shutil
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flagtrack.daemon.aot import cache
from flagtrack.daemon.core import jit
from flagtrack.daemon.errors import FlagtrackError


@dataclass(frozen=True)
class BuildResult:
    """What a build made."""

    folder: Path
    exports: int
    kernels: int
    skipped: int
    workload_s: float
    compile_s: float


def run_workload(folder: Path) -> None:
    """Run the kernels under numba on small synthetic recordings written to ``folder``."""
    import numpy as np

    from flagtrack.daemon.core.events import make_events
    from flagtrack.daemon.core.tracker import Tracker
    from flagtrack.daemon.tracking.offline import reconstruct_file
    from flagtrack.daemon.tracking.section import Method, TrackingConfig
    from flagtrack.daemon.tracking.setup import tracking_setup
    from flagtrack.drivers.formats import write_events
    from flagtrack.drivers.formats.native import NativeCutter
    from flagtrack.drivers.formats.packets import Packetizer, decode_packet
    from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

    chunks = list(line_events(WavyFlag(length=60.0, root=(40.0, 64.0)), 0, 20_000, 128, 128, QuickLineParams(), 0))
    events = np.concatenate(chunks)
    for encoding in ("evt3", "evt2"):
        packetizer = Packetizer(encoding, 128, 128)
        packets = packetizer.push(events, t_until_us=int(events["t"][-1]) + 5000) + packetizer.flush()
        cutter = NativeCutter(encoding)
        for packet in packets + cutter.push(b"".join(p.data for p in packets)) + cutter.flush():
            decode_packet(encoding, packet.data, packet.t_offset_us)
    files = [folder / "w3.raw", folder / "w2.raw", folder / "w.npy", folder / "w.dat"]
    for path, file_encoding in zip(files, ("evt3", "evt2", None, None)):
        write_events(path, events, width=128, height=128, encoding=file_encoding)
    for method in (Method.ROBUST, Method.PAPER):
        config = TrackingConfig(root=(40.0, 64.0), length=60.0, tau_s=2.5e-4, method=method)
        setup = tracking_setup(config)
        for path in files:
            reconstruct_file(path, folder / "out.h5", setup)
        tracker = Tracker(config.tracker_params())
        tracker.feed(make_events(np.array([0, 10]), np.array([40, 41]), np.array([64, 64]), np.array([1, 0])), 20)
        tracker.finish()


def _arg_spec(arg: Any) -> list[Any] | None:
    """The JSON form of one numba argument type (None: a type the compiled module is not used for)."""
    import numpy as np
    from numba import types
    from numba.np.numpy_support import as_dtype

    if isinstance(arg, types.Array):
        if arg.layout not in ("C", "A"):
            return None
        dtype = as_dtype(arg.dtype)
        descr: Any = np.lib.format.dtype_to_descr(dtype) if dtype.fields else dtype.str
        return ["a", descr, arg.ndim, arg.layout == "C", bool(arg.mutable), False]
    if isinstance(arg, types.Boolean | types.Integer | types.Float):
        return ["s", as_dtype(arg).str]
    return None


def _any_alignment(signature: Any) -> Any:
    """The signature with every array argument taken as possibly unaligned (numba types a field view
    of a packed record array as unaligned; code for unaligned arrays runs on aligned ones too)."""
    from numba import types
    from numba.core.typing import signature as make_signature

    args = [
        types.Array(a.dtype, a.ndim, a.layout, readonly=not a.mutable, aligned=False)
        if isinstance(a, types.Array)
        else a
        for a in signature.args
    ]
    return make_signature(signature.return_type, *args)


def _flags_patch(options: dict[Any, dict[str, Any]]) -> Any:
    """numba.pycc compiles with default flags: give each kernel its own (nogil, fastmath, error_model)."""
    import numba.pycc.compiler as pycc_compiler
    from numba.core.compiler import Flags
    from numba.core.cpu import CPUTargetOptions

    original = pycc_compiler.compile_extra

    def compile_extra(  # numba's own parameter names, so that it can be called as numba's is
        typingctx: Any, targetctx: Any, func: Any, args: Any, return_type: Any, flags: Any, *rest: Any, **kw: Any
    ) -> Any:
        kept = {k: v for k, v in options.get(func, {}).items() if k not in ("cache", "inline")}
        own: Any = Flags()  # pycc shares one Flags object between its exports; its options are descriptors
        CPUTargetOptions.parse_as_flags(own, kept)
        own.no_compile, own.nrt = True, flags.nrt
        return original(typingctx, targetctx, func, args, return_type, own, *rest, **kw)

    pycc_compiler.compile_extra = compile_extra
    return original


def build(progress: Any = None, workload: Any = run_workload) -> BuildResult:
    """Compile every kernel signature ``workload(folder)`` makes numba compile into this machine's
    cache folder (replacing the build there)."""
    say = progress or (lambda _msg: None)
    jit.set_compiled_loader(None)  # the workload runs through numba (an older build may be loaded)
    say("tracking and decoding small synthetic recordings, so that numba compiles every kernel (about 40 s) ...")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        workload(Path(tmp))
    workload_s = time.perf_counter() - started
    import llvmlite.binding as llvm
    from numba.core.errors import NumbaPendingDeprecationWarning

    with warnings.catch_warnings():  # numba.pycc is "pending deprecation" with no replacement yet
        warnings.simplefilter("ignore", NumbaPendingDeprecationWarning)
        import numba.pycc.compiler as pycc_compiler
        from numba.pycc import CC

    target = cache.build_dir()
    staging = Path(tempfile.mkdtemp(prefix=".build-", dir=_ensure(target.parent)))
    cc = CC(cache.MODULE_NAME)
    cc.output_dir = str(staging)
    cc.target_cpu = llvm.get_host_cpu_name()
    cc.verbose = False
    exports, options, skipped, kernels = _export_signatures(cc)
    say(f"compiling {len(exports)} signatures of {kernels} kernels ...")
    original = _flags_patch(options)
    compile_started = time.perf_counter()
    try:
        cc.compile()
    except Exception as exc:  # no C compiler, a numba that pycc cannot handle, ...
        shutil.rmtree(staging, ignore_errors=True)
        raise FlagtrackError(
            f"cannot compile the kernels ahead of time ({type(exc).__name__}: {exc}); "
            "numba compiles them at first use, as without a build"
        ) from exc
    finally:
        pycc_compiler.compile_extra = original
    compile_s = time.perf_counter() - compile_started
    manifest = {
        "format": cache.FORMAT_VERSION,
        "python": sys.version,
        "numba": _numba_version(),
        "cpu": cc.target_cpu,
        "sources": cache.source_hashes(_kernel_sources()),
        "exports": exports,
    }
    (staging / cache.MANIFEST).write_text(json.dumps(manifest, indent=1), encoding="utf-8")
    if target.exists():
        shutil.rmtree(target)
    staging.replace(target)
    return BuildResult(target, len(exports), kernels, skipped, workload_s, compile_s)


def _export_signatures(cc: Any) -> tuple[list[dict[str, Any]], dict[Any, dict[str, Any]], int, int]:
    """Export to ``cc`` every signature numba compiled: (the manifest's exports, each kernel's options,
    signatures skipped, kernels)."""
    exports: list[dict[str, Any]] = []
    options: dict[Any, dict[str, Any]] = {}
    skipped = kernels = 0
    for kernel in jit.all_kernels():
        dispatcher = kernel._dispatcher
        if dispatcher is None or not dispatcher.signatures:
            continue
        kernels += 1
        options[kernel.py_func] = dict(kernel.options)
        for i, args in enumerate(dispatcher.signatures):
            specs = [_arg_spec(a) for a in args]
            if any(s is None for s in specs):
                skipped += 1
                continue
            name = f"k{len(exports)}_{kernel.py_func.__name__.lstrip('_')}_{i}"
            cc.export(name, _any_alignment(dispatcher.overloads[args].signature))(kernel.py_func)
            exports.append({"kernel": kernel.name, "export": name, "args": specs})
    return exports, options, skipped, kernels


def _ensure(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _numba_version() -> str:
    import numba

    return str(numba.__version__)


def _kernel_sources() -> list[str]:
    """The source files a build depends on: every module defining a kernel, and the flagtrack modules
    those import (a kernel inlines its callees and the constants it reads)."""
    root = cache.package_root()
    names = {kernel.py_func.__module__ for kernel in jit.all_kernels()} | {jit.__name__}
    for name in list(names):
        module = sys.modules.get(name)
        source = Path(module.__file__).read_text(encoding="utf-8") if module and module.__file__ else ""
        names |= set(re.findall(r"^\s*(?:from|import)\s+(flagtrack(?:\.\w+)+)", source, flags=re.MULTILINE))
    files = set()
    for name in names:
        module = sys.modules.get(name)
        if module is not None and getattr(module, "__file__", None):
            path = Path(module.__file__).resolve()  # type: ignore[arg-type]
            if path.is_relative_to(root):
                files.add(str(path.relative_to(root)))
    return sorted(files)
