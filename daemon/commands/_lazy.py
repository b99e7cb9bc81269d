"""What keeps ``flagtrack ... --help`` fast (issue 32: under 0.5 s): a command module is imported only
if its source declares a command, and a command's options are added only when the command line
names it. Neither imports anything beyond the standard library."""

from __future__ import annotations

import argparse
import pkgutil
import re
from typing import Any


def declares_commands(info: pkgutil.ModuleInfo, name: str) -> bool:
    """Whether module ``name``'s source assigns ``COMMAND`` or ``COMMANDS`` (True when it has no source):
    helper modules beside the commands (which may import NumPy or SciPy) are then never imported."""
    spec = info.module_finder.find_spec(name, None)
    loader: Any = spec.loader if spec is not None else None
    source = loader.get_source(name) if loader is not None and hasattr(loader, "get_source") else None
    return source is None or re.search(r"^COMMANDS?\b", source, re.MULTILINE) is not None


class LazySubcommands(argparse._SubParsersAction):
    """Subcommands whose options (``add_arguments``) are added when the command line reaches them."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.pending: dict[str, Any] = {}

    def defer(self, sub: argparse.ArgumentParser, command: Any) -> None:
        """Add ``command``'s options (and its ``run``) to ``sub`` when it is named."""
        self.pending[command.COMMAND] = (sub, command)

    def build(self, name: str) -> argparse.ArgumentParser:
        """The subcommand ``name``'s parser, with its options."""
        sub, command = self.pending.pop(name, (self.choices[name], None))
        if command is not None:
            command.add_arguments(sub)
            if not sub.get_default("run"):
                sub.set_defaults(run=command.run)
        return sub

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        if values and values[0] in self.pending:
            self.build(values[0])
        super().__call__(parser, namespace, values, option_string)
