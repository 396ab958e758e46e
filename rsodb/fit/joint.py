"""Joint fits: several passes of one object under one spin state.

One pass constrains a spin pole poorly (a few minutes of one viewing geometry); passes days
apart see the same body from other directions. A joint fit shares what a torque-free or
slowly changing spin keeps from pass to pass and frees what it cannot know:

- shared: the shape's and materials' parameters, the spin pole (``inertial``) or the cone
  angle and precession period (``precessing``), i.e. every free parameter of the passes'
  configuration except those below;
- the spin period follows a linear trend, ``P_k = P + dP/dt * (t_k - t_1)`` with ``t_k`` the
  reference epoch (fitted window's mid-time) of pass k and ``dP/dt`` in s/day
  (``spin_period_rate_s_per_day``), or is one constant (``trend=False``); every implied
  ``P_k`` must lie inside pass k's own spin-period prior (its periodogram's), which is applied
  to it;
- per pass (``NAME@K``): the spin phase and precession phase (cycles between passes days
  apart cannot be counted), and the jitter (each night's own misfit); the magnitude offset is
  marginalised per pass, as in a single fit.

The attitude families whose state carries over between passes are ``inertial`` and
``precessing`` (`JOINT_ATTITUDES`); a torque-free body's state at one epoch does not fix the
next pass without integrating days of motion, and is refused.

The likelihood is the sum of the passes' likelihoods (independent noise); `JointPosterior`
is a picklable callable like `rsodb.fit.posterior.Posterior`, so the same sampler (global
search, emcee, resumable chain) runs it. ``rsodb fit-joint`` is the command.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
import hashlib
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from rsodb.fit.config import FitConfig
from rsodb.fit.curves import pass_curves
from rsodb.fit.likelihood import flux_error_of, jitter_of, model_error_of
from rsodb.fit.parameters import Parameter, ParameterSpace
from rsodb.fit.priors import Uniform
from rsodb.fit.result import best_and_draws, chain_verdict, first_kept_step
from rsodb.fit.runner import FitProblem, load_periods, shape_store_for, spin_period_bounds
from rsodb.fit.sampler import autocorr_time, run_sampler

__all__ = [
    "JointPosterior",
    "JointProblem",
    "JointResult",
    "fit_joint",
    "plot_joint",
    "PER_PASS",
    "TREND",
    "JOINT_ATTITUDES",
]

PER_PASS = ("spin_phase_deg", "precession_phase_deg", "jitter_mag")
TREND = "spin_period_rate_s_per_day"
PERIOD = "spin_period_s"
JOINT_ATTITUDES = ("inertial", "precessing")
_SAME_EPOCH_DAYS = 1.0 / 86400.0  # passes closer than a second share the period exactly


@dataclass(frozen=True, eq=False)
class JointPosterior:
    """ln p of several passes' data under one spin state, up to a constant.

    Parameters
    ----------
    space : ParameterSpace
        The joint parameters (shared, ``NAME@K`` per pass, and `TREND`).
    parts : tuple of Posterior
        Each pass's own posterior (its space, forward model and likelihood).
    days : tuple of float
        Each pass's reference epoch minus the first pass's, days.
    """

    space: ParameterSpace
    parts: tuple
    days: tuple[float, ...]

    @property
    def ndim(self) -> int:
        return self.space.ndim

    def values(self, theta: np.ndarray) -> dict[str, float]:
        return self.space.values(theta)

    def period_of(self, values: Mapping, k: int):
        """Pass `k`'s spin period from joint values (numbers, or arrays of samples)."""
        return values[PERIOD] + values.get(TREND, 0.0) * self.days[k]

    def pass_values(self, values: Mapping[str, float], k: int) -> dict[str, float]:
        """The values of pass `k` (0-based) from joint values."""
        part = self.parts[k].space
        result = dict(part.fixed)
        for name in part.names:
            if name == PERIOD:
                result[name] = self.period_of(values, k)
            elif name in PER_PASS:
                result[name] = values[f"{name}@{k + 1}"]
            else:
                result[name] = values[name]
        return result

    def pass_theta(self, theta: np.ndarray, k: int) -> np.ndarray:
        """Pass `k`'s own parameter vector at joint `theta`."""
        return self.parts[k].space.vector(self.pass_values(self.space.values(theta), k))

    def __call__(self, theta: np.ndarray) -> float:
        log_p = self.space.log_prior(theta)
        if not math.isfinite(log_p):
            return -math.inf
        values = self.space.values(theta)
        for k, part in enumerate(self.parts):
            own = self.pass_values(values, k)
            if k and PERIOD in part.space.names:
                # Pass k's implied period under its own prior (the first pass's is in `space`).
                log_p += float(_prior_of(part.space, PERIOD).log_prob(own[PERIOD]))
                if not math.isfinite(log_p):
                    return -math.inf
            with np.errstate(divide="ignore", invalid="ignore"):
                log_like = part.likelihood.log_likelihood(
                    part.model.magnitudes(own), jitter_of(own), model_error_of(own), flux_error_of(own)
                )
            if not math.isfinite(log_like):
                return -math.inf
            log_p += log_like
        return log_p


