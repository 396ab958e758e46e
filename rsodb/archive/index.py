"""The catalog index: a SQLite copy of every object file's catalog, results and duplicates.

The object files stay the truth; the index (``catalog.sqlite`` in the archive directory) is
derived from them and can be deleted at any time. It makes a lookup cost what its result costs:
one object's passes, a pass id prefix or a survey query over all passes read a few index rows
instead of opening every object file.

Freshness. Every writer updates the index right after its rename, still holding the object's
lock, recording the new file's identity (inode, size, mtime). A writer killed in between leaves
the index describing the previous file, which readers detect by comparing that identity with the
file's: a query about one object stats that object's file; a query over the whole archive stats
every object file, unless the ``objects/`` directory has not changed since the last such sweep
(a rename changes it). A stale or missing object is read again from its file (its ``/catalog``,
``/results`` and ``/duplicates`` tables) before the query runs. A file that cannot be read is
listed as damaged with the reason; its passes leave the index until it is repaired.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
import os
from pathlib import Path
import sqlite3
import threading
import time

import numpy as np

from rsodb.archive.stored import DamagedObject, DuplicateSource, PassSummary, ResultSummary

__all__ = ["CatalogIndex", "ObjectState", "PassQuery", "DamagedIndexError", "StoredSources", "INDEX_VERSION"]

INDEX_VERSION = 1
# SQLite waits this long for another process's write transaction.
_BUSY_TIMEOUT_S = 60.0
# A directory whose mtime is this recent may change again within the same clock tick, so a sweep
# does not vouch for it.
_SETTLED_NS = 2_000_000_000

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT);
CREATE TABLE IF NOT EXISTS objects (
    norad INTEGER PRIMARY KEY, ino INTEGER, size INTEGER, mtime_ns INTEGER,
    status TEXT NOT NULL, error TEXT, name TEXT, cospar TEXT
);
CREATE TABLE IF NOT EXISTS passes (
    pass_id TEXT PRIMARY KEY, norad INTEGER NOT NULL, lineage_id TEXT, natural_id TEXT,
    version INTEGER, supersedes TEXT, superseded_by TEXT, name TEXT, band TEXT, site TEXT,
    site_key TEXT, start_utc INTEGER, end_utc INTEGER, n_points INTEGER, exposure_s REAL,
    source_name TEXT, source_sha256 TEXT, source_format TEXT, ingested_utc TEXT,
    n_row_problems INTEGER, n_warnings INTEGER, elements TEXT
);
CREATE INDEX IF NOT EXISTS passes_norad ON passes (norad, start_utc);
CREATE INDEX IF NOT EXISTS passes_start ON passes (start_utc);
CREATE INDEX IF NOT EXISTS passes_sha ON passes (source_sha256);
CREATE TABLE IF NOT EXISTS results (
    pass_id TEXT NOT NULL, norad INTEGER NOT NULL, kind TEXT NOT NULL, name TEXT NOT NULL,
    stored_utc TEXT, result_type TEXT, period_s REAL, period_err_s REAL, verdict TEXT,
    PRIMARY KEY (pass_id, kind, name)
);
CREATE INDEX IF NOT EXISTS results_norad ON results (norad);
CREATE INDEX IF NOT EXISTS results_period ON results (kind, name, period_s);
CREATE INDEX IF NOT EXISTS results_verdict ON results (kind, name, verdict, period_s);
CREATE TABLE IF NOT EXISTS sources (
    sha256 TEXT NOT NULL, norad INTEGER NOT NULL, source_name TEXT, pass_id TEXT,
    ingested_utc TEXT, note TEXT
);
CREATE INDEX IF NOT EXISTS sources_sha ON sources (sha256);
CREATE INDEX IF NOT EXISTS sources_norad ON sources (norad);
"""

