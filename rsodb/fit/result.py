"""The outcome of a fit: posterior summary, best-fit light curve, diagnostics, chain pointer.

A `FitResult` is what the archive keeps for a pass (``archive.store_result(pass_id, "fits",
name, result)``). It is built from a sampler run with `FitResult.from_run` and written with
`to_hdf5` into an h5py group laid out for plain h5py and pandas:

``attrs``
    ``schema_version``, ``kind = "fit"``, identity (``pass_id``, ``name``), ``likelihood``,
    scalar statistics (``offset_mag``, ``jitter_mag``, ``residual_rms_mag``, ``chi2``,
    ``reduced_chi2``, ``dof``), diagnostics (``n_steps``, ``n_walkers``, ``discard``,
    ``converged``, ``verdict``), ``chain_path``, ``elapsed_s``, ``n_evaluations``,
    ``created_utc``, ``epoch_utc`` (reference epoch of the phases), ``selection`` (what the
    likelihood saw), and JSON strings ``space``, ``config``, ``init``, ``flags``,
    ``spin_periods`` (`rsodb.fit.conventions`).
``summary``
    One row per free parameter: ``name``, ``median``, ``p16``, ``p84``, ``best``,
    ``autocorr_time`` (the paper's Table 1 plus diagnostics).
``lightcurve``
    Per usable sample of the pass: ``time_utc`` (int64 ns since 1970), ``mag_obs``, ``mag_err``,
    ``mag_model`` (best fit, the marginalised offset applied), ``in_window`` (inside the fitted
    window: the residual statistics cover these), ``fitted`` (seen by the likelihood).
``curve``
    The model at fine time steps over the whole pass (`rsodb.fit.curves.ModelCurve`):
    ``time_utc``, ``mag_best``, ``mag_band`` (quantiles over posterior draws, one row per level
    of the ``levels`` attribute).
``samples``
    Up to `MAX_STORED_SAMPLES` posterior draws (after burn-in, thinned evenly), so the
    archive keeps a posterior even if the chain file is removed.
``acceptance_fraction``
    Per walker.

The summary uses circular statistics for wrapped angles (see
`ParameterSpace.wrap_samples`): the median is reduced into the prior window and the 16/84
percentiles are on the same unrolled branch, so ``p16 <= median <= p84`` may exceed the
window by up to half a period.

Schema 1 records (before the window, the curve and the conventions) are read with every stored
sample in the window and fitted, no curve and no conventions.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
import json
import math
from typing import Any

import numpy as np

from rsodb.fit.conventions import comparable_convention
from rsodb.fit.curves import ModelCurve, PassCurve
from rsodb.fit.likelihood import flux_error_of, jitter_of
from rsodb.fit.parameters import ParameterSpace, describe
from rsodb.fit.sampler import CONVERGED_TAUS, autocorr_time
from rsodb.storage import attr_text, to_json

__all__ = [
    "ChainHealth",
    "FitResult",
    "SCHEMA_VERSION",
    "MAX_STORED_SAMPLES",
    "assess_convergence",
    "best_and_draws",
    "chain_verdict",
    "chain_health",
    "first_kept_step",
    "prior_bound_flags",
]

SCHEMA_VERSION = 2
READABLE_SCHEMAS = (1, 2)
MAX_STORED_SAMPLES = 4000
# emcee's guidance: trust autocorrelation times, and the posterior, when the chain is at
# least ~50 of them long: the length the sampler's convergence check stops at.
MIN_AUTOCORR_LENGTHS = CONVERGED_TAUS
# Stretch-move acceptance is healthy in roughly 0.2-0.5; far outside, walkers are stuck or
# the proposal scale is wrong.
ACCEPTANCE_RANGE = (0.15, 0.7)
# A model whose best fit misses the data by more than this many quoted errors (reduced chi2
# with the observed errors alone) is flagged as not describing them.
MISFIT_REDUCED_CHI2 = 2.0
# A parameter "sits at a prior bound" when more than BOUND_SHARE of its kept samples lie within
# BOUND_EDGE of the prior's range from that bound: a posterior spread evenly over the prior puts
# 1% there, one cut off by the bound far more.
BOUND_EDGE, BOUND_SHARE = 0.01, 0.05


def first_kept_step(run, discard: int | None = None) -> int:
    """The first step of a chain run that its summaries keep: `discard` when given, else the
    burn-in its convergence check settled on, else half the chain."""
    if discard is not None:
        return int(discard)
    return run.burn_in if run.burn_in is not None else run.n_steps // 2


def chain_verdict(run, n_kept: int, tau: np.ndarray) -> tuple[bool, str]:
    """(converged, verdict) of a run from its kept steps and their autocorrelation times (`assess_convergence`),
    with why the run stopped."""
    converged, verdict = assess_convergence(n_kept, tau, run.acceptance_fraction)
    return converged, f"{verdict} ({run.stopped})" if run.stopped else verdict


def best_and_draws(run, space, discard: int | None, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(highest-posterior point (ndim,), `count` random draws (count, ndim)) of a chain run.

    Draws come from the kept part (after `discard`, default `first_kept_step`), wrapped angles reduced.
    """
    discard = first_kept_step(run, discard)
    best_index = np.unravel_index(np.argmax(run.log_prob), run.log_prob.shape)
    flat = run.chain[discard:].reshape(-1, space.ndim)
    rng = np.random.default_rng(seed)
    picked = flat[rng.choice(flat.shape[0], size=min(count, flat.shape[0]), replace=False)] if count else flat[:0]
    return space.wrap(run.chain[best_index]), space.wrap(picked)