def _prior_of(space: ParameterSpace, name: str):
    return next(p.prior for p in space.free if p.name == name)


def joint_space(spaces: Sequence[ParameterSpace], days: Sequence[float], trend: bool) -> ParameterSpace:
    """The joint parameter space of passes with these spaces and epochs (days after the first).

    Raises
    ------
    ValueError
        When the passes' spaces differ, or their spin-period priors admit no common period or trend.
    """
    first = spaces[0]
    for k, space in enumerate(spaces[1:], start=2):
        if space.names != first.names or dict(space.fixed) != dict(first.fixed):
            raise ValueError(
                f"pass {k} of the joint fit has free parameters {list(space.names)} and fixed {dict(space.fixed)}, "
                f"pass 1 {list(first.names)} and {dict(first.fixed)}: a joint fit needs one configuration"
            )
    free: list[Parameter] = []
    for parameter in first.free:
        if parameter.name in PER_PASS:
            free += [Parameter(f"{parameter.name}@{k + 1}", _prior_of(s, parameter.name)) for k, s in enumerate(spaces)]
        elif parameter.name == PERIOD:
            free.append(parameter)
            rate = _rate_bounds(spaces, days) if trend else None
            if rate is not None:
                free.append(Parameter(TREND, Uniform(*rate)))
            elif not trend:
                _check_common_period(spaces)
        else:
            free.append(parameter)
    return ParameterSpace(tuple(free), dict(first.fixed))


def _rate_bounds(spaces, days) -> tuple[float, float] | None:
    """The trends (s/day) that keep every pass's period inside its prior; None when the passes are simultaneous."""
    low0, high0 = _prior_of(spaces[0], PERIOD).bounds
    low, high = -math.inf, math.inf
    for space, day in zip(spaces[1:], days[1:]):
        if abs(day) < _SAME_EPOCH_DAYS:
            continue
        low_k, high_k = _prior_of(space, PERIOD).bounds
        a, b = (low_k - high0) / day, (high_k - low0) / day
        low, high = max(low, min(a, b)), min(high, max(a, b))
    if low == -math.inf:
        return None
    if not low < high:
        raise ValueError(
            "the passes' spin-period priors admit no linear trend through all of them; check their periods "
            "('rsodb periods') or widen the priors"
        )
    return low, high


def _check_common_period(spaces) -> None:
    bounds = np.array([_prior_of(s, PERIOD).bounds for s in spaces])
    if bounds[:, 0].max() >= bounds[:, 1].min():
        raise ValueError(
            "without a trend the passes share one spin period, but their spin-period priors do not overlap "
            f"({', '.join(f'{a:.4g}-{b:.4g} s' for a, b in bounds)}); fit with a trend or widen the priors"
        )


