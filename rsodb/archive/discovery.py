"""Finding observation files under the paths a user names.

Files named explicitly are always read (the readers recognise formats by content). Inside
directories, which may also hold images, logs and notes, only names that look like observation
files are taken: ``*.ph<letter>`` (ccd_phot ``.phV``, ``.phR``, ... and the photometer's ``.phc``).
Hidden files and directories are skipped. Symbolic links are followed, but each real directory is
entered once, so a link loop ends the walk instead of hanging it, and a file reached twice is
listed once.
"""

from __future__ import annotations

from collections.abc import Iterable
import os
from pathlib import Path
import re

from ingest.errors import FormatError

__all__ = ["find_observation_files", "OBSERVATION_NAME"]

OBSERVATION_NAME = re.compile(r"\.ph[A-Za-z]$")


def find_observation_files(paths: Iterable[str | os.PathLike]) -> tuple[list[Path], list[FormatError]]:
    """Files to ingest under `paths`, and the paths that could not be used.

    Parameters
    ----------
    paths : iterable of str or path-like
        Files and directories (walked recursively).

    Returns
    -------
    files : list of Path
        In the order given; files of a directory sorted by path. Each real file appears once.
    problems : list of FormatError
        Missing paths, broken links and unreadable directories, with the reason.
    """
    files: list[Path] = []
    problems: list[FormatError] = []
    seen_files: set[tuple[int, int]] = set()
    seen_dirs: set[tuple[int, int]] = set()

    def add_file(path: Path, stat: os.stat_result) -> None:
        key = (stat.st_dev, stat.st_ino)
        if key not in seen_files:
            seen_files.add(key)
            files.append(path)

    def walk(directory: Path) -> None:
        try:
            stat = directory.stat()
        except OSError as exc:
            problems.append(FormatError(directory, None, f"cannot open directory ({exc.strerror})"))
            return
        key = (stat.st_dev, stat.st_ino)
        if key in seen_dirs:
            return  # a link back to a directory already walked: a loop, or a second route in
        seen_dirs.add(key)
        try:
            entries = sorted(os.scandir(directory), key=lambda entry: entry.name)
        except OSError as exc:
            problems.append(FormatError(directory, None, f"cannot list directory ({exc.strerror})"))
            return
        for entry in entries:
            if entry.name.startswith("."):
                continue
            path = directory / entry.name
            try:
                is_dir = entry.is_dir(follow_symlinks=True)
                is_file = not is_dir and entry.is_file(follow_symlinks=True)
            except OSError as exc:
                problems.append(FormatError(path, None, f"cannot inspect ({exc.strerror})"))
                continue
            if is_dir:
                walk(path)
            elif OBSERVATION_NAME.search(entry.name):
                if is_file:
                    add_file(path, path.stat())
                elif entry.is_symlink():
                    problems.append(FormatError(path, None, "broken symbolic link; its target does not exist"))

    for raw in paths:
        path = Path(raw)
        try:
            stat = path.stat()
        except FileNotFoundError:
            problems.append(FormatError(path, None, "no such file or directory"))
            continue
        except OSError as exc:
            problems.append(FormatError(path, None, f"cannot open ({exc.strerror})"))
            continue
        if path.is_dir():
            walk(path)
        else:
            add_file(path, stat)
    return files, problems
