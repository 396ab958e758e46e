"""The ingest pipeline: find files, read them in worker processes, commit per object in batches.

Reading (parsing text) is the expensive part and runs in a process pool; the parent collects
the passes per object and commits them in batches. A commit copies the object's current file, so
committing after every file would cost time quadratic in the object's size; committing too rarely
would lose more work to a crash and hold more passes in memory. The parent therefore commits
every `commit_interval_s` seconds, but never sooner than `_COMMIT_SPACING` times the duration of
its previous commit (so commits take at most ~1/(1 + spacing) of the wall time however large the
objects grow), and whenever the passes waiting in memory exceed `_MAX_PENDING_BYTES`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
import hashlib
import multiprocessing
import os
from pathlib import Path
import time
from typing import TYPE_CHECKING

from tqdm import tqdm

from ingest.errors import FormatError
from ingest.readers import read_file
from rsodb.archive.discovery import find_observation_files
from rsodb.archive.ingest_report import CommitEvent, IngestReport, PendingFile

if TYPE_CHECKING:
    from rsodb.archive.store import Archive

__all__ = ["run_ingest", "read_observation_file"]

_COMMIT_SPACING = 3.0
_MAX_PENDING_BYTES = 256 << 20
# Below this many files a process pool costs more (start-up, imports) than it saves.
_MIN_FILES_FOR_POOL = 16
_CHUNK_FILES = 4
_READ_AHEAD_CHUNKS_PER_WORKER = 32

_known_sha256: frozenset[str] = frozenset()


def _init_worker(known_sha256: frozenset[str]) -> None:
    global _known_sha256
    _known_sha256 = known_sha256


def read_observation_file(path: str, known_sha256: frozenset[str] = frozenset()):
    """Read one file for ingest.

    Returns
    -------
    (path, sha256, passes, error)
        `passes` is None when the file's SHA-256 is in `known_sha256` (nothing parsed) or when it
        failed; `error` is then a `FormatError` naming file, line and reason.
    """
    sha = ""
    if known_sha256:  # hash first only when a stored file could match (the reader hashes too)
        try:
            with open(path, "rb") as handle:
                sha = hashlib.file_digest(handle, "sha256").hexdigest()
        except IsADirectoryError:
            return path, "", None, FormatError(path, None, "is a directory, not an observation file")
        except OSError as exc:
            return path, "", None, FormatError(path, None, f"cannot read ({exc.strerror or exc})")
        if sha in known_sha256:
            return path, sha, None, None
    try:
        passes = tuple(read_file(path))
    except FormatError as exc:
        return path, sha, None, exc
    except IsADirectoryError:
        return path, sha, None, FormatError(path, None, "is a directory, not an observation file")
    except OSError as exc:
        return path, sha, None, FormatError(path, None, f"cannot read ({exc.strerror or exc})")
    except (ValueError, UnicodeError) as exc:
        return path, sha, None, FormatError(path, None, str(exc) or type(exc).__name__)
    except Exception as exc:  # a reader bug must not stop the batch; it is reported, not hidden
        return (
            path,
            sha,
            None,
            FormatError(path, None, f"unexpected {type(exc).__name__} in the reader ({exc}); please report this file"),
        )
    if not passes:
        return path, sha, None, FormatError(path, None, "the file holds no light curve")
    return path, sha or passes[0].source_sha256, passes, None


def _read_chunk(paths: list[str]):
    return [read_observation_file(path, _known_sha256) for path in paths]


def _auto_workers(n_files: int) -> int:
    if n_files < _MIN_FILES_FOR_POOL:
        return 0
    return max(1, min(os.cpu_count() or 1, 8))


def _results(files: list[Path], known: frozenset[str], workers: int):
    """Yield read results in file order, reading ahead in `workers` processes (0: in this one)."""
    paths = [str(path) for path in files]
    if workers == 0:
        for path in paths:
            yield read_observation_file(path, known)
        return
    chunks = [paths[i : i + _CHUNK_FILES] for i in range(0, len(paths), _CHUNK_FILES)]
    # Read far enough ahead that the readers keep parsing while the parent commits (a commit
    # round over 50 objects takes up to seconds late in a large ingest); ~50 MB of 2500-row passes.
    window = _READ_AHEAD_CHUNKS_PER_WORKER * workers
    # Spawned, not forked: a fork taken while another thread of this process holds a lock (an
    # Embree or BLAS pool, a logging handler) can leave the reader waiting on it forever.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_init_worker, initargs=(known,)
    ) as pool:
        queued = deque()
        next_chunk = 0
        try:
            while queued or next_chunk < len(chunks):
                while len(queued) < window and next_chunk < len(chunks):
                    queued.append(pool.submit(_read_chunk, chunks[next_chunk]))
                    next_chunk += 1
                yield from queued.popleft().result()
        finally:
            for future in queued:
                future.cancel()


def run_ingest(
    archive: Archive,
    paths: list,
    *,
    progress: bool = True,
    workers: int | None = None,
    on_commit: Callable[[CommitEvent], None] | None = None,
    commit_interval_s: float = 1.0,
) -> IngestReport:
    """Implementation of `Archive.ingest` (see there)."""
    if workers is not None and (not isinstance(workers, int) or workers < 0):
        raise ValueError(f"workers={workers!r} must be a non-negative integer (0 reads in this process)")
    if not commit_interval_s >= 0:
        raise ValueError(f"commit_interval_s={commit_interval_s!r} must be zero or positive seconds")
    started = time.monotonic()
    files, problems = find_observation_files(paths)
    failed: list[FormatError] = list(problems)
    present: list[str] = []
    ingested = []
    known = frozenset(row.source_sha256 for row in archive.catalog(all_versions=True))
    workers = _auto_workers(len(files)) if workers is None else workers

    pending: dict[int, list[PendingFile]] = {}
    pending_sha: set[str] = set()
    pending_bytes = 0
    last_commit_end = time.monotonic()
    last_commit_cost = 0.0

    def commit_pending() -> None:
        nonlocal pending_bytes, last_commit_end, last_commit_cost
        began = time.monotonic()
        for norad in sorted(pending):
            event = archive.commit(norad, pending[norad])
            ingested.extend(event.ingested)
            present.extend(event.already_present)
            if on_commit is not None:
                on_commit(event)
        pending.clear()
        pending_sha.clear()
        pending_bytes = 0
        last_commit_end = time.monotonic()
        last_commit_cost = last_commit_end - began

    with tqdm(total=len(files), disable=not progress, unit="file", desc="ingest", dynamic_ncols=True) as bar:
        for path, sha, passes, error in _results(files, known, workers):
            bar.update(1)
            if error is not None:
                failed.append(error)
            elif passes is None or sha in pending_sha:
                present.append(path)
            else:
                pending_sha.add(sha)
                by_object: dict[int, list] = {}
                for pass_ in passes:
                    by_object.setdefault(int(pass_.norad), []).append(pass_)
                for norad, object_passes in by_object.items():
                    pending.setdefault(norad, []).append(PendingFile(path, sha, tuple(object_passes)))
                pending_bytes += sum(pass_.time_utc.nbytes * 11 for pass_ in passes)
            since = time.monotonic() - last_commit_end
            if pending and (
                pending_bytes > _MAX_PENDING_BYTES
                or since >= max(commit_interval_s, _COMMIT_SPACING * last_commit_cost)
            ):
                commit_pending()
            if progress:
                bar.set_postfix(committed=len(ingested), present=len(present), failed=len(failed), refresh=False)
        if pending:
            commit_pending()

    order = {str(path): i for i, path in enumerate(files)}
    ingested.sort(key=lambda item: order.get(item.path, len(order)))
    return IngestReport(
        ingested=tuple(ingested),
        already_present=tuple(present),
        failed=tuple(failed),
        elapsed_s=time.monotonic() - started,
    )