_N_INDEXES = _SCHEMA.count("CREATE INDEX")
_PASS_COLUMNS = (
    "pass_id",
    "lineage_id",
    "natural_id",
    "version",
    "supersedes",
    "superseded_by",
    "norad",
    "name",
    "band",
    "site",
    "start_utc",
    "end_utc",
    "n_points",
    "exposure_s",
    "source_name",
    "source_sha256",
    "source_format",
    "ingested_utc",
    "n_row_problems",
    "n_warnings",
    "elements",
)

_INSERT_COLUMNS = [
    name for column in _PASS_COLUMNS for name in ((column, "site_key") if column == "site" else (column,))
]
_INSERT_PASS = f"INSERT INTO passes ({', '.join(_INSERT_COLUMNS)}) VALUES ({', '.join('?' * len(_INSERT_COLUMNS))})"


@dataclass(frozen=True)
class ObjectState:
    """What the index knows of one object file.

    Attributes
    ----------
    norad : int
    ino, size, mtime_ns : int
        The file's identity when it was indexed.
    status : str
        ``"ok"`` or ``"damaged"``.
    error : str
        Why it is damaged.
    """

    norad: int
    ino: int
    size: int
    mtime_ns: int
    status: str = "ok"
    error: str = ""

    @classmethod
    def of(cls, norad: int, stat: os.stat_result, status: str = "ok", error: str = "") -> ObjectState:
        return cls(int(norad), stat.st_ino, stat.st_size, stat.st_mtime_ns, status, error)

    def matches(self, stat: os.stat_result) -> bool:
        """True when `stat` describes the file this state was taken from."""
        return (self.ino, self.size, self.mtime_ns) == (stat.st_ino, stat.st_size, stat.st_mtime_ns)


@dataclass(frozen=True)
class PassQuery:
    """Which passes a query selects (every field optional).

    Attributes
    ----------
    norad : int or None
    band : str or None
        Exact band.
    site : str or None
        Site name, case-insensitive.
    all_versions : bool
        Include versions superseded by a changed file.
    since_utc, until_utc : numpy.datetime64 or None
        Passes starting at or after / before these times.
    period_min_s, period_max_s : float or None
        Passes whose stored period result lies in this range (passes without one are left out
        when either bound is given).
    verdict : str or None
        Passes whose stored period result has this verdict.
    periods_name : str
        The period result the period columns and filters use.
    pass_id_prefix : str or None
        Pass ids starting with this text.
    """

    norad: int | None = None
    band: str | None = None
    site: str | None = None
    all_versions: bool = False
    since_utc: np.datetime64 | None = None
    until_utc: np.datetime64 | None = None
    period_min_s: float | None = None
    period_max_s: float | None = None
    verdict: str | None = None
    periods_name: str = "default"
    pass_id_prefix: str | None = None

    def where(self) -> tuple[str, list]:
        """The SQL condition on ``p`` (passes) and ``r`` (the joined result), and its parameters."""
        clauses, params = [], []
        if self.norad is not None:
            clauses.append("p.norad = ?")
            params.append(int(self.norad))
        if self.band is not None:
            clauses.append("p.band = ?")
            params.append(self.band)
        if self.site is not None:
            clauses.append("p.site_key = ?")
            params.append(self.site.strip().lower())
        if not self.all_versions:
            clauses.append("(p.superseded_by IS NULL OR p.superseded_by = '')")
        for bound, op in ((self.since_utc, ">="), (self.until_utc, "<")):
            if bound is not None:
                clauses.append(f"p.start_utc {op} ?")
                params.append(int(np.datetime64(bound, "ns").astype(np.int64)))
        if self.period_min_s is not None:
            clauses.append("r.period_s >= ?")
            params.append(float(self.period_min_s))
        if self.period_max_s is not None:
            clauses.append("r.period_s <= ?")
            params.append(float(self.period_max_s))
        if self.verdict is not None:
            clauses.append("r.verdict = ?")
            params.append(self.verdict)
        if self.pass_id_prefix:
            # A range on the primary key: the prefix and everything that sorts after it with the
            # same beginning (U+10FFFF sorts after any character a pass id holds).
            clauses.append("p.pass_id >= ? AND p.pass_id < ?")
            params += [self.pass_id_prefix, self.pass_id_prefix + "\U0010ffff"]
        return (" AND ".join(clauses) or "1"), params


