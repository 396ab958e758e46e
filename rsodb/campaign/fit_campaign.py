"""Campaigns: fit many passes (every pass of an object, or a selection) in parallel on Dask.

`run_campaign` submits one task per pass to a Dask distributed cluster: a `LocalCluster` of
single-threaded worker processes by default, or an existing scheduler given by address (a
real cluster; the archive directory must then be on a file system every worker sees). Each
task is `rsodb.fit.runner.fit_pass` with the sampler kept to one process (the parallelism is
across passes), so the task writes its chain at ``archive.chain_path`` and stores its
`FitResult` in the archive itself, under the archive's per-object lock: a campaign whose client
dies keeps every finished fit. Passes that already have a stored fit of the same name are
skipped, so rerunning a campaign only does what is left (``restart=True`` refits everything).

>>> from rsodb.campaign import run_campaign                       # doctest: +SKIP
>>> outcome = run_campaign("archive", norad=22076)                 # doctest: +SKIP
>>> print(outcome.summary())                                       # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
import time

from tqdm.auto import tqdm

from raycast.geometry.pass_geometry import orbit_problem
from rsodb.archive import Archive
from rsodb.fit.config import FitConfig
from rsodb.fit.runner import fit_pass
from rsodb.pool import default_processes

__all__ = ["CampaignOutcome", "run_campaign", "run_campaigns", "select_passes", "NO_ORBIT"]

# Why a pass without an orbit is not fitted (CampaignOutcome.failed, the reports' index): it has
# no orbital elements and no Az/El/range columns to fit a track to (`raycast.geometry.pass_geometry.orbit_problem`).
NO_ORBIT = (
    "no orbital elements and no Az/El/range columns, so no pass geometry to fit: add elements with "
    "'rsodb elements add TLE_FILE' (or ingest the file with --tle TLE_FILE)"
)


def _has_orbit(archive: Archive, pass_id: str) -> bool:
    """Whether a stored pass has a geometry: elements, or a track of its Az/El/range columns."""
    return bool(archive.summary(pass_id).elements) or not orbit_problem(archive.get(pass_id))


@dataclass(frozen=True)
class CampaignOutcome:
    """What a campaign did.

    Attributes
    ----------
    name : str
        The fit name used.
    fitted : tuple of dict
        ``FitResult.to_dict()`` of every pass fitted in this run.
    skipped : tuple of str
        Passes that already had a fit of this name.
    failed : tuple of (str, str)
        Pass id and one-line error of every failed fit.
    elapsed_s : float
    scheduler : str
        Address of the scheduler used.
    """

    name: str
    fitted: tuple = ()
    skipped: tuple = ()
    failed: tuple = ()
    elapsed_s: float = 0.0
    scheduler: str = ""

    @property
    def ok(self) -> bool:
        return not self.failed

    def summary(self) -> str:
        """One line of counts."""
        return (
            f"fit {self.name!r}: {len(self.fitted)} fitted, {len(self.skipped)} already done (skipped), "
            f"{len(self.failed)} not fitted (failed, or no orbital elements) in {self.elapsed_s:.0f} s on "
            f"{self.scheduler}"
        )

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "fitted": list(self.fitted),
            "skipped": list(self.skipped),
            "failed": [{"pass_id": p, "error": e} for p, e in self.failed],
            "elapsed_s": self.elapsed_s,
            "scheduler": self.scheduler,
        }


def select_passes(archive, norad: int | None = None, pass_ids=None, band: str | None = None) -> list[str]:
    """Pass ids of a campaign: the given ids (prefixes resolved) or every pass of an object/band."""
    if pass_ids:
        return [archive.get(pass_id).pass_id for pass_id in pass_ids]
    if norad is None:
        raise ValueError("a campaign needs an object (--object NORAD) or a list of passes")
    return [row.pass_id for row in archive.summaries(norad, band)]


def _fit_task(archive_path: str, pass_id: str, config_record: dict) -> dict:
    """One pass, run on a Dask worker; returns the stored result's summary."""
    config = FitConfig.from_dict(config_record)
    result = fit_pass(Archive(archive_path, create=False), pass_id, config, progress=False)
    return result.to_dict()


def _client(scheduler: str | None, n_workers: int | None):
    try:
        # Dask's distributed loads in about a second; only campaigns need it.
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - a declared dependency
        raise ImportError("campaigns need Dask distributed; install the 'dask[distributed]' package") from None
    if scheduler:
        return Client(scheduler, timeout="30s"), None

    cluster = LocalCluster(
        n_workers=n_workers or default_processes(),
        threads_per_worker=1,
        processes=True,
        # A random free port: None does not disable the dashboard (dask/distributed#8136) and
        # warns whenever another cluster holds the default 8787.
        dashboard_address=":0",
        silence_logs=40,
    )
    return Client(cluster), cluster