@dataclass(frozen=True, eq=False)
class JointProblem:
    """The passes' `FitProblem`s and their joint posterior (full, and the search's cheaper one)."""

    problems: tuple[FitProblem, ...]
    posterior: JointPosterior
    search_posterior: JointPosterior
    trend: bool

    @classmethod
    def build(cls, observed: Sequence, config, periods: Sequence | None = None, *, trend: bool = True, store=None):
        """Build every pass's problem with `config` and join them.

        Parameters
        ----------
        observed : sequence of StoredPass or Pass
            Two or more passes of one object (one is allowed: the joint posterior is then the pass's own).
        config : FitConfig
            One configuration for all (attitude `inertial` or `precessing`).
        periods : sequence of PeriodResult or None, optional
            Each pass's stored period (for the spin-period priors).
        trend : bool
            A linear trend of the spin period across the passes (else one period).
        """
        if not observed:
            raise ValueError("a joint fit needs at least one pass")
        if config.model.attitude not in JOINT_ATTITUDES:
            raise ValueError(
                f"attitude {config.model.attitude!r} cannot be shared between passes (a torque-free state does not "
                f"carry over days); a joint fit takes {' or '.join(JOINT_ATTITUDES)}"
            )
        norads = sorted({int(o.norad) for o in observed})
        if len(norads) > 1:
            raise ValueError(f"a joint fit is of one object; these passes are of NORAD {', '.join(map(str, norads))}")
        ids = [getattr(o, "pass_id", "") or o.source_name for o in observed]
        if len(set(ids)) != len(ids):
            raise ValueError(f"a pass is given twice: {', '.join(ids)}")
        periods = list(periods) if periods is not None else [None] * len(observed)
        problems = tuple(FitProblem.build(o, config, p, store=store) for o, p in zip(observed, periods))
        reference = problems[0].epoch_utc
        days = tuple(float((p.epoch_utc - reference) / np.timedelta64(1, "s")) / 86400.0 for p in problems)
        space = joint_space([p.posterior.space for p in problems], days, trend)
        return cls(
            problems,
            JointPosterior(space, tuple(p.posterior for p in problems), days),
            JointPosterior(space, tuple(p.search_posterior for p in problems), days),
            trend,
        )

    @property
    def pass_ids(self) -> tuple[str, ...]:
        return tuple(p.pass_id for p in self.problems)

    def chain_name(self, config_name: str) -> str:
        """A file name for this joint fit's chain: the configuration's name and a digest of the passes."""
        key = json.dumps({"passes": sorted(self.pass_ids), "trend": self.trend})
        return f"{config_name}-{hashlib.sha256(key.encode()).hexdigest()[:12]}.h5"


