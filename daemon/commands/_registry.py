"""How ``flagtrack`` finds its commands: one module each (``COMMAND``, ``HELP``, ``add_arguments``,
``run``), or several in one module (``COMMANDS = [Command(...), ...]``)."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import Any, cast

from flagtrack.daemon.commands._lazy import LazySubcommands, declares_commands


@dataclass(frozen=True)
class Command:
    """One subcommand, for modules that define several (``COMMANDS = [Command(...), ...]``)."""

    COMMAND: str
    HELP: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
    DESCRIPTION: str = ""


def discover(package: ModuleType) -> list[Any]:
    """The commands of ``package``'s modules (a module with ``COMMAND``, or its ``COMMANDS``), by name."""
    found: list[Any] = []
    for info in pkgutil.iter_modules(package.__path__):
        if info.name.startswith("_") or not declares_commands(info, f"{package.__name__}.{info.name}"):
            continue
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        if hasattr(module, "COMMAND"):
            found.append(module)
        found.extend(getattr(module, "COMMANDS", ()))
    return sorted(found, key=lambda m: m.COMMAND)


def add_subcommands(parser: argparse.ArgumentParser, package: ModuleType, dest: str, only: str | None = None) -> None:
    """Add one subparser per command module of ``package`` (or only the one named ``only``); each sets
    ``args.run``."""
    subparsers = cast(
        LazySubcommands, parser.add_subparsers(dest=dest, metavar="COMMAND", required=True, action=LazySubcommands)
    )
    for module in discover(package):
        if only is not None and only != module.COMMAND:
            continue
        sub = subparsers.add_parser(
            module.COMMAND,
            help=module.HELP,
            description=getattr(module, "DESCRIPTION", "") or module.HELP,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        subparsers.defer(sub, module)  # its options are added when the command line names it