def prior_bound_flags(space, samples: np.ndarray) -> list[str]:
    """Warnings for the free parameters whose kept samples (n, ndim) pile up at a prior bound
    (`BOUND_EDGE`, `BOUND_SHARE`) that is a choice, not the quantity's own limit (a jitter of 0,
    a cone of 0 deg: `Known.limits`): there the prior, not the data, ends the interval, and
    walkers pressed against it accept few proposals. Wrapped angles have no bound."""
    flags = []
    samples = np.asarray(samples, dtype=float)
    for k, parameter in enumerate(space.free):
        known = describe(parameter.name)
        if known.period is not None:
            continue
        low, high = parameter.prior.bounds
        edge = BOUND_EDGE * (high - low)
        for side, bound, share, physical in (
            ("lower", low, np.mean(samples[:, k] <= low + edge), low <= known.limits[0]),
            ("upper", high, np.mean(samples[:, k] >= high - edge), high >= known.limits[1]),
        ):
            if share > BOUND_SHARE and not physical:
                flags.append(
                    f"at a prior bound: {parameter.name} piles at its prior's {side} bound {bound:g} "
                    f"({100 * share:.0f}% of the kept samples within {100 * BOUND_EDGE:g}% of the prior's range of it): the "
                    "prior, not the data, ends this interval; widen it if the object allows"
                )
    return flags


@dataclass(frozen=True)
class ChainHealth:
    """What the convergence verdict rests on (:func:`chain_health`).

    Attributes
    ----------
    lengths : float
        Kept steps / the longest autocorrelation time.
    tau : float
        The longest autocorrelation time, steps.
    mean_acceptance : float
    stuck : int
        Walkers that accepted under 5% of their proposals.
    """

    lengths: float
    tau: float
    mean_acceptance: float
    stuck: int

    @property
    def too_short(self) -> bool:
        return self.lengths < MIN_AUTOCORR_LENGTHS

    @property
    def mixing_problems(self) -> tuple[str, ...]:
        """The walkers' problems other than the chain's length, in words."""
        problems = []
        low, high = ACCEPTANCE_RANGE
        if not low <= self.mean_acceptance <= high:
            problems.append(f"mean acceptance {self.mean_acceptance:.2f} is outside {low}-{high}")
        if self.stuck:
            problems.append(f"{self.stuck} walker(s) accepted under 5% of proposals (stuck)")
        return tuple(problems)


