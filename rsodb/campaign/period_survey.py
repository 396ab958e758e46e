"""Period survey of an archive: every pass through `rsodb.periods.analyse_pass`, in parallel.

Workers (a ``spawn`` process pool, `rsodb.pool`) each open the archive read-only, read their
pass, compute its geometry from the pass's elements and find its period; the main process
stores the results as they arrive, in batches (``archive.store_results``, one atomic commit
per object, at most `STORE_EVERY` results or `STORE_EVERY_S` seconds apart, and whatever is
pending when the survey stops or is interrupted), so an interrupted survey keeps what it
finished. A pass that fails is reported with its error and does not stop the others.

A pass whose stored result (under the same name) was found from the same inputs (the pass's
content hash, orbital elements included, the settings, the geometry switch and the method: the
result's ``input_sha256``) is not searched again: its stored result is reported (``force=True``
searches every pass). Re-running a survey after a night's ingest searches only the new passes.

>>> from rsodb.archive import Archive                                   # doctest: +SKIP
>>> survey = survey_periods(Archive("archive"), norad=22076)            # doctest: +SKIP
>>> [r.summary() for r in survey.results]                               # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import hashlib
import json
import time

from rsodb.archive import Archive, DamagedObjectError
from rsodb.periods.result import DEFAULT_RESULT_NAME, METHOD, PeriodResult, PeriodSettings
from rsodb.pool import default_processes, imap_in_pool

__all__ = ["survey_periods", "PeriodSurvey", "load_period_results", "input_sha256"]

# Results held before a batched store (each store rewrites the object's file once).
STORE_EVERY = 200
STORE_EVERY_S = 30.0
# A spawned worker takes ~3 s to import the search (numpy, scipy, skyfield) and a pass takes
# ~1 s: by default each worker gets at least this many passes, so a handful run in this process
# (3 TOPEX passes: 3.0 s here against 7.3 s through a two-worker pool).
PASSES_PER_WORKER = 8


@dataclass(frozen=True)
class PeriodSurvey:
    """What a survey found.

    Attributes
    ----------
    results : tuple of PeriodResult
        One per pass that was analysed, sorted by pass start.
    failures : tuple of (str, str)
        ``(pass_id, error)`` for the passes that could not be analysed.
    stored_as : str or None
        The result name used in the archive, None when nothing was stored.
    reused : tuple of str
        The passes whose stored result was found from the same inputs, reported without a search.
    """

    results: tuple[PeriodResult, ...]
    failures: tuple[tuple[str, str], ...]
    stored_as: str | None
    reused: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return not self.failures

    def to_dict(self) -> dict:
        return {
            "results": [result.to_dict() for result in self.results],
            "failures": [{"pass_id": pass_id, "error": error} for pass_id, error in self.failures],
            "stored_as": self.stored_as,
            "reused": list(self.reused),
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, ensure_ascii=False)


_OPEN_ARCHIVES: dict = {}


def _analyse_stored(task: tuple) -> tuple[str, PeriodResult | None, str]:
    """Worker: (archive path, pass id, settings dict, geometry flag) -> (pass id, result, error)."""
    path, pass_id, settings, geometry = task
    try:
        archive = _OPEN_ARCHIVES.get(path)
        if archive is None:
            archive = _OPEN_ARCHIVES[path] = Archive(path, create=False)
        # The search (astropy, scipy) is imported only where a pass is searched.
        from rsodb.periods.analysis import analyse_pass

        result = analyse_pass(archive.get(pass_id), PeriodSettings.from_dict(settings), geometry=geometry)
        return pass_id, result, ""
    except Exception as error:  # noqa: BLE001 - one bad pass is reported, the survey goes on
        return pass_id, None, f"{type(error).__name__}: {error}"


def survey_periods(
    archive,
    norad: int | None = None,
    *,
    band: str | None = None,
    settings: PeriodSettings | None = None,
    name: str = DEFAULT_RESULT_NAME,
    processes: int | None = None,
    progress: bool = True,
    store: bool = True,
    geometry: bool = True,
    force: bool = False,
) -> PeriodSurvey:
    """Find the period of every current pass of an archive (or of one object).

    Parameters
    ----------
    archive : rsodb.archive.Archive
    norad : int, optional
        Only this object.
    band : str, optional
        Only this band.
    settings : PeriodSettings, optional
    name : str
        Name under which results are stored (``"default"``); storing again replaces them.
    processes : int, optional
        Worker processes (default: the usable cores, at most one per `PASSES_PER_WORKER` passes;
        1 = in this process).
    progress : bool
        Show a progress bar.
    store : bool
        Store each result in the archive as it arrives.
    geometry : bool
        Compute each pass's geometry for the synodic-to-sidereal correction.
    force : bool
        Search every pass, even those whose stored result was found from the same inputs.

    Returns
    -------
    PeriodSurvey
    """
    settings = settings or PeriodSettings()
    rows = archive.summaries(norad, band)
    inputs = _input_hashes(archive, rows, settings, geometry)
    reused = [] if force else _stored_results(archive, rows, name, inputs)
    done = {result.pass_id for result in reused}
    tasks = [(str(archive.path), row.pass_id, settings.to_dict(), geometry) for row in rows if row.pass_id not in done]
    if processes is None:
        processes = max(1, min(default_processes(), len(tasks) // PASSES_PER_WORKER))
    results, failures, unstored = [], [], []
    last_store_s = time.monotonic()
    try:
        for pass_id, result, error in imap_in_pool(
            _analyse_stored, tasks, processes=processes, progress=progress, description="periods", chunksize=1
        ):
            if result is None:
                failures.append((pass_id, error))
                continue
            if inputs.get(pass_id):
                result = replace(result, input_sha256=inputs[pass_id])
            results.append(result)
            if store:
                unstored.append((pass_id, "periods", name, result))
            # Each commit rewrites the object's file: store in batches, but never hold more than
            # STORE_EVERY results or STORE_EVERY_S seconds of work that a crash would lose.
            if len(unstored) >= STORE_EVERY or (unstored and time.monotonic() - last_store_s > STORE_EVERY_S):
                archive.store_results(unstored)
                unstored, last_store_s = [], time.monotonic()
    finally:
        if unstored:
            archive.store_results(unstored)
    order = {row.pass_id: i for i, row in enumerate(rows)}
    results = sorted([*results, *reused], key=lambda r: order[r.pass_id])
    failures.sort(key=lambda f: order[f[0]])
    return PeriodSurvey(
        tuple(results), tuple(failures), name if store else None, tuple(result.pass_id for result in reused)
    )


def input_sha256(content_sha256: str, settings: PeriodSettings, geometry: bool) -> str:
    """What a period result is found from, as one hash: the pass's content hash (samples and
    metadata, orbital elements included), the settings, the geometry switch and the method."""
    record = json.dumps([content_sha256, settings.to_dict(), bool(geometry), METHOD], sort_keys=True)
    return hashlib.sha256(record.encode()).hexdigest()


def _input_hashes(archive, rows, settings: PeriodSettings, geometry: bool) -> dict[str, str]:
    """pass id -> `input_sha256` of each pass (absent for a pass of a damaged object file)."""
    content = {}
    for norad in sorted({row.norad for row in rows}):
        try:
            content.update(archive.content_hashes(norad))
        except DamagedObjectError:
            continue  # its passes are searched, and fail there with the error named
    return {
        row.pass_id: input_sha256(content[row.pass_id], settings, geometry) for row in rows if row.pass_id in content
    }


def _stored_results(archive, rows, name: str, inputs: dict[str, str]) -> list[PeriodResult]:
    """The stored results named `name` found from the inputs the passes have now."""
    found = []
    for row in rows:
        if not inputs.get(row.pass_id) or name not in archive.result_names(row.pass_id, "periods"):
            continue
        try:
            result = archive.load_result(row.pass_id, "periods", name, PeriodResult.from_hdf5)
        except (ValueError, KeyError, OSError):
            continue  # another kind of result under this name, or damaged: searched again
        if result.input_sha256 == inputs[row.pass_id]:
            found.append(result)
    return found


def load_period_results(
    archive, norad: int | None = None, name: str = DEFAULT_RESULT_NAME, band: str | None = None
) -> list[PeriodResult]:
    """The stored period results of an archive's passes (passes without one are skipped), by start time."""
    results = []
    for row in archive.summaries(norad, band):
        if name in archive.result_names(row.pass_id, "periods"):
            results.append(archive.load_result(row.pass_id, "periods", name, PeriodResult.from_hdf5))
    return results
