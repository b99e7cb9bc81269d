"""``--help`` of every command is quick and short (issue 32): it imports nothing beyond the standard
library (no NumPy, SciPy, h5py, Zenoh, Rerun, matplotlib, cryptography, ...), and prints a short
paragraph and the options; the long explanation lives in docs/. The time it takes is measured in
docs/commands.md, not here."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

MAX_TEXT_LINES = 6  # description and epilog together, as printed

# Run in a fresh interpreter: walks every command (building each parser, as `--help` would), then
# runs `flagtrack PATH --help` for each, noting the modules outside the standard library each step
# imported and the lines of text besides the usage and the options.
SCRIPT = r"""
import argparse, contextlib, io, json, sys

baseline = set(sys.modules)
from flagtrack.daemon import cli
from flagtrack.daemon.commands._lazy import LazySubcommands

def outside_stdlib():
    top = {name.partition(".")[0] for name in set(sys.modules) - baseline}
    return sorted(top - set(sys.stdlib_module_names) - {"flagtrack"})

def text_lines(parser):
    formatter = parser._get_formatter()
    formatter.add_text(parser.description)
    formatter.add_text(parser.epilog)
    return len([line for line in formatter.format_help().splitlines() if line.strip()])

def walk(parser, path):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name in list(action.choices):
                sub = action.build(name) if isinstance(action, LazySubcommands) else action.choices[name]
                yield from walk(sub, path + [name])

commands = {}
for path, parser in walk(cli.build_parser(), []):
    commands[" ".join(path)] = {"text_lines": text_lines(parser), "imported_by_parser": outside_stdlib()}
for path, found in commands.items():
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            cli.main(path.split() + ["--help"])
        except SystemExit as exc:
            found["exit"] = exc.code
    found["help"] = out.getvalue()
    found["imported_by_help"] = outside_stdlib()
print(json.dumps(commands))
"""


@pytest.fixture(scope="module")
def commands() -> dict[str, dict]:
    result = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def test_every_command_and_subcommand_is_walked(commands: dict[str, dict]) -> None:
    nested = {
        "bench live",
        "events info",
        "runs list",
        "tunnel sim",
        "certs init",
        "batch reconstruct",
        "metrics compare",
    }
    assert nested | {"", "reconstruct", "up", "sweep", "tracker", "bench decode"} <= set(commands)
    assert len(commands) >= 45


def test_help_imports_nothing_beyond_the_standard_library(commands: dict[str, dict]) -> None:
    first = {path: found["imported_by_parser"] for path, found in commands.items() if found["imported_by_parser"]}
    assert not first, f"building these commands' options imported {first}"
    after = {path: found["imported_by_help"] for path, found in commands.items() if found["imported_by_help"]}
    assert not after, f"--help imported {after}"


def test_help_is_a_short_paragraph_and_the_options(commands: dict[str, dict]) -> None:
    long = {path or "flagtrack": found["text_lines"] for path, found in commands.items()}
    assert {path: n for path, n in long.items() if n > MAX_TEXT_LINES} == {}
    for path, found in commands.items():
        assert found["exit"] == 0 and "usage: flagtrack" in found["help"], path
        assert "options:" in found["help"], path


def test_a_subcommand_help_leaves_the_heavy_modules_of_its_package_unimported() -> None:
    """``flagtrack bench onset --help`` does not import bench's helper modules (onset_traces imports
    scipy.signal at module level) nor the other benchmarks' modules' NumPy."""
    code = (
        "import sys, contextlib, io\n"
        "from flagtrack.daemon import cli\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    cli.main(['bench', 'onset', '--help'])\n"
        "import json; print(json.dumps(sorted(m for m in sys.modules if m.startswith('flagtrack.daemon.bench.') or m in ('numpy', 'scipy'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    imported = json.loads(out)
    assert "flagtrack.daemon.bench.onset" in imported
    assert not {"flagtrack.daemon.bench.onset_traces", "flagtrack.daemon.bench.fuzz_targets", "numpy", "scipy"} & set(
        imported
    )
