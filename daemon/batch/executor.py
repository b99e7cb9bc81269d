"""Where a batch's tasks run: a local process pool, or Dask distributed (a ``LocalCluster`` started here,
or the scheduler of a lab's cluster), behind the one futures interface both follow.

Dask is optional (``pip install -e ".[cluster]"``) and imported only when a ``--scheduler`` asks for it.
"""

from __future__ import annotations

import concurrent.futures
import logging
import multiprocessing
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Literal

from flagtrack.daemon.errors import ConfigError

log = logging.getLogger(__name__)


def cpu_count() -> int:
    """Cores this process may run on (its affinity; the machine's count where that is unknown)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


@dataclass(frozen=True)
class ExecutorSpec:
    """Which executor: ``pool`` (local processes), ``local`` (a Dask ``LocalCluster``) or ``remote`` (a
    Dask scheduler's address)."""

    kind: Literal["pool", "local", "remote"]
    workers: int = 1
    address: str | None = None

    def describe(self) -> str:
        """``pool:2``, ``dask local:2``, ``dask tcp://host:8786``."""
        if self.kind == "pool":
            return f"pool:{self.workers}"
        return f"dask local:{self.workers}" if self.kind == "local" else f"dask {self.address}"


def executor_spec(jobs: int | None, scheduler: str | None) -> ExecutorSpec:
    """The executor of ``--jobs N`` (default: the cores) or ``--scheduler local[:N]|ADDRESS``.

    Raises:
        ConfigError: a count below 1, or a scheduler that is neither ``local[:N]`` nor ``scheme://host:port``.
    """
    if scheduler is None:
        workers = cpu_count() if jobs is None else jobs
        if workers < 1:
            raise ConfigError(f"must be at least 1, got {workers}", key="--jobs")
        return ExecutorSpec("pool", workers)
    if scheduler == "local" or scheduler.startswith("local:"):
        count = scheduler.partition(":")[2]
        try:
            workers = int(count) if count else cpu_count()
        except ValueError:
            raise ConfigError(f"local:N needs a number of workers, got {scheduler!r}", key="--scheduler") from None
        if workers < 1:
            raise ConfigError(f"local:N needs at least 1 worker, got {workers}", key="--scheduler")
        return ExecutorSpec("local", workers)
    scheme, sep, rest = scheduler.partition("://")
    if not sep or not scheme or not rest:
        raise ConfigError(
            f"expected local, local:N or a scheduler address such as tcp://HOST:8786, got {scheduler!r}",
            key="--scheduler",
        )
    return ExecutorSpec("remote", 0, scheduler)


def import_dask() -> Any:
    """The ``distributed`` module.

    Raises:
        ConfigError: Dask is not installed (one line saying how to install it).
    """
    try:
        import distributed
    except ImportError as exc:
        raise ConfigError(
            f'needs Dask distributed, which is not installed ({exc}): pip install -e ".[cluster]" '
            "(or pip install 'dask[distributed]'), or use --jobs N for a local process pool",
            key="--scheduler",
        ) from None
    return distributed


class Executor:
    """Runs tasks: :meth:`submit` a function of paths, :meth:`wait` for the first to finish. A context
    manager: leaving it waits for nothing more (pending tasks are cancelled, a local pool's running
    workers stopped when leaving on an exception such as Ctrl-C)."""

    workers: int
    description: str

    def submit(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Start ``fn(*args)`` on a worker; return its future."""
        raise NotImplementedError

    def wait(self, pending: Iterable[Any]) -> tuple[set[Any], set[Any]]:
        """Block until at least one of ``pending`` is finished; return (finished, still pending)."""
        raise NotImplementedError

    def close(self, *, abandon: bool = False) -> None:
        """Release the workers (``abandon``: cancel what is pending and stop what runs)."""
        raise NotImplementedError

    def __enter__(self) -> Executor:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close(abandon=exc_type is not None)


class LocalPool(Executor):
    """A :class:`concurrent.futures.ProcessPoolExecutor` of ``workers`` processes (started fresh with
    ``spawn``: nothing of the parent's threads or open files is inherited)."""

    def __init__(self, workers: int) -> None:
        from flagtrack.daemon.batch.tasks import init_pool_worker

        self.workers = workers
        self.description = f"pool:{workers}"
        self._pool = concurrent.futures.ProcessPoolExecutor(
            max_workers=workers, mp_context=multiprocessing.get_context("spawn"), initializer=init_pool_worker
        )

    def submit(self, fn: Callable[..., Any], *args: Any) -> Any:
        return self._pool.submit(fn, *args)

    def wait(self, pending: Iterable[Any]) -> tuple[set[Any], set[Any]]:
        done, not_done = concurrent.futures.wait(set(pending), return_when=concurrent.futures.FIRST_COMPLETED)
        return set(done), set(not_done)

    def close(self, *, abandon: bool = False) -> None:
        if abandon:
            # The running workers are stopped (SIGTERM unwinds them: an unfinished output's temporary file
            # is removed); ProcessPoolExecutor has no public way to reach them before Python 3.14.
            processes = list((getattr(self._pool, "_processes", None) or {}).values())
            self._pool.shutdown(wait=False, cancel_futures=True)
            for process in processes:
                process.terminate()
            for process in processes:
                process.join(5.0)
        self._pool.shutdown(wait=True, cancel_futures=True)


class DaskExecutor(Executor):
    """A Dask ``Client``: of a ``LocalCluster`` of ``workers`` single-threaded processes started here, or
    connected to the scheduler at ``address`` (whose workers are the lab's)."""

    def __init__(self, spec: ExecutorSpec) -> None:
        distributed = import_dask()
        # Dask's own loggers say INFO by default; they follow -v like flagtrack's.
        logging.getLogger("distributed").setLevel(logging.getLogger().getEffectiveLevel())
        self._distributed = distributed
        self._cluster = None
        self._futures: list[Any] = []
        if spec.kind == "local":
            self._cluster = distributed.LocalCluster(
                n_workers=spec.workers,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=":0",  # any free port: two batches on one machine do not collide
            )
            self._client = distributed.Client(self._cluster)
        else:
            try:
                self._client = distributed.Client(spec.address, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise ConfigError(
                    f"cannot reach the Dask scheduler at {spec.address}: {exc}", key="--scheduler"
                ) from None
        self.workers = max(1, len(self._client.scheduler_info().get("workers", {})))
        self.description = spec.describe()
        log.info("%s: %d workers", self.description, self.workers)

    def submit(self, fn: Callable[..., Any], *args: Any) -> Any:
        future = self._client.submit(fn, *args, pure=False)
        self._futures.append(future)
        return future

    def wait(self, pending: Iterable[Any]) -> tuple[set[Any], set[Any]]:
        done, not_done = self._distributed.wait(list(pending), return_when="FIRST_COMPLETED")
        return set(done), set(not_done)

    def close(self, *, abandon: bool = False) -> None:
        if abandon:
            self._client.cancel(self._futures)  # tasks already running on a remote worker run to their end
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()


def open_executor(spec: ExecutorSpec, tasks: int) -> Executor:
    """The executor of ``spec`` for ``tasks`` tasks (a local pool starts no more processes than tasks).

    Raises:
        ConfigError: Dask is missing, or its scheduler cannot be reached.
    """
    if spec.kind == "pool":
        return LocalPool(max(1, min(spec.workers, tasks)))
    return DaskExecutor(spec)
