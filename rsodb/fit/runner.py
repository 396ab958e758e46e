"""Fit a pass: select the data, build the posterior, sample, summarise, store.

``fit_pass(archive, pass_id, config)`` is the whole job for one stored pass: it reads the pass
and its stored period, runs the sampler with the chain at ``archive.chain_path(pass_id,
config.name)`` (so a killed fit resumes when run again), and stores the `FitResult` with
``archive.store_result(pass_id, "fits", config.name, result)``.

The pieces are separate for campaigns, where workers compute and the client stores:
`FitProblem.build` (data + posterior, no archive), `fit_problem` (sample + summarise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from raycast.geometry.pass_geometry import PassGeometry
from rsodb.fit.config import FitConfig
from rsodb.fit.likelihood import make_likelihood
from rsodb.fit.model import SpinStateModel
from rsodb.fit.posterior import Posterior
from rsodb.fit.result import FitResult
from rsodb.fit.sampler import run_sampler
from rsodb.fit.shapes import MATERIAL_PARAMETERS, SHAPES, brightness_for, shape_for_norad
from rsodb.periods.search import PeriodResult

__all__ = ["FitProblem", "select_samples", "fit_problem", "fit_pass", "load_periods", "reference_range_km"]

# Where the stored period lives (written by `rsodb periods`).
PERIODS_RESULT_NAME = "default"


def reference_range_km(observed) -> float | None:
    """1000 km when the pass's magnitudes are reduced to 1000 km range, else None (true range)."""
    return 1000.0 if "reduced to 1000 km" in (observed.mag_convention or "") else None


def select_samples(observed, data) -> np.ndarray:
    """(n,) bool: the samples of `observed` to fit under `data` (a `DataConfig`).

    Valid, finite magnitudes with finite errors, not saturated unless asked, inside the time
    window, every ``stride``-th, then at most ``max_points`` of those, evenly spread.
    """
    mag = observed.best_mag
    keep = observed.valid & np.isfinite(mag) & np.isfinite(observed.mag_err)
    if not data.keep_saturated:
        keep &= ~observed.saturated
    t_s = observed.t_s
    keep &= t_s >= data.start_s
    if data.duration_s > 0:
        keep &= t_s <= data.start_s + data.duration_s
    index = np.flatnonzero(keep)[:: data.stride]
    if data.max_points and index.size > data.max_points:
        index = index[np.unique(np.linspace(0, index.size - 1, data.max_points).round().astype(int))]
    chosen = np.zeros(len(observed), dtype=bool)
    chosen[index] = True
    return chosen


