"""No user-facing text names a file the repository lacks (issue 29): the docs, README.md,
CONTRIBUTING.md, deploy/, the --help of every command and the module docstrings of daemon/, drivers/
and calibration/.

A name is checked when it looks like a file of the repository: ``*.md``, ``*.yaml``, ``*.py``, or a
path under ``deploy/`` or ``docs/``. With a folder in it, it must be a tracked file or folder (from the
repository's root or from the text's own folder, or the end of a tracked path: ``services/sequence.py``);
a bare name must be the name of some tracked file. Placeholders are not files: an ALL-CAPS name
(``CAL.yaml``, ``RUN_DIR/...``; not ``*.md``: DESIGN.md is a document's name), a pattern (``deploy/rig-*.yaml``, ``<name>.md``), a path outside
the repository (``/etc/...``, ``~/...``), and the generic names of ``PLACEHOLDERS``.
"""

from __future__ import annotations

import argparse
import ast
import os
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path, PurePosixPath

import pytest

from flagtrack.daemon import cli
from flagtrack.daemon.commands._lazy import LazySubcommands

REPO = Path(__file__).resolve().parents[2]

#: Names that stand for a file the user makes or a command writes, not a file of the repository.
PLACEHOLDERS = frozenset(
    {
        "rig.yaml",  # the user's rig config (`-c rig.yaml`)
        "cal.yaml",  # a calibration `flagtrack calibrate -o cal.yaml` writes
        "cfg.yaml",
        "tracker.yaml",  # a config file holding a `tracker:` section
        "tracking.yaml",
        "cluster.py",  # the user's Dask cluster script (docs/batch.md)
        "report.md",  # what `flagtrack bench accuracy` writes into its results folder
    }
)

#: Known stale names, per text, that a change leaves for another to fix (none now): add one only with
#: the reason, and remove it once its text is fixed.
KNOWN_EXCEPTIONS: dict[str, set[str]] = {}

_NAME = r"[\w.@*+<>-]+"
REFERENCE = re.compile(
    rf"(?<![\w./:~$@-])((?:\.\.?/)*(?:{_NAME}/)*{_NAME}\.(?:md|yaml|yml|py)(?![\w/-])|(?:deploy|docs)/[\w./@*+<>-]*)"
)


def _tracked() -> tuple[set[str], set[str]]:
    command = ["git", "ls-files", "--cached", "--others", "--exclude-standard"]  # new files count before `git add`
    out = subprocess.run(command, cwd=REPO, capture_output=True, text=True, check=True).stdout
    files = set(out.split())
    folders = {str(parent) for f in files for parent in PurePosixPath(f).parents if str(parent) != "."}
    return files, folders


FILES, FOLDERS = _tracked()
BASENAMES = {PurePosixPath(f).name for f in FILES}


def is_placeholder(name: str) -> bool:
    if name.startswith(("/", "~")) or re.search(r"[*<>{}$]", name) or name in PLACEHOLDERS:
        return True
    first, path = name.split("/")[0], PurePosixPath(name)
    if "/" in name:
        return first.isupper()  # RUN_DIR/run.jsonl
    return path.stem.isupper() and path.suffix != ".md"  # CAL.yaml; but DESIGN.md is a document's name


def exists(name: str, folder: str) -> bool:
    """Whether ``name``, found in a text of ``folder`` (relative to the root), is in the repository."""
    name = name.rstrip("/")
    if "/" not in name:
        return name in BASENAMES or name in FOLDERS
    for base in (folder, "."):
        path = os.path.normpath(os.path.join(base, name))
        if path in FILES or path in FOLDERS:
            return True
    return not name.startswith(".") and any(f.endswith("/" + name) for f in FILES | FOLDERS)


def references(text: str) -> Iterator[str]:
    for match in REFERENCE.finditer(text):
        yield match.group(1).rstrip(".,;:")


def _help_texts() -> Iterator[tuple[str, str]]:
    def walk(parser: argparse.ArgumentParser, path: list[str]) -> Iterator[tuple[str, str]]:
        yield "flagtrack " + " ".join(path) + " --help", parser.format_help()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name in list(action.choices):
                    sub = action.build(name) if isinstance(action, LazySubcommands) else action.choices[name]
                    yield from walk(sub, [*path, name])

    yield from walk(cli.build_parser(), [])


def user_facing_texts() -> Iterator[tuple[str, str, str]]:
    """(where, its folder, the text) of every user-facing text."""
    for f in sorted(FILES):
        if (f.startswith("docs/") and f.endswith(".md")) or f in ("README.md", "CONTRIBUTING.md"):
            yield f, str(PurePosixPath(f).parent), (REPO / f).read_text()
        elif f.startswith("deploy/"):
            yield f, str(PurePosixPath(f).parent), (REPO / f).read_text(errors="replace")
        elif f.endswith(".py") and f.split("/")[0] in ("daemon", "drivers", "calibration"):
            doc = ast.get_docstring(ast.parse((REPO / f).read_text()), clean=False)
            if doc:
                yield f"{f} (module docstring)", str(PurePosixPath(f).parent), doc
    for where, text in _help_texts():
        yield where, ".", text


def missing_files() -> dict[str, list[str]]:
    missing: dict[str, list[str]] = {}
    for where, folder, text in user_facing_texts():
        known = KNOWN_EXCEPTIONS.get(where, set())
        for name in references(text):
            if name not in known and not is_placeholder(name) and not exists(name, folder):
                missing.setdefault(where, []).append(name)
    return missing


def test_no_user_facing_text_names_a_file_the_repository_lacks() -> None:
    assert missing_files() == {}


@pytest.mark.parametrize(
    ("text", "found"),
    [
        ("see DESIGN.md for the layout", ["DESIGN.md"]),
        ("  flagtrack sweep -c deploy/rig-sweep-sim.yaml", ["deploy/rig-sweep-sim.yaml"]),
        ("`../shared/DESIGN.md` is the picture", ["../shared/DESIGN.md"]),
        ("(docs/tunnel.md).", ["docs/tunnel.md"]),
        ("https://example.org/a/docs/x.md and flagtrack.daemon.cli", []),
    ],
)
def test_references_are_found_in_prose(text: str, found: list[str]) -> None:
    assert list(references(text)) == found


def test_real_stale_names_are_caught_and_placeholders_are_not() -> None:
    for stale in ("DESIGN.md", "deploy/rig-sweep-sim.yaml", "../shared/DESIGN.md", "services/rerun_serve.py"):
        assert not is_placeholder(stale) and not exists(stale, "docs"), stale
    for placeholder in ("rig.yaml", "CAL.yaml", "RUN_DIR/run.jsonl", "deploy/rig-*.yaml", "/etc/flagtrack/rig.yaml"):
        assert is_placeholder(placeholder), placeholder
    for real in ("deploy/rig-sensor-sim.yaml", "../README.md", "batch.md", "services/sequence.py", "deploy/systemd/"):
        assert exists(real, "docs"), real
