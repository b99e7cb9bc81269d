"""The ``flagtrack`` command.

Each subcommand lives in its own module of :mod:`flagtrack.daemon.commands`, which defines
``COMMAND`` (its name), ``HELP`` (one line), ``add_arguments(parser)`` and ``run(args) -> int``.
Command modules import only the standard library at module level and in ``add_arguments`` so that
``--help`` is fast (tests/unit/test_cli_help.py); heavy imports happen inside ``run``.
"""

from __future__ import annotations

import argparse
import logging
import sys
import warnings
from collections.abc import Sequence
from typing import Any

from flagtrack.daemon import commands
from flagtrack.daemon.commands._registry import add_subcommands, discover
from flagtrack.daemon.core import jit_hook
from flagtrack.daemon.errors import FlagtrackError
from flagtrack.daemon.process import tune_process

log = logging.getLogger(__name__)

#: Libraries that log, at ERROR, a failure flagtrack reports itself in its one error line (pymodbus:
#: "(22, 'Invalid argument')" before "cannot open the serial port"); shown with -vv only.
QUIET_LOGGERS = ("pymodbus",)


class _VersionAction(argparse.Action):
    """``--version``: print the installed version and exit (looked up only when asked)."""

    def __init__(
        self,
        option_strings: Sequence[str],
        dest: str = argparse.SUPPRESS,
        default: Any = argparse.SUPPRESS,
        help: str = "show the version and exit",  # noqa: A002 - argparse.Action's own keyword
    ) -> None:
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        from flagtrack.daemon import __version__

        print(f"flagtrack {__version__}")  # on stdout, as argparse's own version action does
        parser.exit()


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Return the top-level ``flagtrack`` argument parser, with every command or only the one named
    ``only`` (a command's run needs only its own options: building all of them took ~60 ms)."""
    parser = argparse.ArgumentParser(
        prog="flagtrack",
        description="Event-camera centreline tracking of flapping flags in a wind tunnel.",
    )
    parser.add_argument("--version", action=_VersionAction)
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)")
    add_subcommands(parser, commands, "command", only)
    return parser


def _named_command(argv: Sequence[str]) -> str | None:
    """The command the arguments name (the first that is not an option), if it is one of flagtrack's."""
    first = next((arg for arg in argv if not arg.startswith("-")), None)
    return first if first in {module.COMMAND for module in discover(commands)} else None


def _configure_logging(verbose: int) -> None:
    """WARNING and up on stderr (-v: INFO, -vv: DEBUG); the libraries of ``QUIET_LOGGERS`` only with -vv."""
    logging.basicConfig(level=logging.WARNING - 10 * min(verbose, 2), format="%(levelname)s %(name)s: %(message)s")
    for name in QUIET_LOGGERS:
        logging.getLogger(name).setLevel(logging.DEBUG if verbose >= 2 else logging.CRITICAL)


class _WarningLines:
    """Warnings (a damaged file's words skipped, a truncated end) print as one line each, as errors do,
    the first :attr:`SHOWN` of them unless ``every`` (-v): a file damaged over 100 kB gave 160 lines."""

    SHOWN = 10

    def __init__(self, command: str, every: bool) -> None:
        self.command, self.every = command, every
        self.shown = self.hidden = 0

    def show(self, message: Warning | str, *_where: Any, **_named: Any) -> None:
        """``warnings.showwarning``: the category, file, line and stream are left out."""
        if self.every or self.shown < self.SHOWN:
            self.shown += 1
            print(f"flagtrack {self.command}: warning: {message}", file=sys.stderr)
        else:
            self.hidden += 1

    def close(self) -> None:
        """Say how many were not shown, if any."""
        if self.hidden:
            print(
                f"flagtrack {self.command}: {self.hidden} more warnings not shown (flagtrack -v {self.command} ... shows each)",
                file=sys.stderr,
            )
            self.hidden = 0


def _exit_at_once(status: int) -> None:
    """End the process now: exit handlers run and output is flushed, but the interpreter does not
    tear its modules and arrays down one by one (~0.15 s after a reconstruction; docs/tracking.md)."""
    import atexit
    import os

    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(status)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``flagtrack`` command; return its exit status.

    Run as the process's own command (``argv`` None), a command module with ``EXIT_AT_ONCE = True``
    ends the process as soon as it has succeeded (:func:`_exit_at_once`).
    """
    exit_now = argv is None
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv == ["--version"]:  # without building every command's parser (~1 s)
        from flagtrack.daemon import __version__

        print(f"flagtrack {__version__}")
        raise SystemExit(0)  # as argparse's version action does
    args = build_parser(_named_command(argv)).parse_args(argv)
    _configure_logging(args.verbose)
    tune_process()
    from flagtrack.daemon.aot.cache import load as load_compiled_kernels

    jit_hook.loader = load_compiled_kernels  # the kernels built ahead of time, if any (no numba import)
    previous = warnings.showwarning
    warning_lines = _WarningLines(args.command, every=args.verbose > 0)
    warnings.showwarning = warning_lines.show
    try:
        status = int(args.run(args) or 0)
        warning_lines.close()
        if exit_now and getattr(sys.modules.get(args.run.__module__), "EXIT_AT_ONCE", False):
            _exit_at_once(status)
        return status
    except FlagtrackError as exc:
        warning_lines.close()  # (before the error line, which stays the last)
        print(f"flagtrack {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a path a command did not check itself: still one line (the traceback at DEBUG)
        warning_lines.close()
        log.debug("flagtrack %s failed", args.command, exc_info=exc)
        where = ": ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
        print(f"flagtrack {args.command}: error: {where + ': ' if where else ''}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        warning_lines.close()
        print(f"flagtrack {args.command}: interrupted", file=sys.stderr)
        return 130
    finally:
        warning_lines.close()
        warnings.showwarning = previous  # main() is also called in-process (tests)


if __name__ == "__main__":
    sys.exit(main())