def chain_health(n_kept: int, autocorr_time: np.ndarray, acceptance: np.ndarray) -> ChainHealth:
    """The kept chain's length in autocorrelation times and its walkers' acceptance.

    Parameters
    ----------
    n_kept : int
        Steps kept after burn-in.
    autocorr_time : (ndim,) float
        Integrated autocorrelation time per parameter, steps.
    acceptance : (n_walkers,) float
        Acceptance fraction per walker.
    """
    autocorr_time = np.asarray(autocorr_time, dtype=float)
    acceptance = np.asarray(acceptance, dtype=float)
    tau = float(np.nanmax(autocorr_time)) if np.any(np.isfinite(autocorr_time)) else math.inf
    lengths = n_kept / tau if tau > 0 else math.inf
    return ChainHealth(lengths, tau, float(np.mean(acceptance)), int(np.sum(acceptance < 0.05)))


def assess_convergence(n_kept: int, autocorr_time: np.ndarray, acceptance: np.ndarray) -> tuple[bool, str]:
    """(converged, one-line verdict) from the kept chain length, tau per parameter and acceptance
    (:func:`chain_health`)."""
    check = chain_health(n_kept, autocorr_time, acceptance)
    lengths, tau = check.lengths, check.tau
    problems = list(check.mixing_problems)
    if check.too_short:
        problems.insert(
            0,
            f"the kept chain is only {lengths:.1f} autocorrelation times long "
            f"({MIN_AUTOCORR_LENGTHS} wanted; tau = {tau:.0f} steps)",
        )
        return False, "not converged: " + "; ".join(problems) + ". Run more steps (a rerun resumes the chain)."
    if problems:
        # Long enough, but the walkers move badly: more steps will not change that.
        return False, (
            f"not converged: the kept chain is {lengths:.0f} autocorrelation times long (tau = {tau:.0f} steps), "
            f"but {'; '.join(problems)}: walkers pressed against a prior bound or split between modes "
            "(see the trace plot); more steps will not change it"
        )
    return True, (
        f"converged: the kept chain is {lengths:.0f} autocorrelation times long (tau = {tau:.0f} steps), "
        f"mean acceptance {check.mean_acceptance:.2f}"
    )


