"""Per-object write locks and the atomic file replacement that every archive write goes through.

Two processes that write the same object take turns on an advisory ``fcntl.flock`` of the
object's lock file; readers never lock. A writer builds the object's next state in a temporary
file beside the current one, flushes it to disk, renames it over the current file and flushes the
directory, so a reader (or a process that was killed mid-write) sees either the old file or the
new one, never a mixture.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
import ctypes
import errno
import fcntl
import os
from pathlib import Path
import secrets
import shutil
import time

__all__ = [
    "ObjectLock",
    "replacing",
    "temp_path",
    "publish",
    "stale_temp_files",
    "remove_abandoned_staging",
    "TEMP_SUFFIX",
]

TEMP_SUFFIX = ".tmp"
# A staging directory without its lock file is a killed run's after this long.
_ORPHAN_STAGING_S = 3600.0


class ObjectLock:
    """An exclusive advisory lock on one lock file, usable as a context manager.

    Parameters
    ----------
    path : Path
        The lock file; created when missing and never deleted (deleting a lock file that another
        process has open would let two writers hold "the" lock at once).
    timeout_s : float or None
        Give up with `TimeoutError` after this many seconds of waiting; None waits forever.
    """

    def __init__(self, path: Path, timeout_s: float | None = 600.0):
        self.path = Path(path)
        self.timeout_s = timeout_s
        self._fd: int | None = None

    def acquire(self, blocking: bool = True) -> bool:
        """Take the lock; return False only when `blocking` is False and another process holds it."""
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        deadline = None if self.timeout_s is None else time.monotonic() + self.timeout_s
        delay_s = 0.002
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                self._fd = fd
                return True
            except OSError as exc:
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN):
                    os.close(fd)
                    raise
            if not blocking:
                os.close(fd)
                return False
            if deadline is not None and time.monotonic() > deadline:
                os.close(fd)
                raise TimeoutError(
                    f"{self.path} has been locked by another writer for more than {self.timeout_s:g} s; "
                    "wait for the other ingest or fit to finish, or stop it"
                )
            time.sleep(delay_s)
            delay_s = min(delay_s * 2, 0.05)

    def release(self) -> None:
        """Drop the lock (closing the descriptor releases the flock)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> ObjectLock:
        self.acquire()
        return self

    def __exit__(self, *exc_info) -> None:
        self.release()


def _fsync_path(path: Path, directory: bool = False) -> None:
    fd = os.open(path, os.O_RDONLY | (os.O_DIRECTORY if directory else 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def temp_path(final_path: Path) -> Path:
    """A fresh temporary name beside `final_path` (``.<name>.<pid>.<random>.tmp``)."""
    final_path = Path(final_path)
    return final_path.with_name(f".{final_path.name}.{os.getpid()}.{secrets.token_hex(4)}{TEMP_SUFFIX}")


def _syncfs():
    """libc's ``syncfs(fd)`` (Linux), or None."""
    try:
        function = ctypes.CDLL(None, use_errno=True).syncfs
    except (AttributeError, OSError):
        return None
    function.argtypes = [ctypes.c_int]
    return function


_SYNCFS = _syncfs()
# From this many files on, one syncfs of the file system beats an fsync per file.
_SYNCFS_FROM = 4


def publish(replacements: Sequence[tuple[Path, Path]], directory: Path, durable: bool = True) -> None:
    """Make each complete temporary file its final file: flush them all, rename each, flush the directory.

    All files must be closed and live in `directory`, whose objects' locks the caller holds.
    Flushing many files at once (one ``syncfs``) costs about what one ``fsync`` does, so a round of
    commits over many objects pays for one flush instead of one per object. Each rename is atomic,
    so every object is either in its old or in its new state.
    """
    if durable and replacements:
        flushed = False
        if _SYNCFS is not None and len(replacements) >= _SYNCFS_FROM:
            fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
            try:
                flushed = _SYNCFS(fd) == 0
            finally:
                os.close(fd)
        if not flushed:
            for tmp, _ in replacements:
                _fsync_path(tmp)
    for tmp, final in replacements:
        os.replace(tmp, final)
    if durable and replacements:
        _fsync_path(directory, directory=True)


@contextmanager
def replacing(final_path: Path, durable: bool = True) -> Iterator[Path]:
    """Yield a temporary path; on normal exit make it `final_path` atomically.

    The body writes the complete new content to the yielded path and closes it. On exit the
    temporary file is fsynced, renamed over `final_path` (atomic on POSIX) and the directory is
    fsynced, so the rename itself survives a power cut. If the body raises, the temporary file is
    removed and `final_path` is untouched. The caller must hold the object's lock.

    Parameters
    ----------
    final_path : Path
        The file to create or replace.
    durable : bool
        fsync file and directory (default). Without it the replacement is still atomic for
        readers and survives a killed process, but not a power cut.
    """
    final_path = Path(final_path)
    tmp = temp_path(final_path)
    try:
        yield tmp
        publish([(tmp, final_path)], final_path.parent, durable)
    finally:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass


def stale_temp_files(directory: Path, final_name: str) -> list[Path]:
    """Temporary files that writers of `final_name` left in `directory` (call with its lock held);
    `final_name` "" lists those of every file."""
    prefix = f".{final_name}." if final_name else "."
    try:
        names = os.listdir(directory)
    except FileNotFoundError:
        return []
    return [directory / name for name in names if name.startswith(prefix) and name.endswith(TEMP_SUFFIX)]


def remove_abandoned_staging(root: Path) -> None:
    """Remove the staging directories under `root` of runs that have ended or were killed: each
    run holds the lock on ``<name>.lock`` beside its directory ``<name>`` while it lives."""
    for entry in os.scandir(root):
        if entry.name.endswith(".lock"):
            lock = ObjectLock(Path(entry.path), timeout_s=0)
            if lock.acquire(blocking=False):  # its run has ended (or was killed)
                try:
                    shutil.rmtree(root / entry.name.removesuffix(".lock"), ignore_errors=True)
                    Path(entry.path).unlink(missing_ok=True)
                finally:
                    lock.release()
        elif entry.is_dir() and not (root / f"{entry.name}.lock").exists():
            try:  # its run may be removing it right now, or may be about to lock it
                abandoned = time.time() - entry.stat().st_mtime > _ORPHAN_STAGING_S
            except FileNotFoundError:
                continue
            if abandoned:
                shutil.rmtree(entry.path, ignore_errors=True)