@dataclass(frozen=True, eq=False)
class JointResult:
    """What a joint fit found.

    Attributes
    ----------
    pass_ids : tuple of str
    names : tuple of str
        The joint parameters.
    median, p16, p84, best : mapping of str to float
        Posterior median, 16th and 84th percentiles (wrapped angles unrolled) and the best sample.
    passes : tuple of mapping
        Per pass: ``pass_id``, ``epoch_utc``, ``days`` (after the first), its spin period
        (``period_median_s``, ``period_p16_s``, ``period_p84_s``), ``rms_mag`` (residual RMS at the
        best sample over every sample of its fitted window) and ``n_window``.
    converged : bool
    verdict : str
    n_walkers, n_steps : int
    elapsed_s : float
    chain_path : str
    trend : bool
    curves : tuple of (PassCurve, ModelCurve)
        Each pass's observed samples and the best model over the whole pass (for `plot_joint`).
    """

    pass_ids: tuple[str, ...]
    names: tuple[str, ...]
    median: Mapping[str, float]
    p16: Mapping[str, float]
    p84: Mapping[str, float]
    best: Mapping[str, float]
    passes: tuple[Mapping[str, Any], ...]
    converged: bool
    verdict: str
    n_walkers: int
    n_steps: int
    elapsed_s: float
    chain_path: str
    trend: bool
    curves: tuple = field(default=(), repr=False)

    def to_dict(self) -> dict:
        return {
            "pass_ids": list(self.pass_ids),
            "trend": self.trend,
            "parameters": {
                name: {
                    "median": self.median[name],
                    "p16": self.p16[name],
                    "p84": self.p84[name],
                    "best": self.best[name],
                }
                for name in self.names
            },
            "passes": [dict(item) for item in self.passes],
            "converged": self.converged,
            "verdict": self.verdict,
            "n_walkers": self.n_walkers,
            "n_steps": self.n_steps,
            "elapsed_s": self.elapsed_s,
            "chain_path": self.chain_path,
        }

    def table(self) -> str:
        """The posterior and the passes, as text."""
        lines = [f"{'parameter':<30} {'median':>12} {'-1 sigma':>10} {'+1 sigma':>10} {'best':>12}"]
        for name in self.names:
            m = self.median[name]
            lines.append(
                f"{name:<30} {m:>12.5g} {self.p16[name] - m:>10.3g} {self.p84[name] - m:>+10.3g} {self.best[name]:>12.5g}"
            )
        lines.append("")
        lines.append(f"{'pass':<36} {'days':>8} {'spin period [s]':>24} {'RMS [mag]':>9} {'samples':>8}")
        for item in self.passes:
            period = (
                f"{item['period_median_s']:.5f} ({item['period_p16_s'] - item['period_median_s']:+.5f}/"
                f"{item['period_p84_s'] - item['period_median_s']:+.5f})"
            )
            lines.append(
                f"{item['pass_id']:<36} {item['days']:>8.3f} {period:>24} {item['rms_mag']:>9.3f} {item['n_window']:>8d}"
            )
        lines.append("")
        lines.append(f"sampler: {self.verdict}")
        return "\n".join(lines)


def summarise(problem: JointProblem, run, config) -> JointResult:
    """The `JointResult` of a sampler run of `problem`."""
    posterior = problem.posterior
    space = posterior.space
    # As a single fit's summary (`FitResult.from_run`): every kept sample, angles unrolled.
    discard = first_kept_step(run, config.discard)
    kept = run.chain[discard:]
    flat = space.wrap_samples(kept.reshape(-1, space.ndim))
    quantiles = np.percentile(flat, [16, 50, 84], axis=0)
    columns = dict(space.fixed) | dict(zip(space.names, flat.T))
    best, _ = best_and_draws(run, space, discard, 0, config.sampler.seed)
    best_values = space.values(best)
    passes, curves = [], []
    for k, part_problem in enumerate(problem.problems):
        periods = np.broadcast_to(posterior.period_of(columns, k), flat.shape[:1])  # a fixed period: one value
        pass_curve, model_curve = pass_curves(
            part_problem.posterior,
            part_problem.observed,
            part_problem.selection,
            posterior.pass_theta(best, k),
            np.empty((0, part_problem.posterior.space.ndim)),
            n_sub=part_problem.curve_n_sub(),
            fastest_period_s=spin_period_bounds(part_problem.posterior.space)[0],
        )
        window = pass_curve.in_window
        residual = pass_curve.mag_obs[window] - pass_curve.mag_model[window]
        p16, p50, p84 = np.percentile(periods, [16, 50, 84])
        passes.append(
            {
                "pass_id": part_problem.pass_id,
                "epoch_utc": np.datetime_as_string(part_problem.epoch_utc, unit="ms") + "Z",
                "days": posterior.days[k],
                "period_median_s": float(p50),
                "period_p16_s": float(p16),
                "period_p84_s": float(p84),
                "rms_mag": float(np.sqrt(np.mean(residual**2))) if residual.size else math.nan,
                "n_window": int(window.sum()),
            }
        )
        curves.append((pass_curve, model_curve))
    converged, verdict = chain_verdict(run, kept.shape[0], autocorr_time(kept))
    names = space.names
    return JointResult(
        pass_ids=problem.pass_ids,
        names=names,
        median=dict(zip(names, map(float, quantiles[1]))),
        p16=dict(zip(names, map(float, quantiles[0]))),
        p84=dict(zip(names, map(float, quantiles[2]))),
        best={name: float(best_values[name]) for name in names},
        passes=tuple(passes),
        converged=converged,
        verdict=verdict,
        n_walkers=int(run.chain.shape[1]),
        n_steps=int(run.n_steps),
        elapsed_s=float(run.elapsed_s),
        chain_path=str(run.chain_path),
        trend=problem.trend,
        curves=tuple(curves),
    )