def _summary(row: tuple) -> PassSummary:
    (
        pass_id,
        lineage_id,
        natural_id,
        version,
        supersedes,
        superseded_by,
        norad,
        name,
        band,
        site,
        start,
        end,
        n_points,
        exposure_s,
        source_name,
        source_sha256,
        source_format,
        ingested_utc,
        n_row_problems,
        n_warnings,
        elements,
        period_s,
        period_err_s,
        verdict,
    ) = row
    return PassSummary(
        pass_id=pass_id,
        lineage_id=lineage_id,
        natural_id=natural_id,
        version=version,
        supersedes=supersedes or None,
        superseded_by=superseded_by or None,
        norad=norad,
        name=name,
        band=band,
        site=site,
        start_utc=np.datetime64(start, "ns"),
        end_utc=np.datetime64(end, "ns"),
        n_points=n_points,
        exposure_s=exposure_s,
        source_name=source_name,
        source_sha256=source_sha256,
        source_format=source_format,
        ingested_utc=ingested_utc,
        n_row_problems=n_row_problems or 0,
        n_warnings=n_warnings or 0,
        elements=elements or "",
        period_s=period_s,
        period_err_s=period_err_s,
        verdict=verdict or None,
    )


class DamagedIndexError(OSError):
    """The catalog index cannot be read; it holds nothing the object files do not."""


def _chunks(items: list, size: int = 500) -> list[list]:
    """`items` in pieces small enough for one SQL statement's parameters."""
    return [items[i : i + size] for i in range(0, len(items), size)]


class StoredSources:
    """``sha256 in sources``: whether a file with that content is stored (the source of a pass or a
    duplicate source), asked of the index file itself: an ingest's reader processes ask it file by
    file (an indexed lookup), instead of receiving every stored hash when they start (a 100 000-pass
    archive's 6 MB pickle held each reader's start-up, one after the other).

    Read-only and picklable (the connection is opened on first use in each process). An index
    that cannot be read answers "not stored": the file is then read, and its commit finds it.
    """

    _QUERY = "SELECT 1 FROM passes WHERE source_sha256 = ?1 UNION ALL SELECT 1 FROM sources WHERE sha256 = ?1 LIMIT 1"

    def __init__(self, path: Path):
        self.path = Path(path)
        self._db: sqlite3.Connection | None = None

    def __getstate__(self) -> dict:
        return {"path": self.path}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["path"])

    def __contains__(self, sha256: object) -> bool:
        try:
            if self._db is None:
                self._db = sqlite3.connect(
                    f"{self.path.resolve().as_uri()}?mode=ro",
                    uri=True,
                    timeout=_BUSY_TIMEOUT_S,
                    check_same_thread=False,
                )
            return self._db.execute(self._QUERY, (sha256,)).fetchone() is not None
        except sqlite3.Error:
            return False


