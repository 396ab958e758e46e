"""What an ingest did: files ingested, duplicates, already present, warnings and failures."""

from __future__ import annotations

from dataclasses import dataclass

from ingest.errors import FormatError
from ingest.observation import Pass

__all__ = ["IngestReport", "IngestedFile", "DuplicateFile", "IngestWarning", "CommitEvent", "PendingFile"]

# Warnings listed per file in a summary; the rest are counted (``rsodb show PASS`` lists them all).
_WARNINGS_SHOWN_PER_FILE = 5


@dataclass(frozen=True)
class IngestedFile:
    """A file whose passes were stored by this ingest.

    Attributes
    ----------
    path : str
        The file as it was found (not resolved).
    pass_ids : tuple of str
        The passes stored from it (two for a B+V photometer file).
    superseded : tuple of str
        Earlier versions that these passes replace as the current ones (kept in the archive).
    """

    path: str
    pass_ids: tuple[str, ...]
    superseded: tuple[str, ...] = ()


@dataclass(frozen=True)
class DuplicateFile:
    """A file whose rows were all in stored passes: recorded as a duplicate source, not stored again.

    Attributes
    ----------
    path : str
    pass_ids : tuple of str
        The stored passes that hold its rows.
    note : str
        What its header says differently (another band letter, fewer rows, ...), or "".
    """

    path: str
    pass_ids: tuple[str, ...]
    note: str = ""


@dataclass(frozen=True)
class IngestWarning:
    """Something stored with a pass that the user should know: a row set aside, a header that
    disagrees with the data, a pass left without orbital elements.

    Attributes
    ----------
    path : str
    line : int or None
    reason : str
    """

    path: str
    line: int | None
    reason: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.reason}" if self.line is not None else f"{self.path}: {self.reason}"


@dataclass(frozen=True)
class CommitEvent:
    """One object file made durable: everything listed here survives a crash from now on.

    Attributes
    ----------
    norad : int
    ingested : tuple of IngestedFile
        Files whose passes this commit stored.
    already_present : tuple of str
        Files found, under the lock, to be stored already (by this or another process).
    duplicates : tuple of DuplicateFile
        Files recorded as duplicate sources of stored passes.
    """

    norad: int
    ingested: tuple[IngestedFile, ...]
    already_present: tuple[str, ...]
    duplicates: tuple[DuplicateFile, ...] = ()


@dataclass(frozen=True)
class IngestReport:
    """The outcome of `Archive.ingest`.

    Attributes
    ----------
    ingested : tuple of IngestedFile
    already_present : tuple of str
        Files whose exact content (SHA-256) was already stored: nothing was written for them.
    failed : tuple of FormatError
        Files that could not be read or stored; ``str(error)`` reads ``path:line: reason``.
    elapsed_s : float
        Wall-clock duration of the ingest.
    duplicates : tuple of DuplicateFile
        Files whose rows were all stored already (see docs/archive.md, "Pass ids and versions").
    warnings : tuple of IngestWarning
        Rows set aside, headers that disagree with their data, passes left without elements.
    """

    ingested: tuple[IngestedFile, ...] = ()
    already_present: tuple[str, ...] = ()
    failed: tuple[FormatError, ...] = ()
    elapsed_s: float = 0.0
    duplicates: tuple[DuplicateFile, ...] = ()
    warnings: tuple[IngestWarning, ...] = ()

    @property
    def ok(self) -> bool:
        """True when no file failed."""
        return not self.failed

    @property
    def n_files(self) -> int:
        """Files considered: ingested, duplicates, already present and failed."""
        return len(self.ingested) + len(self.duplicates) + len(self.already_present) + len(self.failed)

    @property
    def pass_ids(self) -> tuple[str, ...]:
        """Every pass id stored by this ingest."""
        return tuple(pass_id for item in self.ingested for pass_id in item.pass_ids)

    def summary(self) -> str:
        """A few human-readable lines: counts, then new versions, duplicates, warnings and failures."""
        if self.n_files == 0:
            return "no observation files found (directories are searched for *.ph<letter> files; name other files explicitly)"
        rate = f" in {self.elapsed_s:.1f} s" if self.elapsed_s else ""
        lines = [
            f"ingested {len(self.ingested)} file(s) ({len(self.pass_ids)} pass(es)){rate}, "
            f"{len(self.duplicates)} duplicate(s), {len(self.already_present)} already present, "
            f"{len(self.failed)} failed, {len(self.warnings)} warning(s)"
        ]
        for item in self.ingested:
            for old in item.superseded:
                lines.append(f"  new version of {old} from {item.path}")
        for item in self.duplicates:
            lines.append(
                f"  duplicate: {item.path} holds only rows of {', '.join(item.pass_ids)}; recorded as a duplicate "
                "source, nothing superseded" + (f" ({item.note})" if item.note else "")
            )
        if self.warnings:
            lines.append("warnings:")
            shown: dict[str, int] = {}
            for warning in self.warnings:
                shown[warning.path] = shown.get(warning.path, 0) + 1
                if shown[warning.path] <= _WARNINGS_SHOWN_PER_FILE:
                    lines.append(f"  {warning}")
            for path, count in shown.items():
                if count > _WARNINGS_SHOWN_PER_FILE:
                    lines.append(
                        f"  ... and {count - _WARNINGS_SHOWN_PER_FILE} more for {path} ('rsodb show PASS' lists them)"
                    )
        if self.failed:
            lines.append("failed:")
            lines.extend(f"  {error}" for error in self.failed)
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready form of the report."""
        return {
            "ingested": [
                {"path": item.path, "pass_ids": list(item.pass_ids), "superseded": list(item.superseded)}
                for item in self.ingested
            ],
            "duplicates": [
                {"path": item.path, "pass_ids": list(item.pass_ids), "note": item.note} for item in self.duplicates
            ],
            "already_present": list(self.already_present),
            "warnings": [
                {"path": item.path, "line": item.line, "reason": item.reason, "message": str(item)}
                for item in self.warnings
            ],
            "failed": [
                {"path": error.path, "line": error.line, "reason": error.reason, "message": str(error)}
                for error in self.failed
            ],
            "elapsed_s": round(self.elapsed_s, 3),
        }


@dataclass(frozen=True)
class PendingFile:
    """Passes read from one file, waiting to be committed to their object.

    Attributes
    ----------
    path : str
        Where they came from, as reported to the user.
    sha256 : str
        Content hash: a file whose hash is stored already is skipped.
    passes : tuple of Pass
        All of the same object.
    prepared : Staged or None
        The object's next file, staged by the reader process from the object file as it was
        then (`rsodb.archive.commits.ObjectTransaction.hand_over`); the commit publishes it when
        this is the object's only file in the round and the object file has not changed since,
        and stages the file itself otherwise.
    """

    path: str
    sha256: str
    passes: tuple[Pass, ...]
    prepared: object | None = None
