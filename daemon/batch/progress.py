"""How a batch shows its progress: a tqdm bar on a terminal (files and bytes done, events, rates, ETA),
one plain line per finished item otherwise (logs, pipes, ``nohup``)."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO


def _eta(seconds: float) -> str:
    minutes, secs = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    if hours:
        return f"{hours}:{minutes:02d}:{secs:02d}"
    return f"{minutes}:{secs:02d}" if minutes else f"{secs} s"


class Progress:
    """Progress of ``total_items`` inputs of ``total_bytes`` in all.

    Args:
        prefix: what starts each line (``flagtrack batch``).
        total_items: inputs to go through.
        total_bytes: their sizes summed.
        bar: draw a tqdm bar (on a terminal); otherwise :meth:`advance` prints a line per item.
        stream: where it goes (stderr).
    """

    def __init__(
        self, prefix: str, total_items: int, total_bytes: int, *, bar: bool, stream: TextIO | None = None
    ) -> None:
        self.prefix = prefix
        self.total_items = total_items
        self.total_bytes = max(total_bytes, 1)
        self.stream = stream if stream is not None else sys.stderr
        self.items = 0
        self.bytes_done = 0
        self.bytes_worked = 0  # of items processed to the end (not skipped, not failed): what the ETA uses
        self.events = 0
        self.started = time.monotonic()
        self._bar: Any = None
        if bar:
            from tqdm import tqdm

            self._bar = tqdm(
                total=self.total_bytes,
                unit="B",
                unit_scale=True,
                desc=f"0/{total_items} files",
                file=self.stream,
                leave=False,
                dynamic_ncols=True,
            )

    def advance(self, name: str, nbytes: int, status: str, events: int | None, detail: str = "") -> None:
        """One item finished: ``status`` (``done``, ``skipped``, ``failed``) of ``nbytes`` with ``events``.

        A line says so (without a bar; with one, only failures print a line); ``detail`` ends it.
        """
        self.items += 1
        self.bytes_done += nbytes
        if status == "done":
            self.bytes_worked += nbytes
        self.events += events or 0
        elapsed = time.monotonic() - self.started
        rate = self.events / elapsed / 1e6 if elapsed > 0 else 0.0
        text = {"skipped": "skipped (up to date)", "failed": "failed"}.get(status, status)
        if self._bar is not None:
            self._bar.set_description_str(f"{self.items}/{self.total_items} files", refresh=False)
            self._bar.set_postfix_str(f"{self.events / 1e6:.1f} M events, {rate:.1f} Mev/s", refresh=False)
            self._bar.update(nbytes)
            if status == "failed":
                self.line(f"{name}: {text}{': ' + detail if detail else ''}")
            return
        remaining = self.total_bytes - self.bytes_done
        eta = f", ETA {_eta(elapsed * remaining / self.bytes_worked)}" if self.bytes_worked and remaining > 0 else ""
        where = (
            f"[{self.items}/{self.total_items}, {self.bytes_done / 1e6:.1f} of {self.total_bytes / 1e6:.1f} MB{eta}]"
        )
        self.line(f"{where} {name}: {text}{(': ' if status == 'failed' else ' ') + detail if detail else ''}")

    def line(self, text: str) -> None:
        """Print ``prefix: text`` (above the bar, if there is one)."""
        message = f"{self.prefix}: {text}"
        if self._bar is not None:
            self._bar.write(message, file=self.stream)
        else:
            print(message, file=self.stream, flush=True)

    def close(self) -> None:
        """Remove the bar."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