def fit_joint(
    archive,
    pass_ids: Sequence[str],
    config=None,
    *,
    trend: bool = True,
    restart: bool = False,
    progress: bool = True,
) -> JointResult:
    """Fit stored passes of one object jointly (module docstring); the chain is kept in the
    archive's ``joint/`` directory and resumed when the same command runs again.

    Parameters
    ----------
    archive : rsodb.archive.Archive
    pass_ids : sequence of str
        Pass ids (unique prefixes are enough); the first one's epoch is the trend's origin.
    config : FitConfig, optional
        One configuration for every pass (default `FitConfig()` with the ``inertial`` attitude).
    trend : bool
        Fit a linear trend of the spin period (else one period for all passes).
    restart : bool
        Discard a stored chain of this joint fit.
    progress : bool
    """
    config = config or FitConfig().with_model(attitude="inertial")
    observed = [archive.get(p) for p in pass_ids]
    periods = [load_periods(archive, o.pass_id) for o in observed]
    problem = JointProblem.build(observed, config, periods, trend=trend, store=shape_store_for(archive))
    chain_path = Path(archive.path) / "joint" / problem.chain_name(config.name)
    run = run_sampler(
        problem.posterior,
        config.sampler,
        chain_path,
        restart=restart,
        progress=progress,
        description=f"joint fit of {len(observed)} passes",
        search_posterior=problem.search_posterior,
    )
    return summarise(problem, run, config)


def plot_joint(result: JointResult, path) -> Path:
    """Each pass's observed magnitudes and the best joint model as a continuous curve over the
    whole pass (the fitted window shaded), one panel per pass; written to `path` (PNG)."""
    # matplotlib loads in about a second; only drawing needs it.
    from matplotlib.figure import Figure

    n = len(result.curves)
    figure = Figure(figsize=(10, 2.8 * n))
    axes = figure.subplots(n, 1, squeeze=False)
    for axis, (pass_curve, model_curve), item in zip(axes[:, 0], result.curves, result.passes):
        t0 = pass_curve.time_utc[0]
        seconds = (pass_curve.time_utc - t0) / np.timedelta64(1, "s")
        fine = (model_curve.time_utc - t0) / np.timedelta64(1, "s")
        window = seconds[pass_curve.in_window]
        if window.size:
            axis.axvspan(window.min(), window.max(), color="0.92", zorder=0, label="fitted window")
        axis.plot(seconds, pass_curve.mag_obs, ".", ms=2, color="0.35", label="observed")
        axis.plot(fine, model_curve.mag_best, "-", lw=0.8, color="tab:red", label="joint best fit")
        axis.invert_yaxis()
        axis.set_ylabel("mag")
        axis.set_title(
            f"{item['pass_id']}: P = {item['period_median_s']:.4f} s, residual RMS {item['rms_mag']:.3f} mag",
            fontsize=9,
        )
    axes[-1, 0].set_xlabel("seconds after the pass's first sample")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    figure.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    return path