@dataclass(frozen=True, eq=False)
class FitProblem:
    """A posterior ready to sample, with what is needed to store its result.

    Attributes
    ----------
    pass_id : str
    config : FitConfig
    shape : str
        The shape actually used (``auto`` resolved).
    posterior : Posterior
    time_utc : (n,) datetime64[ns]
        The fitted samples.
    search_posterior : Posterior
        The same posterior on at most ``config.sampler.search_points`` samples without
        exposure sub-samples, for the global search that starts the walkers.
    """

    pass_id: str
    config: FitConfig
    shape: str
    posterior: Posterior
    time_utc: np.ndarray
    search_posterior: Posterior

    @classmethod
    def build(cls, observed, config: FitConfig, periods=None, *, progress: bool = False) -> FitProblem:
        """Data selection, geometry, shape, priors and likelihood for one pass.

        Parameters
        ----------
        observed : StoredPass or Pass
            The pass (with a TLE or OMM).
        config : FitConfig
        periods : PeriodResult or None
            The pass's stored period (for the default spin-period prior).
        progress : bool
            Progress bar while a shape cache is built.
        """
        pass_id = getattr(observed, "pass_id", "") or observed.source_name
        chosen = select_samples(observed, config.data)
        n = int(chosen.sum())
        if n < 10:
            raise ValueError(
                f"pass {pass_id}: only {n} usable samples in the chosen window; a fit needs at least 10 "
                "(check [data] start_s/duration_s/stride, or keep_saturated)"
            )
        shape = shape_for_norad(observed.norad) if config.model.shape == "auto" else config.model.shape
        space = config.parameter_space(SHAPES[shape].articulations, periods)
        brightness_names = set(SHAPES[shape].articulations) | set(MATERIAL_PARAMETERS)
        free_bounds = {p.name: p.prior.bounds for p in space.free if p.name in brightness_names}
        fixed = {k: v for k, v in space.fixed.items() if k in brightness_names}
        brightness, brightness_parameters = brightness_for(
            shape,
            free_bounds,
            fixed,
            renderer=config.model.renderer,
            accuracy_mag=config.model.accuracy_mag,
            progress=progress,
        )
        # The fastest spin the prior allows sets the exposure sub-sampling (2 deg per sub-sample).
        period_guess = dict(space.fixed, **{p.name: p.prior.low for p in space.free}).get("spin_period_s")

        def posterior_on(index: np.ndarray, n_sub: int | None) -> Posterior:
            geometry = PassGeometry.from_pass(
                observed, n_sub=n_sub, spin_period_s=period_guess if period_guess else None, samples=index
            )
            model = SpinStateModel(
                geometry,
                brightness,
                config.model.attitude,
                config.model.attitude_settings,
                brightness_parameters,
                observed.band,
                reference_range_km(observed),
            )
            err = np.maximum(observed.mag_err[index], config.data.mag_err_floor)
            likelihood = make_likelihood(
                config.likelihood.kind, observed.best_mag[index], err, config.likelihood.offset
            )
            return Posterior(space, model, likelihood)

        index = np.flatnonzero(chosen)
        posterior = posterior_on(index, config.model.n_sub or None)
        coarse = index[np.unique(np.linspace(0, n - 1, min(n, config.sampler.search_points)).round().astype(int))]
        search_posterior = (
            posterior_on(coarse, 1) if coarse.size < n or posterior.model.geometry.n_sub > 1 else posterior
        )
        return cls(pass_id, config, shape, posterior, observed.time_utc[chosen], search_posterior)


def fit_problem(problem: FitProblem, chain_path, *, restart: bool = False, progress: bool = True) -> FitResult:
    """Sample a prepared problem (chain at `chain_path`, resumed when present) and summarise it."""
    config = problem.config
    run = run_sampler(
        problem.posterior,
        config.sampler,
        chain_path,
        restart=restart,
        progress=progress,
        description=f"fit {problem.pass_id}",
        search_posterior=problem.search_posterior,
    )
    record = dict(config.to_dict(), shape=problem.shape)
    return FitResult.from_run(
        run,
        problem.posterior,
        pass_id=problem.pass_id,
        name=config.name,
        time_utc=problem.time_utc,
        discard=config.discard,
        config=record,
    )


def load_periods(archive, pass_id: str):
    """The pass's stored `PeriodResult`, or None when it has none."""
    if PERIODS_RESULT_NAME not in archive.result_names(pass_id, "periods"):
        return None
    return archive.load_result(pass_id, "periods", PERIODS_RESULT_NAME, PeriodResult.from_hdf5)


def _needs_periods(config: FitConfig) -> bool:
    spec = config.parameter_specs({}).get("spin_period_s")
    return isinstance(spec, dict) and spec.get("from") == "periods"


def fit_pass(
    archive,
    pass_id: str,
    config: FitConfig | None = None,
    *,
    periods: PeriodResult | None = None,
    restart: bool = False,
    progress: bool = True,
    store: bool = True,
) -> FitResult:
    """Fit one stored pass and store the result in the archive.

    Parameters
    ----------
    archive : rsodb.archive.Archive
    pass_id : str
        The pass (a unique prefix is enough).
    config : FitConfig, optional
        Default: `FitConfig()`.
    periods : PeriodResult, optional
        The pass's period, for the spin-period prior; default: the one stored in the archive.
    restart : bool
        Discard a stored chain of this fit instead of resuming it.
    progress : bool
        Progress bars.
    store : bool
        Store the result (``archive.store_result(pass_id, "fits", config.name, result)``).

    Returns
    -------
    FitResult
    """
    config = config or FitConfig()
    observed = archive.get(pass_id)
    if periods is None and _needs_periods(config):
        periods = load_periods(archive, observed.pass_id)
    problem = FitProblem.build(observed, config, periods, progress=progress)
    result = fit_problem(problem, archive.chain_path(observed.pass_id, config.name), restart=restart, progress=progress)
    if store:
        archive.store_result(observed.pass_id, "fits", config.name, result)
    return result