class CatalogIndex:
    """The SQLite index of one archive.

    Parameters
    ----------
    path : Path
        ``catalog.sqlite`` in the archive directory. When it cannot be opened for writing (a
        read-only archive), the index lives in memory for this process. A file that is not a
        readable index is replaced by an empty one (the object files are read into it again).
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        self._lock = threading.RLock()
        self.in_memory = False
        try:
            self._db = self._connect(self.path)
        except sqlite3.DatabaseError:
            self._remove_files()
            self._db = self._connect(self.path)
        except OSError:
            self._db = self._connect(":memory:")
            self.in_memory = True

    def _remove_files(self) -> None:
        for suffix in ("", "-wal", "-shm"):
            Path(f"{self.path}{suffix}").unlink(missing_ok=True)

    @staticmethod
    def _connect(target) -> sqlite3.Connection:
        if target != ":memory:" and not os.access(Path(target).parent, os.W_OK):
            raise PermissionError(f"{Path(target).parent} is not writable")
        db = sqlite3.connect(str(target), timeout=_BUSY_TIMEOUT_S, isolation_level=None, check_same_thread=False)
        try:
            db.execute("PRAGMA journal_mode=WAL")
            # The index is rebuilt from the object files whenever it disagrees with them, so a
            # transaction lost to a power cut costs a re-read, never a wrong answer.
            db.execute("PRAGMA synchronous=NORMAL")
            try:
                row = db.execute("SELECT value FROM meta WHERE key = 'version'").fetchone()
            except sqlite3.OperationalError:  # a new index: no tables yet
                row = None
            if row is None or int(row[0]) != INDEX_VERSION:
                db.executescript(_SCHEMA)
                db.executescript("DELETE FROM objects; DELETE FROM passes; DELETE FROM results; DELETE FROM sources;")
                db.execute("INSERT OR REPLACE INTO meta VALUES ('version', ?)", (str(INDEX_VERSION),))
            elif db.execute("SELECT count(*) FROM sqlite_master WHERE type = 'index'").fetchone()[0] < _N_INDEXES:
                db.executescript(_SCHEMA)  # indexes added since the file was made
        except sqlite3.DatabaseError:
            db.close()
            raise
        return db

    @contextmanager
    def guarded(self):
        """Hold the lock; turn SQLite's errors into one-sentence ones callers already handle."""
        with self._lock:
            try:
                yield self._db
            except sqlite3.OperationalError as exc:
                if "locked" in str(exc) or "busy" in str(exc):
                    raise TimeoutError(
                        f"the catalog index {self.path} stayed locked by another process for {_BUSY_TIMEOUT_S:g} s; "
                        "try again when the other ingest or fit has finished"
                    ) from None
                raise DamagedIndexError(self._damaged(exc)) from None
            except sqlite3.DatabaseError as exc:
                raise DamagedIndexError(self._damaged(exc)) from None

    def _damaged(self, exc: Exception) -> str:
        archive = self.path.parent
        return (
            f"the catalog index {self.path} cannot be read ({exc}); it is derived from the object files: "
            f"run 'rsodb check --archive {archive}' to rebuild it"
        )

    def close(self) -> None:
        with self._lock:
            self._db.close()

    # -- writing --------------------------------------------------------------------------------
    def replace_objects(self, entries: Iterable[tuple]) -> None:
        """Record the current content of objects in one transaction.

        Parameters
        ----------
        entries : iterable of (ObjectState, name, cospar, passes, results, duplicates[, before[, changed]])
            Per object: the file's identity, the object's name and COSPAR id, its catalog rows,
            result summaries and duplicate sources. `results` None means "unchanged": the index
            keeps its result rows if it described the file the commit started from (`before`);
            otherwise it records the object as stale, to be read again from its file. `changed`,
            when given, are the catalog rows that differ from those of `before`: if the index
            described `before`, only they are written (an object of many passes gains one a night);
            `passes` may then be None.
        """
        entries = list({entry[0].norad: entry for entry in entries}.values())  # the last of an object
        if not entries:
            return
        with self.guarded() as connection, _transaction(connection) as db:
            # One statement per table for the whole round (a round commits hundreds of objects;
            # statement by statement, the index cost a millisecond and a half per object).
            norads = [state.norad for state, *_ in entries]
            indexed = {}
            for chunk in _chunks(norads):
                marks = ",".join("?" * len(chunk))
                indexed.update(
                    (row[0], tuple(row[1:]))
                    for row in db.execute(
                        f"SELECT norad, ino, size, mtime_ns FROM objects WHERE status = 'ok' AND norad IN ({marks})",
                        chunk,
                    )
                )
            objects, pass_rows, result_rows, source_rows, keep, drop = [], [], [], [], [], []
            delta, replaced_ids, drop_results = [], [], []  # objects whose unchanged pass rows stay; the rows that go
            for state, name, cospar, passes, results, duplicates, *extra in entries:
                previous = extra[0] if extra else None
                changed = extra[1] if len(extra) > 1 else None
                described = previous is not None and indexed.get(state.norad) == (
                    previous.ino,
                    previous.size,
                    previous.mtime_ns,
                )
                # Without its rows (None) or results, an object the index did not describe is stale.
                stale = (results is None or passes is None) and not described
                if described and changed is not None:
                    delta.append(state.norad)
                    if results is not None:
                        drop_results.append(state.norad)
                    replaced_ids += [row.pass_id for row in changed]
                    pass_rows += [_pass_values(row) for row in changed]
                else:
                    (keep if results is None and not stale else drop).append(state.norad)
                    pass_rows += [_pass_values(row) for row in passes or ()]
                # -1 never matches a file: a stale object is read again from its file.
                ino = -1 if stale else state.ino
                objects.append((state.norad, ino, state.size, state.mtime_ns, state.status, state.error, name, cospar))
                result_rows += [
                    (
                        item.pass_id,
                        state.norad,
                        item.kind,
                        item.name,
                        item.stored_utc,
                        item.result_type,
                        item.period_s,
                        item.period_err_s,
                        item.verdict,
                    )
                    for item in results or ()
                ]
                source_rows += [
                    (item.sha256, state.norad, item.source_name, item.pass_id, item.ingested_utc, item.note)
                    for item in duplicates
                ]
            self._delete_many(db, keep, keep_results=True)
            self._delete_many(db, drop)
            for chunk in _chunks(delta):
                marks = ",".join("?" * len(chunk))
                db.execute(f"DELETE FROM objects WHERE norad IN ({marks})", chunk)
                db.execute(f"DELETE FROM sources WHERE norad IN ({marks})", chunk)
            for chunk in _chunks(drop_results):
                db.execute(f"DELETE FROM results WHERE norad IN ({','.join('?' * len(chunk))})", chunk)
            for chunk in _chunks(replaced_ids):
                db.execute(f"DELETE FROM passes WHERE pass_id IN ({','.join('?' * len(chunk))})", chunk)
            db.executemany("INSERT INTO objects VALUES (?, ?, ?, ?, ?, ?, ?, ?)", objects)
            db.executemany(_INSERT_PASS, pass_rows)
            db.executemany("INSERT OR REPLACE INTO results VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)", result_rows)
            db.executemany("INSERT INTO sources VALUES (?, ?, ?, ?, ?, ?)", source_rows)

    def mark_damaged(self, state: ObjectState) -> None:
        """Record that an object's file cannot be read: its passes leave the index."""
        with self.guarded() as connection, _transaction(connection) as db:
            self._delete(db, state.norad)
            db.execute(
                "INSERT INTO objects VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (state.norad, state.ino, state.size, state.mtime_ns, "damaged", state.error, "", ""),
            )

    def remove_objects(self, norads: Iterable[int]) -> None:
        """Forget objects whose files are gone."""
        with self.guarded() as connection, _transaction(connection) as db:
            for norad in norads:
                self._delete(db, int(norad))

    @staticmethod
    def _delete(db: sqlite3.Connection, norad: int, keep_results: bool = False) -> None:
        CatalogIndex._delete_many(db, [norad], keep_results)

    @staticmethod
    def _delete_many(db: sqlite3.Connection, norads: list[int], keep_results: bool = False) -> None:
        for chunk in _chunks(norads):
            marks = ",".join("?" * len(chunk))
            for table in (
                ("objects", "passes", "sources") if keep_results else ("objects", "passes", "results", "sources")
            ):
                db.execute(f"DELETE FROM {table} WHERE norad IN ({marks})", chunk)

    def clear(self) -> None:
        """Forget everything (before a rebuild); a damaged index file is replaced by a new one."""
        try:
            with self.guarded() as connection, _transaction(connection) as db:
                for table in ("objects", "passes", "results", "sources"):
                    db.execute(f"DELETE FROM {table}")
                db.execute("DELETE FROM meta WHERE key = 'swept_dir'")
        except DamagedIndexError:
            with self._lock:
                self._db.close()
                self._remove_files()
                self._db = self._connect(self.path)

    # -- freshness ------------------------------------------------------------------------------
    def states(self, norads: Iterable[int] | None = None) -> dict[int, ObjectState]:
        """The recorded identity of every object (or of `norads`)."""
        query = "SELECT norad, ino, size, mtime_ns, status, error FROM objects"
        with self.guarded():
            if norads is None:
                rows = self._db.execute(query).fetchall()
            else:
                rows = [
                    row
                    for norad in norads
                    for row in self._db.execute(query + " WHERE norad = ?", (int(norad),)).fetchall()
                ]
        return {row[0]: ObjectState(*row[:4], row[4], row[5] or "") for row in rows}

    def directory_unchanged(self, stat: os.stat_result) -> bool:
        """True when the objects directory is as it was at the last complete sweep."""
        with self.guarded():
            row = self._db.execute("SELECT value FROM meta WHERE key = 'swept_dir'").fetchone()
        return row is not None and row[0] == f"{stat.st_ino}:{stat.st_mtime_ns}"

    def remember_sweep(self, stat: os.stat_result) -> None:
        """Note that every object file of the directory in `stat` was found indexed and current."""
        if time.time_ns() - stat.st_mtime_ns < _SETTLED_NS:
            return  # it may still change within the same clock tick
        with self.guarded():
            self._db.execute(
                "INSERT OR REPLACE INTO meta VALUES ('swept_dir', ?)", (f"{stat.st_ino}:{stat.st_mtime_ns}",)
            )

    # -- queries --------------------------------------------------------------------------------
    def _select(self, query: PassQuery, columns: str, order: bool = True) -> tuple[str, list]:
        where, params = query.where()
        # With a period or verdict filter only passes with a result qualify: an inner join lets
        # SQLite start from the results' (kind, name, verdict, period) index instead of every pass.
        filtered = query.period_min_s is not None or query.period_max_s is not None or query.verdict is not None
        sql = (
            f"SELECT {columns} FROM passes p {'JOIN' if filtered else 'LEFT JOIN'} results r "
            "ON r.pass_id = p.pass_id AND r.kind = 'periods' AND r.name = ? "
            f"WHERE {where}" + (" ORDER BY p.start_utc, p.pass_id" if order else "")
        )
        return sql, [query.periods_name, *params]

    def passes(self, query: PassQuery) -> Iterator[PassSummary]:
        """The passes `query` selects, by start time, one at a time."""
        columns = ", ".join(f"p.{name}" for name in _PASS_COLUMNS) + ", r.period_s, r.period_err_s, r.verdict"
        sql, params = self._select(query, columns)
        with self.guarded():
            cursor = self._db.execute(sql, params)
            rows = cursor.fetchmany(512)
        while rows:
            yield from map(_summary, rows)
            with self.guarded():
                rows = cursor.fetchmany(512)

    def count(self, query: PassQuery) -> int:
        """How many passes `query` selects."""
        sql, params = self._select(query, "count(*)", order=False)
        with self.guarded():
            return int(self._db.execute(sql, params).fetchone()[0])

    def widths(self, query: PassQuery) -> dict[str, int]:
        """The longest pass id, name and site among the passes `query` selects (for tables)."""
        sql, params = self._select(
            query, "max(length(p.pass_id)), max(length(p.name)), max(length(p.site)), max(length(p.band))", order=False
        )
        with self.guarded():
            row = self._db.execute(sql, params).fetchone()
        return dict(zip(("pass_id", "name", "site", "band"), (value or 0 for value in row)))

    def frame_sql(self, query: PassQuery) -> tuple[str, list]:
        """SQL and parameters giving the passes `query` selects with every catalog column."""
        columns = (
            ", ".join(f"p.{name}" for name in _PASS_COLUMNS if name != "natural_id")
            + ", r.period_s, r.period_err_s, r.verdict"
        )
        return self._select(query, columns)

    def holds_sources(self) -> bool:
        """Whether any file is stored (a pass or a duplicate source)."""
        with self.guarded():
            row = self._db.execute("SELECT EXISTS (SELECT 1 FROM passes) OR EXISTS (SELECT 1 FROM sources)").fetchone()
        return bool(row[0])

    def holders(self, sha256: str) -> list[int]:
        """The objects the index says store a file with this hash (as a pass's source or a duplicate)."""
        with self.guarded():
            rows = self._db.execute(
                "SELECT norad FROM passes WHERE source_sha256 = ?1 UNION SELECT norad FROM sources WHERE sha256 = ?1",
                (sha256,),
            ).fetchall()
        return [row[0] for row in rows]

    def known_sha256(self) -> set[str]:
        """Content hashes of every stored file, passes and duplicate sources alike."""
        with self.guarded():
            rows = self._db.execute("SELECT source_sha256 FROM passes UNION SELECT sha256 FROM sources").fetchall()
        return {row[0] for row in rows}

    def results(self, pass_id: str) -> list[ResultSummary]:
        """The stored results of one pass."""
        with self.guarded():
            rows = self._db.execute(
                "SELECT pass_id, kind, name, stored_utc, result_type, period_s, period_err_s, verdict "
                "FROM results WHERE pass_id = ? ORDER BY kind, name",
                (pass_id,),
            ).fetchall()
        return [ResultSummary(*row) for row in rows]

    def duplicates(self, pass_id: str) -> list[DuplicateSource]:
        """Files recorded as duplicate sources of one pass."""
        with self.guarded():
            rows = self._db.execute(
                "SELECT sha256, source_name, pass_id, ingested_utc, note FROM sources WHERE pass_id = ?", (pass_id,)
            ).fetchall()
        return [DuplicateSource(*row) for row in rows]

    def damaged(self, norad: int | None = None) -> list[DamagedObject]:
        """Objects whose files could not be read when last looked at."""
        sql = "SELECT norad, error FROM objects WHERE status = 'damaged'"
        with self.guarded():
            rows = (
                self._db.execute(sql + " AND norad = ?", (int(norad),)).fetchall()
                if norad is not None
                else self._db.execute(sql + " ORDER BY norad").fetchall()
            )
        return [DamagedObject(row[0], "", row[1] or "") for row in rows]

    def objects(self) -> list[tuple]:
        """Per object in the index: norad, name, cospar and its current passes' count, bands,
        first and last start (ns)."""
        with self.guarded():
            return self._db.execute(
                "SELECT o.norad, o.name, o.cospar, count(p.pass_id), group_concat(DISTINCT p.band), "
                "min(p.start_utc), max(p.start_utc), "
                "(SELECT count(*) FROM passes q WHERE q.norad = o.norad) "
                "FROM objects o JOIN passes p ON p.norad = o.norad "
                "WHERE o.status = 'ok' AND (p.superseded_by IS NULL OR p.superseded_by = '') "
                "GROUP BY o.norad ORDER BY o.norad"
            ).fetchall()


def _pass_values(row: PassSummary) -> tuple:
    values = []
    for name in _PASS_COLUMNS:
        value = getattr(row, name)
        if name in ("start_utc", "end_utc"):
            value = int(np.datetime64(value, "ns").astype(np.int64))
        elif name in ("supersedes", "superseded_by"):
            value = value or None
        values.append(value)
        if name == "site":
            values.append(row.site.strip().lower())
    return tuple(values)


class _transaction:
    """``BEGIN IMMEDIATE`` .. ``COMMIT`` (or ``ROLLBACK`` on an error) on an autocommit connection."""

    def __init__(self, db: sqlite3.Connection):
        self.db = db

    def __enter__(self) -> sqlite3.Connection:
        self.db.execute("BEGIN IMMEDIATE")
        return self.db

    def __exit__(self, kind, value, traceback) -> None:
        self.db.execute("COMMIT" if kind is None else "ROLLBACK")
