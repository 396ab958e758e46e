"""Fit a pass: select the data, build the posterior, sample, summarise, store.

``fit_pass(archive, pass_id, config)`` is the whole job for one stored pass: it reads the pass
and its stored period, runs the sampler with the chain at ``archive.chain_path(pass_id,
config.name)`` (so a killed fit resumes when run again), and stores the `FitResult` with
``archive.store_result(pass_id, "fits", config.name, result)``. Shape caches are kept beside the
archive (`shape_store_for`), built by the first fit that needs one.

The pieces are separate for campaigns, where workers compute and the client stores:
`FitProblem.build` (data + posterior, no archive), `fit_problem` (sample + summarise).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from raycast.geometry.pass_geometry import MAX_SUBSAMPLE_TURN_DEG, choose_n_sub
from rsodb.fit.config import FitConfig
from rsodb.fit.conventions import PERIODOGRAM_DRAWS, periodogram_period, spin_periods
from rsodb.fit.curves import geometry_at, pass_curves
from rsodb.fit.likelihood import make_likelihood
from rsodb.fit.model import SpinStateModel
from rsodb.fit.posterior import Posterior
from rsodb.fit.result import FitResult, best_and_draws
from rsodb.fit.sampler import run_sampler
from rsodb.fit.selection import Selection, select_samples
from rsodb.fit.shape_store import ShapeStore
from rsodb.fit.shapes import MATERIAL_PARAMETERS, Shape, brightness_for, cache_grid_size, resolve_shape
from rsodb.fit.subsampling import SUB_SAMPLE_DRAWS, sub_samples_needed
from rsodb.periods.result import PeriodResult

__all__ = [
    "FitProblem",
    "fit_problem",
    "fit_pass",
    "load_periods",
    "reference_range_km",
    "shape_store_for",
    "spin_period_bounds",
    "SEARCH_BIN_TURN_DEG",
]

# Where the stored period lives (written by `rsodb periods`).
PERIODS_RESULT_NAME = "default"
# The global search may bin samples more coarsely than the fit: it only has to find the mode.
SEARCH_BIN_TURN_DEG = 30.0
# Posterior draws behind the spin period's conventions.
CONVENTION_DRAWS = 200


def reference_range_km(observed) -> float | None:
    """1000 km when the pass's magnitudes are reduced to 1000 km range, else None (true range)."""
    return 1000.0 if "reduced to 1000 km" in (observed.mag_convention or "") else None


def shape_store_for(archive) -> ShapeStore:
    """The shape caches of an archive: ``<archive>/shapes/``."""
    return ShapeStore(Path(archive.path) / "shapes")


def spin_period_bounds(space) -> tuple[float, float]:
    """(fastest, slowest) spin period a parameter space allows (its prior's support, or the fixed value)."""
    if "spin_period_s" in space.fixed:
        value = abs(space.fixed["spin_period_s"])
        return value, value
    low, high = next(p.prior.bounds for p in space.free if p.name == "spin_period_s")
    return abs(low), abs(high)


def planned_frame_evaluations(config: FitConfig, observed, selection: Selection, bounds) -> int:
    """Walkers x steps x the frames of one evaluation (samples x exposure sub-samples, as
    `geometry_at` will choose them): the work a shape cache's grid is chosen for."""
    n_sub = config.model.n_sub or choose_n_sub(selection.exposure_s(observed), bounds[0])
    return config.sampler.n_walkers * config.sampler.n_steps * selection.n * n_sub


def measured_sub_samples(posterior_on, selection, exposure_s: float, space, fastest_s: float, config: FitConfig):
    """(posterior, turn per sub-sample in deg, in words): the posterior on `selection` with the
    fewest exposure sub-samples at which the model's curve over the fit's samples, at a few prior
    draws, moves by less than ``config.model.sub_tolerance_mag`` RMS when they double
    (`sub_samples_needed`); at most the 2 deg rule's count."""
    limit = choose_n_sub(exposure_s, fastest_s)
    thetas = space.sample_prior(np.random.default_rng(config.sampler.seed), SUB_SAMPLE_DRAWS)
    built = {}  # the posteriors measured, by count: the chosen one is the fit's

    def curves_at(count: int) -> np.ndarray:
        built[count] = posterior_on(selection, count)
        return np.array([built[count].magnitudes(theta) for theta in thetas])

    count, change = sub_samples_needed(curves_at, limit, config.model.sub_tolerance_mag)
    counted = f"{count} exposure sub-sample{'' if count == 1 else 's'}"
    if exposure_s <= 0 or count >= limit:
        return built[count], MAX_SUBSAMPLE_TURN_DEG, f"{counted} (the 2 deg rule's count, the most it takes)"
    turn_deg = 360.0 * exposure_s / (fastest_s * count)
    return (
        built[count],
        turn_deg,
        f"{counted} ({turn_deg:.3g} deg of turn each: {change:.3f} mag RMS from twice as many)",
    )


