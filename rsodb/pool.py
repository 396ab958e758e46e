"""Map a function over many items in a process pool, with a progress bar.

Workers are started with the ``spawn`` method (no inherited locks, open HDF5 files or threads)
and with one BLAS/OpenMP thread each: the period search works on small matrices, for which a
second BLAS thread per process only adds contention on a machine whose cores the processes
already fill.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
import multiprocessing
import os

__all__ = ["imap_in_pool", "default_processes", "ingest_readers", "SINGLE_THREAD_ENV"]

SINGLE_THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def default_processes() -> int:
    """Usable CPU cores of this process."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def ingest_readers() -> int:
    """Reader processes an ingest uses at most: one more than the usable cores. A reader waits
    part of the time on reading object files and writing the next ones; with one reader per core
    an ingest into a 100 000-pass archive left ~17% of the CPU idle (bench/archive_scale.py)."""
    return default_processes() + 1


@contextmanager
def environment(values: dict) -> Iterator[None]:
    """Set environment variables for the children spawned inside the block, then restore them."""
    saved = {key: os.environ.get(key) for key in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def imap_in_pool(
    function: Callable,
    items: Iterable,
    *,
    processes: int | None = None,
    progress: bool = True,
    description: str = "",
    ordered: bool = False,
    chunksize: int | None = None,
) -> Iterator:
    """Yield ``function(item)`` for every item, computed in worker processes.

    Parameters
    ----------
    function : callable
        A module-level function (it is pickled by name).
    items : iterable
        Picklable arguments.
    processes : int, optional
        Workers (default: the usable cores); 1 runs in this process, without a pool.
    progress : bool
        Show a tqdm bar on stderr.
    description : str
        Label of the bar.
    ordered : bool
        Yield in the order of `items` (default: as results arrive).
    chunksize : int, optional
        Items sent to a worker at a time (default: about 4 chunks per worker).

    Yields
    ------
    object
        The results.
    """
    items = list(items)
    processes = default_processes() if processes is None else int(processes)
    if processes < 1:
        raise ValueError(f"processes={processes!r} must be at least 1")
    if not items:  # nothing to do: no bar (and none of tqdm's imports, 50 ms)
        return
    # tqdm.auto loads asyncio; the archive's commands import this module for default_processes
    # alone and should not load it at start-up (bench/archive_scale.py times their start-up).
    from tqdm.auto import tqdm

    bar = tqdm(total=len(items), desc=description or None, disable=not progress, unit="item")
    try:
        if processes == 1 or len(items) <= 1:
            for item in items:
                yield function(item)
                bar.update()
            return
        chunksize = chunksize or max(1, len(items) // (4 * processes))
        context = multiprocessing.get_context("spawn")
        with environment(SINGLE_THREAD_ENV):
            pool = context.Pool(min(processes, len(items)))
        with pool:
            mapper = pool.imap if ordered else pool.imap_unordered
            for result in mapper(function, items, chunksize=chunksize):
                yield result
                bar.update()
    finally:
        bar.close()
