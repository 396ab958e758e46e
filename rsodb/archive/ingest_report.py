"""What an ingest did: files ingested, already present, and failed (with file, line and reason)."""

from __future__ import annotations

from dataclasses import dataclass

from ingest.errors import FormatError
from ingest.observation import Pass

__all__ = ["IngestReport", "IngestedFile", "CommitEvent", "PendingFile"]


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
class CommitEvent:
    """One object file made durable: everything listed here survives a crash from now on.

    Attributes
    ----------
    norad : int
    ingested : tuple of IngestedFile
        Files whose passes this commit stored.
    already_present : tuple of str
        Files found, under the lock, to be stored already (by this or another process).
    """

    norad: int
    ingested: tuple[IngestedFile, ...]
    already_present: tuple[str, ...]


@dataclass(frozen=True)
class IngestReport:
    """The outcome of `Archive.ingest`.

    Attributes
    ----------
    ingested : tuple of IngestedFile
    already_present : tuple of str
        Files whose exact content (SHA-256) was already stored: nothing was written for them.
    failed : tuple of FormatError
        Files that could not be read; ``str(error)`` reads ``path:line: reason``.
    elapsed_s : float
        Wall-clock duration of the ingest.
    """

    ingested: tuple[IngestedFile, ...] = ()
    already_present: tuple[str, ...] = ()
    failed: tuple[FormatError, ...] = ()
    elapsed_s: float = 0.0

    @property
    def ok(self) -> bool:
        """True when no file failed."""
        return not self.failed

    @property
    def n_files(self) -> int:
        """Files considered: ingested, already present and failed."""
        return len(self.ingested) + len(self.already_present) + len(self.failed)

    @property
    def pass_ids(self) -> tuple[str, ...]:
        """Every pass id stored by this ingest."""
        return tuple(pass_id for item in self.ingested for pass_id in item.pass_ids)

    def summary(self) -> str:
        """A few human-readable lines: counts, then one line per failed file."""
        if self.n_files == 0:
            return "no observation files found (directories are searched for *.ph<letter> files)"
        rate = f" in {self.elapsed_s:.1f} s" if self.elapsed_s else ""
        lines = [
            f"ingested {len(self.ingested)} file(s) ({len(self.pass_ids)} pass(es)){rate}, "
            f"{len(self.already_present)} already present, {len(self.failed)} failed"
        ]
        superseded = [(old, item.path) for item in self.ingested for old in item.superseded]
        for old, path in superseded:
            lines.append(f"  new version of {old} from {path}")
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
            "already_present": list(self.already_present),
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
    """

    path: str
    sha256: str
    passes: tuple[Pass, ...]
