"""Counting the repeated problems of a service (or of a bus subscription) and logging them rarely."""

from __future__ import annotations

import logging
import math
import time


class ProblemLog:
    """Counts the repeated problems of one service by kind and logs them rarely.

    The first problem of a kind is logged at once with its detail; later ones are only counted, and
    summed up in one line at most every ``interval_s`` (by :meth:`add` as they come, or by
    :meth:`flush`, which a service calls now and then and when it stops). O(1) per problem.

    Args:
        logger: where the lines go.
        service: prefix of every line.
        interval_s: at most one line per kind this often.
        level: logging level of the lines.
    """

    def __init__(
        self, logger: logging.Logger, service: str, interval_s: float = 5.0, level: int = logging.WARNING
    ) -> None:
        self.logger = logger
        self.service = service
        self.interval_s = interval_s
        self.level = level
        self.totals: dict[str, int] = {}
        self._unlogged: dict[str, int] = {}
        self._latest: dict[str, object] = {}
        self._logged_at: dict[str, float] = {}

    def add(self, kind: str, detail: object, count: int = 1) -> None:
        """Count ``count`` problems of ``kind`` (e.g. ``"malformed packets"``); ``detail`` (an exception,
        or text) describes the latest one and is formatted only when logged."""
        self.totals[kind] = self.totals.get(kind, 0) + count
        self._unlogged[kind] = self._unlogged.get(kind, 0) + count
        self._latest[kind] = detail
        now = time.monotonic()
        if now - self._logged_at.get(kind, -math.inf) >= self.interval_s:
            self._log(kind, now)

    def flush(self, force: bool = False) -> None:
        """Log the summary of every kind with unlogged problems whose interval has passed (all: ``force``)."""
        now = time.monotonic()
        for kind, unlogged in self._unlogged.items():
            if unlogged and (force or now - self._logged_at.get(kind, -math.inf) >= self.interval_s):
                self._log(kind, now)

    def _log(self, kind: str, now: float) -> None:
        unlogged, total = self._unlogged[kind], self.totals[kind]
        if unlogged == total:
            self.logger.log(self.level, "%s: %s [%s: %d]", self.service, self._latest[kind], kind, total)
        else:
            self.logger.log(
                self.level,
                "%s: %d more %s in the last %.0f s (%d in all); latest: %s",
                self.service,
                unlogged,
                kind,
                now - self._logged_at[kind],
                total,
                self._latest[kind],
            )
        self._unlogged[kind] = 0
        self._logged_at[kind] = now
