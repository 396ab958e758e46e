"""``rsodb check``: read every object file, report damage, optionally move damaged files aside,
and rebuild the catalog index from the files.

A damaged object file is never repaired in place: it is moved to ``damaged/`` in the archive
directory (under its object's lock, by one rename), so that the archive holds only verified
objects and the damaged bytes stay available for a closer look. Its passes can then be restored
from a backup or by ingesting their files again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
import os
from pathlib import Path
import re
from typing import TYPE_CHECKING

from rsodb.archive import layout
from rsodb.archive.integrity import verify_object

if TYPE_CHECKING:
    from rsodb.archive.store import Archive

__all__ = ["CheckReport", "check_archive"]

_OBJECT_NAME = re.compile(r"^(\d+)\.h5$")


@dataclass
class CheckReport:
    """What `check_archive` found.

    Attributes
    ----------
    n_objects : int
        Object files read.
    damaged : dict of str to list of str
        Object file -> what is wrong with it.
    moved : dict of str to str
        Damaged file -> where it was moved (with ``repair``).
    n_indexed : int
        Objects in the rebuilt index.
    """

    n_objects: int = 0
    damaged: dict[str, list[str]] = field(default_factory=dict)
    moved: dict[str, str] = field(default_factory=dict)
    n_indexed: int = 0

    @property
    def ok(self) -> bool:
        """True when no object file was damaged."""
        return not self.damaged

    def summary(self) -> str:
        lines = [
            f"checked {self.n_objects} object file(s): {self.n_objects - len(self.damaged)} whole, "
            f"{len(self.damaged)} damaged; index rebuilt ({self.n_indexed} objects)"
        ]
        for path, problems in self.damaged.items():
            lines.append(f"  {path}: {problems[0]}" + (f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""))
            if path in self.moved:
                lines.append(f"    moved to {self.moved[path]}")
        if self.damaged and not self.moved:
            lines.append("run again with --repair to move the damaged files aside")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "n_objects": self.n_objects,
            "damaged": [
                {"path": path, "problems": problems, "moved_to": self.moved.get(path)}
                for path, problems in self.damaged.items()
            ],
            "n_indexed": self.n_indexed,
        }


def check_archive(archive: Archive, repair: bool = False, progress: bool = False) -> CheckReport:
    """Verify every object file of `archive` (see `rsodb.archive.integrity.verify_object`).

    Parameters
    ----------
    archive : Archive
    repair : bool
        Move damaged files to ``damaged/<name>.<UTC time>`` (under the object's lock).
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    CheckReport
    """
    report = CheckReport()
    names = sorted(
        (int(match.group(1)), entry)
        for entry in os.listdir(archive.objects_dir)
        if (match := _OBJECT_NAME.match(entry)) is not None
    )
    from tqdm import tqdm  # only a check shows progress; lookups import this module (~30 ms)

    for norad, name in tqdm(names, disable=not progress, unit="object", desc="check"):
        path = archive.objects_dir / name
        report.n_objects += 1
        problems = verify_object(path)
        if not problems:
            continue
        report.damaged[str(path)] = problems
        if repair:
            report.moved[str(path)] = str(_move_aside(archive, norad, path))
    report.n_indexed = archive.rebuild_index()
    return report


def _move_aside(archive: Archive, norad: int, path: Path) -> Path:
    """Rename a damaged object file into ``damaged/`` while holding its lock."""
    target_dir = archive.path / layout.DAMAGED_DIR
    target_dir.mkdir(exist_ok=True)
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    target = target_dir / f"{path.name}.{stamp}"
    with archive.object_lock(norad):
        os.replace(path, target)
    return target
