"""A stored fit replayed over its pass: the posterior median and a band of posterior draws.

`predict_fit(archive, pass_id, name)` rebuilds the fit's own forward model (its shape cache comes
from the archive's shape store, its phases from the fit's reference epoch), evaluates it at the
posterior median over every sample of the pass and at fine time steps, and draws a band from the
stored posterior draws, each with its own marginalised offset. ``rsodb render --from-fit`` prints,
plots and animates this.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from rsodb.fit.config import FitConfig
from rsodb.fit.curves import ModelCurve, PassCurve, geometry_at, pass_curves
from rsodb.fit.posterior import Posterior
from rsodb.fit.result import FitResult
from rsodb.fit.runner import FitProblem, load_periods, shape_store_for, spin_period_bounds

__all__ = ["FitPrediction", "predict_fit", "fit_name_of"]


@dataclass(frozen=True, eq=False)
class FitPrediction:
    """A fit's model over its pass.

    Attributes
    ----------
    result : FitResult
        The stored fit.
    values : dict
        The posterior median (and fixed values) the curves are drawn at.
    samples : PassCurve
        Every usable sample with the median model (offset applied).
    curve : ModelCurve
        The median model at fine steps with quantiles over `draws` posterior draws.
    draws : int
    problem : FitProblem
        The rebuilt fit (forward model, selection, epoch).
    """

    result: FitResult
    values: dict
    samples: PassCurve
    curve: ModelCurve
    draws: int
    problem: FitProblem

    @property
    def residual_rms_mag(self) -> float:
        """RMS of observed minus median model over every sample of the fitted window."""
        window = self.samples.in_window
        return float(np.sqrt(np.mean((self.samples.mag_obs - self.samples.mag_model)[window] ** 2)))

    @property
    def scene(self) -> Any:
        """The rendered scene of the fit's shape (None for the analytic bodies)."""
        brightness = self.problem.posterior.model.brightness
        return getattr(getattr(brightness, "renderer", brightness), "scene", None)

    def _attitude_at(self, time_utc=None):
        """(PassGeometry, attitude) of the median state at `time_utc` (default: the samples')."""
        times = self.samples.time_utc if time_utc is None else time_utc
        geometry = geometry_at(self.problem.observed, times, 0.0, 1, None)
        return geometry, self.problem.posterior.model.on(geometry).attitude_model(self.values)

    def body_geometry(self, time_utc=None):
        """`raycast.geometry.BodyGeometry` of the median state at `time_utc` (default: the samples')."""
        geometry, attitude = self._attitude_at(time_utc)
        return geometry, geometry.body_frame(attitude)

    def bisector_body(self) -> tuple[np.ndarray, np.ndarray]:
        """The Sun-observer bisector in body coordinates at every sample, and the spin axis.

        Returns
        -------
        bisector : (n, 3) float
            Unit bisector of the Sun and observer directions, body frame, at the samples' times
            (`samples.time_utc`): where a mirror's normal must point for it to glint.
        spin_direction : (3,) float
            The median state's spin axis in body coordinates (body z for attitudes without one).
        """
        geometry, attitude = self._attitude_at()
        body = geometry.body_frame(attitude)
        spin = np.asarray(getattr(attitude, "spin_direction_body", (0.0, 0.0, 1.0)), dtype=float)
        bisector = body.sun_body[:, 0] + body.obs_body[:, 0]
        return bisector / np.linalg.norm(bisector, axis=1)[:, None], spin / np.linalg.norm(spin)


def fit_name_of(archive, pass_id: str, name: str | None) -> str:
    """`name`, or the pass's only fit (or its fit called "default") when `name` is None."""
    names = archive.result_names(pass_id, "fits")
    if name:
        if name not in names:
            raise LookupError(
                f"pass {pass_id} has no fit called {name!r}; it has {', '.join(names) or 'none'} "
                "(run 'rsodb fit' first, or give PASS:NAME)"
            )
        return name
    if len(names) == 1:
        return names[0]
    if "default" in names:
        return "default"
    raise LookupError(
        f"pass {pass_id} has {'no fits' if not names else 'the fits ' + ', '.join(names)}; "
        + ("run 'rsodb fit' first" if not names else "name one as PASS:NAME")
    )


def predict_fit(archive, pass_id: str, name: str | None = None, *, draws: int = 100, seed: int = 0) -> FitPrediction:
    """Replay a stored fit over its pass.

    Parameters
    ----------
    archive : rsodb.archive.Archive
    pass_id : str
        A pass id or unique prefix.
    name : str, optional
        The fit's name (default: the pass's only fit, or "default").
    draws : int
        Posterior draws behind the band (taken from the stored draws without replacement).
    seed : int
        Which draws.
    """
    observed = archive.get(pass_id)
    name = fit_name_of(archive, observed.pass_id, name)
    result = archive.load_result(observed.pass_id, "fits", name, FitResult.from_hdf5)
    record = {key: value for key, value in result.config.items() if key != "shape"}
    config = FitConfig.from_dict(record)
    problem = FitProblem.build(
        observed, config, load_periods(archive, observed.pass_id), store=shape_store_for(archive)
    )
    if set(problem.posterior.space.names) != set(result.names):
        raise ValueError(
            f"fit {name!r} of {observed.pass_id} has parameters {list(result.names)} but its configuration now "
            f"gives {list(problem.posterior.space.names)}; refit the pass"
        )
    # The stored fit's own space (its priors as they were, its parameters in its order: a model
    # may list them in another order today, and the model takes them by name) reads its stored
    # draws; parameters the model has gained since (fixed at their defaults) come from the
    # configuration's space.
    posterior = problem.posterior
    space = replace(result.space, fixed={**posterior.space.fixed, **result.space.fixed})
    problem = replace(problem, posterior=Posterior(space, posterior.model, posterior.likelihood))
    rng = np.random.default_rng(seed)
    count = min(int(draws), result.samples.shape[0])
    picked = result.samples[rng.choice(result.samples.shape[0], size=count, replace=False)]
    samples, curve = pass_curves(
        problem.posterior,
        observed,
        problem.selection,
        np.array(result.median, dtype=float),
        space.wrap(picked),
        n_sub=problem.curve_n_sub(),
        fastest_period_s=spin_period_bounds(space)[0],
    )
    return FitPrediction(result, result.values("median"), samples, curve, count, problem)