def run_campaign(
    archive,
    norad: int | None = None,
    *,
    pass_ids=None,
    band: str | None = None,
    config=None,
    scheduler: str | None = None,
    n_workers: int | None = None,
    restart: bool = False,
    progress: bool = True,
) -> CampaignOutcome:
    """Fit every selected pass in parallel on Dask and store the results.

    Parameters
    ----------
    archive : rsodb.archive.Archive or path
    norad : int, optional
        Fit every pass of this object (optionally of one `band`)...
    pass_ids : sequence of str, optional
        ...or these passes.
    band : str, optional
    config : FitConfig, optional
        The fit (default: `FitConfig()`); its sampler runs in one process per task.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); default: a LocalCluster.
    n_workers : int, optional
        LocalCluster workers (default: one per usable core).
    restart : bool
        Refit passes that already have a fit of this name (their chains are discarded).
    progress : bool
        A progress bar over the passes.

    Returns
    -------
    CampaignOutcome
    """
    archive = _open(archive)
    selected = select_passes(archive, norad, pass_ids, band)
    return run_campaigns(
        archive,
        [(config or FitConfig(), selected)],
        scheduler=scheduler,
        n_workers=n_workers,
        restart=restart,
        progress=progress,
    )[0]


def run_campaigns(
    archive,
    groups,
    *,
    scheduler: str | None = None,
    n_workers: int | None = None,
    restart: bool = False,
    progress: bool = True,
) -> list[CampaignOutcome]:
    """Several campaigns at once: each group is a (FitConfig, pass ids) pair.

    Every task goes through one Dask client and one completion loop, so the groups share the
    workers without one waiting for another (the pipeline fits each object with its own
    configuration this way). Arguments as `run_campaign`; one `CampaignOutcome` per group,
    in the order given.
    """
    archive = _open(archive)
    plans = []  # (config, passes to fit, passes already fitted, passes that cannot be fitted)
    for config, pass_ids in groups:
        config = config.replace(sampler={"processes": 1})
        done = [] if restart else [p for p in pass_ids if config.name in archive.result_names(p, "fits")]
        # A pass without an orbit has no geometry: said here, in one line, rather than as a task
        # failing on a worker (whose traceback Dask prints in the client's terminal).
        unfit = [(p, NO_ORBIT) for p in pass_ids if p not in done and not _has_orbit(archive, p)]
        todo = [p for p in pass_ids if p not in done and p not in dict(unfit)]
        if restart:
            for pass_id in todo:
                path = archive.chain_path(pass_id, config.name)
                path.unlink(missing_ok=True)
                path.with_name(path.name + ".bak").unlink(missing_ok=True)
        plans.append((config, todo, done, unfit))
    started = time.perf_counter()
    if not any(todo for _, todo, _, _ in plans):
        return [
            CampaignOutcome(config.name, (), tuple(done), tuple(unfit), 0.0, "nothing to run")
            for config, _, done, unfit in plans
        ]
    # Dask's distributed loads in about a second; only campaigns need it.
    from distributed import as_completed

    client, cluster = _client(scheduler, n_workers)
    fitted = [[] for _ in plans]
    failed = [list(unfit) for _, _, _, unfit in plans]
    finished = [0.0] * len(plans)
    try:
        address = client.scheduler.address
        archive_path = str(Path(archive.path).resolve())
        futures = {}
        for number, (config, todo, _, _) in enumerate(plans):
            record = config.to_dict()
            for pass_id in todo:
                future = client.submit(
                    _fit_task, archive_path, pass_id, record, key=f"fit-{config.name}-{number}-{pass_id}", pure=False
                )
                futures[future] = (number, pass_id)
        names = sorted({config.name for config, _, _, _ in plans})
        with tqdm(total=len(futures), desc=f"campaign {', '.join(names)}", unit="pass", disable=not progress) as bar:
            for future in as_completed(futures):
                number, pass_id = futures[future]
                error = future.exception()
                if error is None:
                    fitted[number].append(future.result())
                else:
                    failed[number].append((pass_id, f"{type(error).__name__}: {error}"))
                finished[number] = time.perf_counter() - started
                bar.update(1)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    outcomes = []
    for (config, _, done, _), results, errors, elapsed in zip(plans, fitted, failed, finished):
        results.sort(key=lambda r: r["start_utc"])
        outcomes.append(CampaignOutcome(config.name, tuple(results), tuple(done), tuple(errors), elapsed, address))
    return outcomes


def _open(archive):
    return archive if isinstance(archive, Archive) else Archive(archive, create=False)
