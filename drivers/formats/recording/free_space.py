"""Stop writing before a disk is full: the HDF5 library does not survive a full disk."""

from __future__ import annotations

import errno
import shutil
from pathlib import Path


class FreeSpaceGuard:
    """Raises ``OSError(ENOSPC)`` when a folder's disk has less than ``min_free_mb`` free.

    Args:
        min_free_mb: the least free space, MB (1e6 bytes).
        every_s: look at the disk at most this often (``check``'s ``now_s`` apart).
        setting: the setting that sets ``min_free_mb``, named in the error.
    """

    def __init__(self, min_free_mb: float, every_s: float = 0.25, setting: str = "min_free_mb") -> None:
        self.min_free_mb = min_free_mb
        self.every_s = every_s
        self.setting = setting
        self._checked_s: float | None = None

    def check(self, folder: Path, now_s: float) -> None:
        """Look at ``folder``'s disk if ``every_s`` has passed since the last look (``now_s``: a monotonic clock).

        Raises:
            OSError: ENOSPC, with the free space and the setting, when it is below ``min_free_mb``.
        """
        if self._checked_s is not None and now_s - self._checked_s < self.every_s:
            return
        self._checked_s = now_s
        free = shutil.disk_usage(folder).free
        if free < self.min_free_mb * 1e6:
            raise OSError(errno.ENOSPC, f"No space left on device: {free / 1e6:.1f} MB free, below {self.setting}")
