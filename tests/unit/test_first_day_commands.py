"""docs/first-day.md names only commands and options that exist: each line of its ``sh`` blocks is a
``flagtrack`` command the real parsers take, or a system program with the reason it is not run in
the tests; each ``flagtrack ...`` and ``--option`` in its prose exists too. The commands are run
against the simulated rig in tests/integration/test_first_day.py, which reads them from here."""

from __future__ import annotations

import argparse
import re
import shlex
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from flagtrack.daemon import cli
from flagtrack.daemon.commands._lazy import LazySubcommands

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "first-day.md"

SYSTEM = {
    "pip": "installs packages: the tests run in the installed tree",
    "sudo": "changes the system (udev rules, groups): root on the lab's PC",
    "ndls": "lists the USB cameras: neuromorphic-drivers (the prophesee extra) and a camera",
    "xdg-open": "opens a browser on the screen in the light-sheet plane",
    "cp": "copies the rig file: the test writes the simulated twin in its place",
}
"""Programs of the page other than flagtrack, and why the tests do not run them."""

PENDING: dict[str, str] = {}
"""flagtrack commands the page names that are not in this tree yet."""


@dataclass(frozen=True)
class DocCommand:
    """One line of an ``sh`` block: its section (the heading above it) and its words."""

    section: str
    line: str

    @property
    def argv(self) -> list[str]:
        return shlex.split(self.line)

    @property
    def program(self) -> str:
        return self.argv[0]


def doc_commands(text: str) -> list[DocCommand]:
    """Every command line of the ``sh`` blocks, in order."""
    found, section, block = [], "", False
    for line in text.splitlines():
        if line.startswith("## "):
            section = line[3:].strip()
        elif line.strip().startswith("```"):
            block = not block and line.strip() == "```sh"
        elif block and line.strip() and not line.lstrip().startswith("#"):
            found.append(DocCommand(section, line.strip()))
    return found


def prose_commands(text: str) -> list[str]:
    """The ``flagtrack ...`` spans of the prose (outside the code blocks; not its messages, ``flagtrack X: ...``)."""
    prose = re.sub(r"```.*?```", "", text, flags=re.DOTALL)
    return [span for span in re.findall(r"`(flagtrack [^`]+)`", prose) if not re.match(r"flagtrack [\w-]+:", span)]


def _walk(parser: argparse.ArgumentParser) -> Iterator[argparse.ArgumentParser]:
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name in list(action.choices):
                yield from _walk(action.build(name) if isinstance(action, LazySubcommands) else action.choices[name])


def options_of(parser: argparse.ArgumentParser) -> set[str]:
    """Every option string of ``parser`` and of its subcommands."""
    return {option for sub in _walk(parser) for action in sub._actions for option in action.option_strings}


def parse_error(argv: list[str]) -> str | None:
    """Why the real ``flagtrack`` parser refuses ``argv`` (the words after ``flagtrack``), or None."""
    try:
        cli.build_parser(argv[0]).parse_args(argv)
    except SystemExit as exc:
        return f"refused (exit {exc.code})"
    return None


def missing_options(argv: list[str]) -> list[str]:
    """The options of ``argv`` that its command does not have (for a span that is not a whole command)."""
    parser = cli.build_parser(argv[0])
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    known = options_of(sub.build(argv[0]) if isinstance(sub, LazySubcommands) else sub.choices[argv[0]])
    return [word.split("=")[0] for word in argv[1:] if word.startswith("-") and word.split("=")[0] not in known]


TEXT = DOC.read_text()
COMMANDS = doc_commands(TEXT)
FLAGTRACK = [c for c in COMMANDS if c.program == "flagtrack"]


def test_the_page_has_the_walk() -> None:
    sections = {c.section for c in COMMANDS}
    assert "Finding the flag's geometry" in sections  # the heading the geometry section merges into
    assert len(FLAGTRACK) >= 15
    words = {c.argv[1] for c in FLAGTRACK}
    assert {"config", "aim", "calibrate", "up", "reconstruct", "sweep", "runs", "tunnel"} <= words


@pytest.mark.parametrize("command", [c.line for c in COMMANDS if c.program != "flagtrack"])
def test_every_other_program_is_one_the_tests_know_not_to_run(command: str) -> None:
    assert shlex.split(command)[0] in SYSTEM, "add the program to SYSTEM with the reason it is not run"


@pytest.mark.parametrize("command", [c.line for c in FLAGTRACK], ids=[c.line for c in FLAGTRACK])
def test_every_command_is_one_the_real_parsers_take(command: str) -> None:
    argv = shlex.split(command)[1:]
    if argv[0] in PENDING:
        pytest.skip(PENDING[argv[0]])
    assert parse_error(argv) is None


@pytest.mark.parametrize("span", prose_commands(TEXT))
def test_every_command_in_the_prose_exists_with_its_options(span: str) -> None:
    argv = [word for word in shlex.split(span.replace("...", ""))[1:] if word]
    if argv[0] in PENDING:
        pytest.skip(PENDING[argv[0]])
    assert argv[0] in {m.COMMAND for m in cli.discover(cli.commands)}, f"no command {argv[0]!r}"
    assert missing_options(argv) == []


def test_every_option_the_prose_names_is_one_of_flagtrack() -> None:
    named = set(re.findall(r"`(--[a-z][a-z0-9-]*)", re.sub(r"```.*?```", "", TEXT, flags=re.DOTALL)))
    assert named, "the page names options"
    assert named - options_of(cli.build_parser()) == set()


def test_a_wrong_command_or_option_is_caught() -> None:
    """The checks can fail: an option no command has, a command that does not exist."""
    assert parse_error(["sweep", "-c", "rig.yaml", "--no-such-option"]) is not None
    assert missing_options(["calibrate", "--board", "9x6", "--bord"]) == ["--bord"]
    assert doc_commands("## A\n```sh\nflagtrack up -c r.yaml\n# a comment\n```\n```text\nflagtrack x\n```\n") == [
        DocCommand("A", "flagtrack up -c r.yaml")
    ]


def test_the_blinking_board_is_the_one_the_page_calibrates_with() -> None:
    """deploy/blink-board.html's default squares have the inner corners the page's calibrate names."""
    page = (REPO / "deploy" / "blink-board.html").read_text()
    squares = re.search(r'get\("squares"\) \|\| "(\d+)x(\d+)"', page)
    assert squares is not None
    corners = f"{int(squares.group(1)) - 1}x{int(squares.group(2)) - 1}"
    calibrate = [c for c in FLAGTRACK if c.argv[1] == "calibrate" and "--board" in c.argv]
    assert calibrate and all(c.argv[c.argv.index("--board") + 1] == corners for c in calibrate)
    assert "deploy/blink-board.html" in TEXT
