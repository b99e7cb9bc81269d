"""A user's control law called in a thread of its own, so that a law that does not return in time is a
fault of the run (the speed held, ``max_faults`` of them stop it safe), never a hung run.

One call is out at a time: a law that has not returned is not called again; what it returns late is
dropped (the state it answers is old). Whatever the law raises, ``SystemExit`` and
``KeyboardInterrupt`` included, is a fault named by its type. A Python thread cannot be killed: a law
that never returns keeps its (daemon) thread until the process ends.
"""

from __future__ import annotations

import queue
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Answer:
    """What one call of the law gave: its value, or why it is a fault; how long it took from the call,
    s (the wait for the law's thread included); where in the law's file it raised (``law.py:12``)."""

    value: object
    fault: str
    took_s: float
    where: str = ""


class LawCall:
    """Calls ``function`` with a state in a daemon thread and waits at most ``timeout_s`` for it;
    ``check`` (in that thread too: a returned object's own methods may hang or raise) turns what it
    returned into (value, fault), "" for no fault."""

    def __init__(
        self,
        function: Callable[[Any], object],
        timeout_s: float,
        name: str = "law",
        check: Callable[[object], tuple[object, str]] = lambda value: (value, ""),
    ) -> None:
        self._function, self._check = function, check
        self.timeout_s = timeout_s
        self._calls: queue.SimpleQueue[tuple[object, float] | None] = queue.SimpleQueue()
        """(state, when it was called, monotonic s); None to close."""
        self._answers: queue.SimpleQueue[Answer] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._serve, name=f"control-{name}", daemon=True)
        self._thread.start()
        self.called_at_s: float | None = None
        """When the call still out (not returned) was made, monotonic s; None when none is."""

    @property
    def busy(self) -> bool:
        """A call has not returned yet."""
        return self.called_at_s is not None

    def call(self, state: object) -> Answer:
        """Call the law with ``state``; its answer, or a fault when it has not returned in ``timeout_s``
        (it is then :attr:`busy` until :meth:`late` sees its answer)."""
        if self.busy:
            raise RuntimeError("the law has not returned from its last call")
        self.called_at_s = time.monotonic()
        self._calls.put((state, self.called_at_s))
        answer = self._answer(self.timeout_s)
        if answer is not None:
            return answer
        return Answer(None, f"did not return within {self.timeout_s:g} s", self.timeout_s)

    def late(self, wait_s: float) -> Answer | None:
        """While :attr:`busy`: the late answer if it comes within ``wait_s`` (the law is then free),
        else None."""
        return self._answer(wait_s) if self.busy else None

    def out_for_s(self) -> float:
        """How long the call still out has been, s (0 when none is)."""
        return 0.0 if self.called_at_s is None else time.monotonic() - self.called_at_s

    def close(self) -> None:
        """Let the thread end once the law has returned."""
        self._calls.put(None)

    def _answer(self, timeout_s: float) -> Answer | None:
        try:
            answer = self._answers.get(timeout=max(0.0, timeout_s))
        except queue.Empty:
            return None
        self.called_at_s = None
        return answer

    def _serve(self) -> None:
        while (call := self._calls.get()) is not None:
            state, called_at_s = call
            where = ""
            try:
                value, fault = self._check(self._function(state))
            except BaseException as exc:  # noqa: BLE001 - a user's law: whatever it raises is a fault
                value, fault = None, f"raised {type(exc).__name__}" + (f": {exc}" if str(exc) else "")
                where = raised_where(exc, self._function)
            self._answers.put(Answer(value, fault, time.monotonic() - called_at_s, where))


def raised_where(exc: BaseException, function: Callable[..., object]) -> str:
    """``file.py:LINE`` of the deepest line of ``function``'s own file that ``exc`` passed through (the
    line of the law to look at; a library it called raised below it), "" when none did."""
    code = getattr(function, "__code__", None) or getattr(type(function).__call__, "__code__", None)
    if code is None:
        return ""
    frames = [frame for frame in traceback.extract_tb(exc.__traceback__) if frame.filename == code.co_filename]
    return f"{Path(frames[-1].filename).name}:{frames[-1].lineno}" if frames else ""
