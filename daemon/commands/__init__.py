"""Subcommands of ``flagtrack``: one module each, discovered by :mod:`flagtrack.daemon.cli`."""