@dataclass(frozen=True, eq=False)
class FitResult:
    """Posterior summary and best fit of one spin-state fit of one pass.

    Attributes
    ----------
    pass_id, name : str
        The pass and the fit's name in the archive.
    space : ParameterSpace
        Free parameters (with priors) and fixed values.
    likelihood : str
        ``"gaussian"`` or ``"normalised"``.
    median, p16, p84, best : (ndim,) float
        Posterior median, 16th and 84th percentiles, and the highest-posterior sample.
    best_log_prob : float
    autocorr_time : (ndim,) float
        Per parameter, steps, measured on the kept part of the chain.
    acceptance_fraction : (n_walkers,) float
    n_steps, n_walkers, discard : int
        Chain length, ensemble size and burn-in steps dropped from the summary.
    converged : bool
    verdict : str
        One line explaining `converged`.
    flags : tuple of str
        Warnings for the reader (model misfit, stuck walkers, ...).
    time_utc : (n,) datetime64[ns]
        Every usable sample of the pass.
    mag_obs, mag_err, mag_model : (n,) float
        Observed magnitudes and errors, best-fit model with the offset applied.
    in_window : (n,) bool
        Inside the fitted window.
    fitted : (n,) bool
        Seen by the likelihood (itself or inside a bin).
    offset_mag, jitter_mag : float
        Offset and jitter at the best fit (0 where not fitted).
    residual_rms_mag : float
        RMS of observed minus best-fit model magnitudes over every sample of the window.
    chi2, dof : float, int
        chi2 of the best fit with the observed errors alone over every sample of the window,
        and degrees of freedom (those samples - free parameters - offset).
    samples : (m, ndim) float
        Posterior draws kept in the archive (wrapped angles unrolled).
    chain_path : str
        The emcee HDFBackend file holding the full chain.
    elapsed_s : float
    n_evaluations : int
    init : mapping
        How the walkers started.
    config : mapping
        The configuration that produced the fit.
    created_utc : str
    curve : ModelCurve or None
        The model at fine time steps over the pass, with a posterior band.
    epoch_utc : str
        Reference epoch of the phases (the fitted window's mid-time), ISO UTC.
    spin_periods : mapping
        The spin period in each convention (`rsodb.fit.conventions.spin_periods`).
    selection : str
        What the likelihood saw, in words.
    """

    pass_id: str
    name: str
    space: ParameterSpace
    likelihood: str
    median: np.ndarray
    p16: np.ndarray
    p84: np.ndarray
    best: np.ndarray
    best_log_prob: float
    autocorr_time: np.ndarray
    acceptance_fraction: np.ndarray
    n_steps: int
    n_walkers: int
    discard: int
    converged: bool
    verdict: str
    flags: tuple[str, ...]
    time_utc: np.ndarray
    mag_obs: np.ndarray
    mag_err: np.ndarray
    mag_model: np.ndarray
    offset_mag: float
    jitter_mag: float
    residual_rms_mag: float
    chi2: float
    dof: int
    samples: np.ndarray
    chain_path: str
    elapsed_s: float
    n_evaluations: int
    init: Mapping[str, Any] = field(default_factory=dict)
    config: Mapping[str, Any] = field(default_factory=dict)
    created_utc: str = ""
    in_window: np.ndarray | None = None
    fitted: np.ndarray | None = None
    curve: ModelCurve | None = None
    epoch_utc: str = ""
    spin_periods: Mapping[str, Any] = field(default_factory=dict)
    selection: str = ""

    def __post_init__(self):
        for name in (
            "median",
            "p16",
            "p84",
            "best",
            "autocorr_time",
            "acceptance_fraction",
            "mag_obs",
            "mag_err",
            "mag_model",
            "samples",
        ):
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        times = np.array(self.time_utc, dtype="datetime64[ns]")
        times.setflags(write=False)
        object.__setattr__(self, "time_utc", times)
        object.__setattr__(self, "flags", tuple(self.flags))
        for name in ("in_window", "fitted"):
            value = getattr(self, name)
            value = np.ones(times.size, dtype=bool) if value is None else np.array(value, dtype=bool)
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    # -- views ------------------------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        return self.space.names

    @property
    def reduced_chi2(self) -> float:
        """chi2 / dof of the best fit with the observed errors alone (NaN without dof)."""
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def residuals_mag(self) -> np.ndarray:
        """(n,) observed minus best-fit model, every stored sample."""
        return self.mag_obs - self.mag_model

    @property
    def t_s(self) -> np.ndarray:
        """(n,) seconds since the first stored sample (the pass's first usable sample)."""
        return (self.time_utc - self.time_utc[0]) / np.timedelta64(1, "s")

    @property
    def window_utc(self) -> tuple[np.datetime64, np.datetime64]:
        """First and last sample of the fitted window."""
        times = self.time_utc[self.in_window]
        return times[0], times[-1]

    @property
    def n_window(self) -> int:
        return int(np.sum(self.in_window))

    def residual_rms_by_sight(self) -> tuple[float, float]:
        """(seen, unseen): the best fit's residual RMS, mag, over the window's samples the
        likelihood saw (``fitted``) and over those it did not (NaN where there are none).

        A fit of a long pass sees ``max_points`` samples in windows spread over it
        (rsodb.fit.selection); the samples between them are an in-pass held-out set. An unseen RMS
        well above the seen one says the model follows its own samples better than the pass."""
        residuals = self.residuals_mag

        def rms(mask):
            return float(np.sqrt(np.mean(residuals[mask] ** 2))) if mask.any() else math.nan

        return rms(self.in_window & self.fitted), rms(self.in_window & ~self.fitted)

    def values(self, which: str = "median") -> dict[str, float]:
        """``{name: value}`` of `which` (``median``, ``best``, ``p16``, ``p84``) plus fixed values."""
        if which not in ("median", "best", "p16", "p84"):
            raise ValueError(f"which={which!r} must be median, best, p16 or p84")
        values = dict(self.space.fixed)
        values.update(zip(self.names, (float(v) for v in getattr(self, which))))
        return values

    def table(self) -> str:
        """The posterior as a text table: median with -/+ errors per parameter, then the spin
        period in every convention, the fit's statistics and verdicts."""
        rows = []
        if self.epoch_utc:
            rows.append(f"phases at the reference epoch {self.epoch_utc} UTC (the fitted window's mid-time)")
        if self.selection:
            rows.append(f"fitted: {self.selection}")
        rows.append(f"{'parameter':<22} {'median':>12} {'-err':>10} {'+err':>10}   best")
        for i, name in enumerate(self.names):
            unit = describe(name).unit
            rows.append(
                f"{name:<22} {self.median[i]:12.5g} {self.median[i] - self.p16[i]:10.3g} "
                f"{self.p84[i] - self.median[i]:10.3g}   {self.best[i]:.5g} {unit}"
            )
        for name, value in self.space.fixed.items():
            rows.append(f"{name:<22} {value:12.5g} {'(fixed)':>10}")
        rows.extend(self.spin_period_lines())
        rows.append(
            f"residual RMS {self.residual_rms_mag:.3f} mag over all {self.n_window} samples of the window, "
            f"reduced chi2 {self.reduced_chi2:.2f} (observed errors), jitter {self.jitter_mag:.3f} mag, "
            f"offset {self.offset_mag:+.3f} mag"
        )
        seen_rms, unseen_rms = self.residual_rms_by_sight()
        if not math.isnan(unseen_rms):
            n_seen = int(np.sum(self.in_window & self.fitted))
            rows.append(
                f"  of which {seen_rms:.3f} mag over the {n_seen} samples the likelihood saw, "
                f"{unseen_rms:.3f} over the {self.n_window - n_seen} between them it did not"
            )
        rows.append(self.verdict)
        rows.extend(f"warning: {flag}" for flag in self.flags)
        return "\n".join(rows)

    def spin_period_lines(self) -> list[str]:
        """The spin period in each convention (`rsodb.fit.conventions`), one line each."""
        conventions = dict(self.spin_periods).get("conventions", {})
        if not conventions:
            return []
        definitions = self.spin_periods.get("definitions", {})
        lines = ["spin period by convention (median, 16-84%):"]
        for name, value in conventions.items():
            share = value.get("share", 1.0)
            lines.append(
                f"  {name:<12} {value['median']:.6g} s ({value['p16']:.6g}-{value['p84']:.6g})  "
                f"{definitions.get(name, '')}"
                + (
                    f"; found at this multiple in {share:.0%} of the draws, the rest a power of 2 from it or at no multiple"
                    if share < 1
                    else ""
                )
            )
        if self.spin_periods.get("periodogram_period_s") is not None:
            lines.append(
                f"  periodogram  {self.spin_periods['periodogram_period_s']:.6g} s "
                f"(+-{self.spin_periods['periodogram_uncertainty_s']:.2g}): the stored period search's, "
                f"to compare with {comparable_convention(conventions)}"
            )
        return lines

    def to_dict(self) -> dict:
        """JSON-friendly summary (no per-sample arrays)."""
        return {
            "pass_id": self.pass_id,
            "name": self.name,
            "likelihood": self.likelihood,
            "parameters": {
                n: {
                    "median": float(self.median[i]),
                    "p16": float(self.p16[i]),
                    "p84": float(self.p84[i]),
                    "best": float(self.best[i]),
                    "autocorr_time": float(self.autocorr_time[i]),
                }
                for i, n in enumerate(self.names)
            },
            "fixed": dict(self.space.fixed),
            "offset_mag": self.offset_mag,
            "jitter_mag": self.jitter_mag,
            "residual_rms_mag": self.residual_rms_mag,
            **{
                f"residual_rms_{part}_mag": None if math.isnan(value) else value
                for part, value in zip(("seen", "unseen"), self.residual_rms_by_sight())
            },
            "chi2": self.chi2,
            "dof": self.dof,
            "reduced_chi2": self.reduced_chi2,
            "n_samples": self.n_window,
            "n_fitted": int(np.sum(self.fitted)),
            "selection": self.selection,
            "epoch_utc": self.epoch_utc,
            "spin_periods": dict(self.spin_periods),
            "n_steps": self.n_steps,
            "n_walkers": self.n_walkers,
            "discard": self.discard,
            "mean_acceptance": float(np.mean(self.acceptance_fraction)),
            "converged": self.converged,
            "verdict": self.verdict,
            "flags": list(self.flags),
            "chain_path": self.chain_path,
            "elapsed_s": self.elapsed_s,
            "n_evaluations": self.n_evaluations,
            "start_utc": str(self.window_utc[0]),
            "created_utc": self.created_utc,
        }

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def from_run(
        cls,
        run,
        posterior,
        *,
        pass_id: str,
        name: str,
        time_utc,
        discard: int | None = None,
        config: Mapping | None = None,
        pass_curve: PassCurve | None = None,
        model_curve: ModelCurve | None = None,
        epoch_utc: str = "",
        spin_periods: Mapping | None = None,
        selection: str = "",
    ) -> FitResult:
        """Summarise a `ChainRun` of `posterior`.

        Parameters
        ----------
        run : ChainRun
        posterior : Posterior
            The posterior that was sampled (for the best-fit light curve).
        pass_id, name : str
        time_utc : (n,) datetime64
            Times of the likelihood's samples (used when `pass_curve` is not given).
        discard : int, optional
            Burn-in steps to drop; default half the chain.
        config : mapping, optional
            The fit configuration, stored for provenance.
        pass_curve : PassCurve, optional
            Every usable sample of the pass with the best fit (`rsodb.fit.curves.pass_curves`):
            then the residual statistics cover every sample of the window. Without it they cover
            the likelihood's samples.
        model_curve : ModelCurve, optional
        epoch_utc, selection : str
        spin_periods : mapping, optional
            `rsodb.fit.conventions.spin_periods`.
        """
        space = posterior.space
        n_steps = run.n_steps
        discard = first_kept_step(run, discard)
        if not 0 <= discard < n_steps:
            raise ValueError(f"discard={discard} must be within 0..{n_steps - 1} (the chain has {n_steps} steps)")
        kept = run.chain[discard:]
        flat = space.wrap_samples(kept.reshape(-1, space.ndim))
        p16, median, p84 = np.percentile(flat, [16, 50, 84], axis=0)
        median_wrapped = space.wrap(median)
        shift = median_wrapped - median
        tau = autocorr_time(kept)

        best_index = np.unravel_index(np.argmax(run.log_prob), run.log_prob.shape)
        best = space.wrap(run.chain[best_index])
        values = space.values(best)
        likelihood = posterior.likelihood
        jitter = jitter_of(values)
        model_mag = posterior.model.magnitudes(values)
        offset = likelihood.offset_mag(model_mag, jitter, flux_error_of(values))
        if pass_curve is None:
            pass_curve = PassCurve(
                time_utc,
                likelihood.mag_obs,
                likelihood.mag_err,
                model_mag + offset,
                np.ones(model_mag.size, dtype=bool),
                np.ones(model_mag.size, dtype=bool),
            )
        window = pass_curve.in_window
        residuals = (pass_curve.mag_obs - pass_curve.mag_model)[window]
        errors = pass_curve.mag_err[window]
        chi2 = float(np.sum((residuals / errors) ** 2))
        dof = int(residuals.size - space.ndim - likelihood.n_free_nuisance)

        converged, verdict = chain_verdict(run, kept.shape[0], tau)
        flags = []
        if likelihood.kind == "gaussian" and dof > 0 and chi2 / dof > MISFIT_REDUCED_CHI2:
            median_err = float(np.median(errors))
            flags.append(
                f"model misfit: the best fit leaves residuals of RMS {np.sqrt(np.mean(residuals**2)):.3f} mag "
                f"against a median quoted error of {median_err:.3f} mag (reduced chi2 {chi2 / dof:.1f}); "
                + (
                    f"the jitter term ({jitter:.3f} mag) absorbs the difference, so the intervals "
                    "describe this model's best compromise, not the object"
                    if "jitter_mag" in space.names
                    else "without a jitter term the intervals are too narrow"
                )
            )
        flags += prior_bound_flags(space, flat)
        if likelihood.kind == "normalised":
            flags.append(
                "normalised comparison (the published workflow's): observed errors are ignored "
                "and the intervals are not calibrated"
            )

        # Thin along the steps, keeping every walker: a stride over the flattened (step, walker)
        # order would keep only some walkers (every other one for a stride of 2), which skews
        # the stored draws when walkers sit in different modes.
        step_stride = max(1, math.ceil(kept.shape[0] * kept.shape[1] / MAX_STORED_SAMPLES))
        stored = flat.reshape(kept.shape)[::step_stride][: max(1, MAX_STORED_SAMPLES // kept.shape[1])]
        return cls(
            pass_id=pass_id,
            name=name,
            space=space,
            likelihood=likelihood.kind,
            median=median_wrapped,
            p16=p16 + shift,
            p84=p84 + shift,
            best=best,
            best_log_prob=float(run.log_prob[best_index]),
            autocorr_time=tau,
            acceptance_fraction=run.acceptance_fraction,
            n_steps=n_steps,
            n_walkers=run.n_walkers,
            discard=discard,
            converged=converged,
            verdict=verdict,
            flags=tuple(flags),
            time_utc=pass_curve.time_utc,
            mag_obs=pass_curve.mag_obs,
            mag_err=pass_curve.mag_err,
            mag_model=pass_curve.mag_model,
            offset_mag=float(offset),
            jitter_mag=jitter,
            residual_rms_mag=float(np.sqrt(np.mean(residuals**2))),
            chi2=chi2,
            dof=dof,
            samples=stored.reshape(-1, space.ndim),
            chain_path=run.chain_path,
            elapsed_s=run.elapsed_s,
            n_evaluations=int(run.n_walkers * run.steps_run + run.init.get("evaluations", 0)),
            init=dict(run.init),
            config=dict(config or {}),
            created_utc=datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            in_window=pass_curve.in_window,
            fitted=pass_curve.fitted,
            curve=model_curve,
            epoch_utc=str(epoch_utc),
            spin_periods=dict(spin_periods or {}),
            selection=selection,
        )

    # -- HDF5 ---------------------------------------------------------------------------------
    def to_hdf5(self, group) -> None:
        """Write into an h5py group (layout in the module docstring)."""
        attrs = group.attrs
        attrs["schema_version"] = SCHEMA_VERSION
        attrs["kind"] = "fit"
        for key in ("pass_id", "name", "likelihood", "verdict", "chain_path", "created_utc"):
            attrs[key] = getattr(self, key)
        for key in ("best_log_prob", "offset_mag", "jitter_mag", "residual_rms_mag", "chi2", "elapsed_s"):
            attrs[key] = float(getattr(self, key))
        attrs["reduced_chi2"] = float(self.reduced_chi2)
        for key in ("dof", "n_steps", "n_walkers", "discard", "n_evaluations"):
            attrs[key] = int(getattr(self, key))
        attrs["converged"] = bool(self.converged)
        attrs["space"] = to_json(self.space.to_dict(), sort_keys=True)
        attrs["config"] = to_json(self.config, sort_keys=True)
        attrs["init"] = to_json(self.init, sort_keys=True)
        attrs["flags"] = to_json(list(self.flags), sort_keys=True)
        attrs["epoch_utc"] = self.epoch_utc
        attrs["selection"] = self.selection
        attrs["spin_periods"] = to_json(dict(self.spin_periods), sort_keys=True)
        width = max(len(n) for n in self.names)
        summary = np.zeros(
            len(self.names),
            dtype=[
                ("name", f"S{width}"),
                ("median", "f8"),
                ("p16", "f8"),
                ("p84", "f8"),
                ("best", "f8"),
                ("autocorr_time", "f8"),
            ],
        )
        summary["name"] = [n.encode() for n in self.names]
        for key in ("median", "p16", "p84", "best", "autocorr_time"):
            summary[key] = getattr(self, key)
        group.create_dataset("summary", data=summary)
        curve = np.zeros(
            self.mag_obs.size,
            dtype=[
                ("time_utc", "i8"),
                ("mag_obs", "f8"),
                ("mag_err", "f8"),
                ("mag_model", "f8"),
                ("in_window", "?"),
                ("fitted", "?"),
            ],
        )
        curve["time_utc"] = self.time_utc.view("i8")
        curve["mag_obs"], curve["mag_err"], curve["mag_model"] = self.mag_obs, self.mag_err, self.mag_model
        curve["in_window"], curve["fitted"] = self.in_window, self.fitted
        group.create_dataset("lightcurve", data=curve, compression="gzip")
        if self.curve is not None:
            fine = group.create_group("curve")
            fine.attrs["levels"] = np.asarray(self.curve.levels, dtype=float)
            fine.create_dataset("time_utc", data=self.curve.time_utc.view("i8"), compression="gzip")
            fine.create_dataset("mag_best", data=self.curve.mag_best, compression="gzip")
            fine.create_dataset("mag_band", data=self.curve.mag_band, compression="gzip")
        group.create_dataset("samples", data=self.samples, compression="gzip")
        group.create_dataset("acceptance_fraction", data=self.acceptance_fraction)

    @classmethod
    def from_hdf5(cls, group) -> FitResult:
        """Read what `to_hdf5` wrote."""
        attrs = group.attrs
        version = int(attrs.get("schema_version", -1))
        if version not in READABLE_SCHEMAS:
            raise ValueError(
                f"fit record {group.name} has schema_version {version}; this rsodb reads "
                f"{', '.join(map(str, READABLE_SCHEMAS))} (refit the pass or upgrade rsodb)"
            )

        def text(key):
            return attr_text(attrs[key])

        summary = group["summary"][...]
        curve = group["lightcurve"][...]
        names = curve.dtype.names
        model_curve = None
        if "curve" in group:
            fine = group["curve"]
            model_curve = ModelCurve(
                fine["time_utc"][...].view("datetime64[ns]"),
                fine["mag_best"][...],
                np.asarray(fine.attrs["levels"], dtype=float),
                fine["mag_band"][...],
            )
        return cls(
            pass_id=text("pass_id"),
            name=text("name"),
            space=ParameterSpace.from_dict(json.loads(text("space"))),
            likelihood=text("likelihood"),
            median=summary["median"],
            p16=summary["p16"],
            p84=summary["p84"],
            best=summary["best"],
            best_log_prob=float(attrs["best_log_prob"]),
            autocorr_time=summary["autocorr_time"],
            acceptance_fraction=group["acceptance_fraction"][...],
            n_steps=int(attrs["n_steps"]),
            n_walkers=int(attrs["n_walkers"]),
            discard=int(attrs["discard"]),
            converged=bool(attrs["converged"]),
            verdict=text("verdict"),
            flags=tuple(json.loads(text("flags"))),
            time_utc=curve["time_utc"].view("datetime64[ns]"),
            mag_obs=curve["mag_obs"],
            mag_err=curve["mag_err"],
            mag_model=curve["mag_model"],
            offset_mag=float(attrs["offset_mag"]),
            jitter_mag=float(attrs["jitter_mag"]),
            residual_rms_mag=float(attrs["residual_rms_mag"]),
            chi2=float(attrs["chi2"]),
            dof=int(attrs["dof"]),
            samples=group["samples"][...],
            chain_path=text("chain_path"),
            elapsed_s=float(attrs["elapsed_s"]),
            n_evaluations=int(attrs["n_evaluations"]),
            init=json.loads(text("init")),
            config=json.loads(text("config")),
            created_utc=text("created_utc"),
            in_window=curve["in_window"] if "in_window" in names else None,
            fitted=curve["fitted"] if "fitted" in names else None,
            curve=model_curve,
            epoch_utc=text("epoch_utc") if "epoch_utc" in attrs else "",
            spin_periods=json.loads(text("spin_periods")) if "spin_periods" in attrs else {},
            selection=text("selection") if "selection" in attrs else "",
        )
