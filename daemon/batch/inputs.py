"""What a batch works on: recordings named by files, folders or glob patterns, and the file each one writes."""

from __future__ import annotations

import glob
from collections.abc import Collection, Sequence
from pathlib import Path

from flagtrack.daemon.errors import ConfigError, FormatError
from flagtrack.drivers.formats.files import READERS

#: Extensions of the recordings a folder or a pattern contributes (those ``open_events`` reads).
RECORDING_SUFFIXES = frozenset({f".{name}" for name in READERS} | {".aedat"})
OUTPUT_SUFFIX = "_centrelines.h5"
_GLOB_CHARACTERS = frozenset("*?[")


def is_recording(path: Path) -> bool:
    """Whether a file found in a folder or by a pattern is a recording: a known extension, not hidden."""
    return path.is_file() and path.suffix.lower() in RECORDING_SUFFIXES and not path.name.startswith(".")


def expand_inputs(items: Sequence[str | Path], *, exclude: Collection[Path] = ()) -> list[Path]:
    """The recordings named by ``items``, resolved, in the order given, each once.

    An item is a file (taken whatever its extension: ``open_events`` may recognise its content), a
    folder (the recordings directly inside it, by name), or a glob pattern (``**`` recurses; the
    recordings it matches, and those of the folders it matches). Hidden files (a ``.`` name, such as
    an unfinished output's temporary file) are left out of folders and patterns.

    Args:
        items: the command line's INPUT arguments.
        exclude: resolved paths never taken (the batch's own ``batch.csv`` when the output folder is an
            input folder).

    Raises:
        FormatError: an item names nothing (no such file or folder, a pattern that matches no
            recording, a folder without recordings).
    """
    found: dict[Path, None] = {}
    skip = {Path(p) for p in exclude}
    for item in items:
        text = str(item)
        if _GLOB_CHARACTERS & set(text):
            matches = [Path(m) for m in sorted(glob.glob(str(Path(text).expanduser()), recursive=True))]
            paths = [p for m in matches for p in (_folder(m) if m.is_dir() else [m] if is_recording(m) else [])]
            if not paths:
                raise FormatError("the pattern matches no recording", path=text)
        else:
            path = Path(text).expanduser()
            if path.is_dir():
                paths = _folder(path)
                if not paths:
                    raise FormatError(
                        f"no recordings in this folder (looked for {', '.join(sorted(RECORDING_SUFFIXES))})",
                        path=str(path.resolve()),
                    )
            elif path.is_file():
                paths = [path]
            else:
                raise FormatError("no such file or folder", path=str(path.resolve()))
        for p in paths:
            resolved = p.resolve()
            if resolved not in skip:
                found.setdefault(resolved, None)
    return list(found)


def _folder(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if is_recording(p))


def output_path(out_dir: Path, recording: Path) -> Path:
    """``OUT_DIR/<stem>_centrelines.h5``: the centreline file of ``recording``."""
    return out_dir / f"{recording.stem}{OUTPUT_SUFFIX}"


def output_paths(out_dir: Path, recordings: Sequence[Path]) -> list[Path]:
    """The output of every recording, checked to be distinct.

    Raises:
        ConfigError: two recordings of the same stem (``a/run1.raw`` and ``b/run1.raw``, or
            ``run1.raw`` and ``run1.npy``) would write the same file; nothing is run.
    """
    outputs: dict[Path, Path] = {}
    for recording in recordings:
        output = output_path(out_dir, recording)
        if output in outputs:
            raise ConfigError(
                f"{outputs[output]} and {recording} would both write {output.name}: give them in separate "
                "batches with different -o folders (outputs are named by the input's stem)",
                key="INPUT",
            )
        outputs[output] = recording
    return list(outputs)