@dataclass(frozen=True, eq=False)
class FitProblem:
    """A posterior ready to sample, with what is needed to summarise and store its result.

    Attributes
    ----------
    pass_id : str
    config : FitConfig
    shape : str
        The shape actually used (``auto`` resolved; ``mesh:NAME`` for a mesh file).
    posterior : Posterior
    time_utc : (m,) datetime64[ns]
        The likelihood's samples (bin mid-times when binned).
    search_posterior : Posterior
        The same posterior on at most ``config.sampler.search_points`` samples (bins and
        contiguous windows, never a stride) with one exposure sub-sample, for the global
        search that starts the walkers.
    observed : Pass
    selection : Selection
    epoch_utc : datetime64[ns]
        Reference epoch of the phases: the fitted window's mid-time.
    search_selection : str
        What the search saw, in words.
    sub_turn_deg : float
        The body's largest turn per exposure sub-sample when ``[model] n_sub`` is 0: 2 deg, or
        what the model's own curve was measured to need (``sub_tolerance_mag``).
    sub_samples : str
        The measured sub-sampling, in words (empty when not measured).
    """

    pass_id: str
    config: FitConfig
    shape: str
    posterior: Posterior
    time_utc: np.ndarray
    search_posterior: Posterior
    observed: object = None
    selection: Selection | None = None
    epoch_utc: np.datetime64 | None = None
    search_selection: str = ""
    sub_turn_deg: float = MAX_SUBSAMPLE_TURN_DEG
    sub_samples: str = ""

    @classmethod
    def build(
        cls,
        observed,
        config: FitConfig,
        periods=None,
        *,
        progress: bool = False,
        store: ShapeStore | None = None,
        shape: tuple[str, Shape] | None = None,
    ) -> FitProblem:
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
        store : ShapeStore, optional
            Where shape caches are kept (default: this process's memory).
        shape : (name, Shape), optional
            Overrides the configuration's shape (e.g. a scene built in code).
        """
        pass_id = getattr(observed, "pass_id", "") or observed.source_name
        shape_name, shape_spec = shape or resolve_shape(config.model, observed.norad)
        # The shape's surface parameters are fixed at their defaults unless freed, except in a fit
        # that rescales every material instead (albedo_scale, roughness).
        scalars = any(name in config.parameters for name in MATERIAL_PARAMETERS)
        surfaces = {} if scalars else shape_spec.surface_defaults
        space = config.parameter_space({**shape_spec.articulations, **surfaces}, periods)
        bounds = spin_period_bounds(space)
        selection = select_samples(observed, config.data, bounds, pass_id)
        brightness_names = set(shape_spec.articulations) | set(MATERIAL_PARAMETERS) | set(shape_spec.surfaces)
        free_bounds = {p.name: p.prior.bounds for p in space.free if p.name in brightness_names}
        fixed = {k: v for k, v in space.fixed.items() if k in brightness_names}
        brightness, brightness_parameters = brightness_for(
            shape_spec,
            free_bounds,
            fixed,
            renderer=config.model.renderer,
            accuracy_mag=config.model.accuracy_mag,
            grid_size=config.model.grid_size
            or cache_grid_size(planned_frame_evaluations(config, observed, selection, bounds)),
            element_size_m=config.model.element_size_m,
            normal_bins_per_step=config.model.normal_bins_per_step,
            progress=progress,
            store=store,
            name=shape_name,
        )
        window_times = observed.time_utc[selection.window]
        epoch_utc = window_times[0] + (window_times[-1] - window_times[0]) // 2

        def posterior_on(chosen: Selection, n_sub: int | None) -> Posterior:
            # The fastest spin the prior allows sets the exposure sub-sampling (2 deg per sub-sample).
            geometry = geometry_at(observed, chosen.time_utc(observed), chosen.exposure_s(observed), n_sub, bounds[0])
            epoch_s = float((epoch_utc - geometry.time_utc[0]) / np.timedelta64(1, "s"))
            model = SpinStateModel(
                geometry,
                brightness,
                config.model.attitude,
                config.model.attitude_settings,
                brightness_parameters,
                observed.band,
                reference_range_km(observed),
                epoch_s,
            )
            mag, err = chosen.magnitudes(observed, config.data.mag_err_floor, point_model=n_sub == 1)
            likelihood = make_likelihood(
                config.likelihood.kind,
                mag,
                err,
                config.likelihood.offset,
                geometry.t_s,
                config.likelihood.correlation_time_s,
                config.likelihood.flux_error,
            )
            return Posterior(space, model, likelihood)

        if config.model.sub_tolerance_mag:
            posterior, sub_turn_deg, sub_samples = measured_sub_samples(
                posterior_on, selection, selection.exposure_s(observed), space, bounds[0], config
            )
        else:
            posterior, sub_turn_deg, sub_samples = (
                posterior_on(selection, config.model.n_sub or None),
                MAX_SUBSAMPLE_TURN_DEG,
                "",
            )
        search_data = replace(
            config.data,
            max_points=config.sampler.search_points,
            bin_turn_deg=max(config.data.bin_turn_deg, SEARCH_BIN_TURN_DEG),
            windows=0,
        )
        try:
            coarse = select_samples(observed, search_data, bounds, pass_id)
        except ValueError:
            # Too few points to cover the phase in contiguous windows: the search sees what the fit sees.
            coarse = selection
        if coarse.n >= selection.n and posterior.model.geometry.n_sub == 1:
            search_posterior = posterior
        else:
            search_posterior = posterior_on(coarse, 1)
        return cls(
            pass_id,
            config,
            shape_name,
            posterior,
            selection.time_utc(observed),
            search_posterior,
            observed,
            selection,
            epoch_utc,
            coarse.description,
            sub_turn_deg,
            sub_samples,
        )

    def curve_n_sub(self) -> int:
        """Exposure sub-samples of the pass-wide curves: the fit's, or chosen for one sample's exposure."""
        if self.config.model.n_sub:
            return self.config.model.n_sub
        fastest = spin_period_bounds(self.posterior.space)[0]
        return choose_n_sub(self.observed.exposure_s, fastest, self.sub_turn_deg)

    def summarise(self, run, periods=None) -> FitResult:
        """The `FitResult` of a sampler run of this problem: residuals over the whole window, the
        model curve and band over the whole pass, the spin period in every convention."""
        config = self.config
        space = self.posterior.space
        best, draws = best_and_draws(
            run, space, config.discard, max(config.band_draws, CONVENTION_DRAWS), config.sampler.seed
        )
        fastest = spin_period_bounds(space)[0]
        pass_curve, model_curve = pass_curves(
            self.posterior,
            self.observed,
            self.selection,
            best,
            draws[: config.band_draws],
            n_sub=self.curve_n_sub(),
            fastest_period_s=fastest,
        )
        window = self.observed.time_utc[self.selection.window]
        periods_record = spin_periods(
            self.posterior.model,
            space,
            draws[:CONVENTION_DRAWS],
            self.observed,
            (window[0], window[-1]),
            config.model.attitude,
            config.model.spin_axis,
            periods,
        )
        # What the stored period search would find in the model's own light curve: the like-with-like comparison.
        periodogram = periodogram_period(
            self.posterior.model,
            space,
            draws[:PERIODOGRAM_DRAWS],
            self.observed,
            self.curve_n_sub(),
            fastest,
            getattr(periods, "settings", None),
        )
        if periodogram is not None:
            periods_record["conventions"]["periodogram"] = periodogram
        record = dict(config.to_dict(), shape=self.shape)
        return FitResult.from_run(
            run,
            self.posterior,
            pass_id=self.pass_id,
            name=config.name,
            time_utc=self.time_utc,
            discard=config.discard,
            config=record,
            pass_curve=pass_curve,
            model_curve=model_curve,
            epoch_utc=np.datetime_as_string(self.epoch_utc, unit="ms"),
            spin_periods=periods_record,
            selection="; ".join(filter(None, (self.selection.description, self.sub_samples))),
        )


def fit_problem(
    problem: FitProblem, chain_path, *, restart: bool = False, progress: bool = True, periods=None
) -> FitResult:
    """Sample a prepared problem (chain at `chain_path`, resumed when present) and summarise it."""
    run = run_sampler(
        problem.posterior,
        problem.config.sampler,
        chain_path,
        restart=restart,
        progress=progress,
        description=f"fit {problem.pass_id}",
        search_posterior=problem.search_posterior,
    )
    return problem.summarise(run, periods)


def load_periods(archive, pass_id: str):
    """The pass's stored `PeriodResult`, or None when it has none."""
    if PERIODS_RESULT_NAME not in archive.result_names(pass_id, "periods"):
        return None
    return archive.load_result(pass_id, "periods", PERIODS_RESULT_NAME, PeriodResult.from_hdf5)


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
    if periods is None:
        periods = load_periods(archive, observed.pass_id)
    problem = FitProblem.build(observed, config, periods, progress=progress, store=shape_store_for(archive))
    result = fit_problem(
        problem, archive.chain_path(observed.pass_id, config.name), restart=restart, progress=progress, periods=periods
    )
    if store:
        archive.store_result(observed.pass_id, "fits", config.name, result)
    return result
