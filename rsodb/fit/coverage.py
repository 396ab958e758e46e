"""Synthetic passes from known truths, for injection-recovery tests and benchmarks.

`inject` renders a forward model at chosen parameter values on the times of a template pass,
adds a magnitude offset and Gaussian noise, and returns a new `Pass` that can be archived and
fitted like an observation. `window` cuts a pass to a time range first (e.g. the published
workflow's 30 s). `recover` is one injection-recovery trial with the truth drawn from the fit's
own prior (the coverage study of bench/fit_coverage.py and tests/test_fit_coverage.py).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import hashlib
import math
from pathlib import Path
import time

import numpy as np

from ingest.observation import ARRAY_FIELDS, Pass
from rsodb.fit.config import FitConfig
from rsodb.fit.result import FitResult
from rsodb.fit.runner import FitProblem
from rsodb.fit.sampler import run_sampler
from rsodb.pool import imap_in_pool

__all__ = [
    "inject",
    "window",
    "Recovery",
    "recover",
    "draw_visible_truth",
    "coverage_bounds",
    "coverage_study",
    "coverage_table",
]


def window(observed: Pass, start_s: float, duration_s: float, stride: int = 1) -> Pass:
    """The samples of `observed` with ``start_s <= t_s <= start_s + duration_s``, every `stride`-th.

    Returns a plain `Pass` (an archived pass loses its archive identity).
    """
    t_s = observed.t_s
    index = np.flatnonzero((t_s >= start_s) & (t_s <= start_s + duration_s))[::stride]
    if index.size < 2:
        raise ValueError(
            f"window start_s={start_s}, duration_s={duration_s} holds {index.size} samples of a "
            f"{observed.duration_s:.1f} s pass; choose a window inside the pass"
        )
    arrays = {name: getattr(observed, name)[index] for name in ARRAY_FIELDS}
    corrected = None if observed.mag_corrected is None else observed.mag_corrected[index]
    return Pass(**{**_scalar_fields(observed), **arrays, "mag_corrected": corrected})


def _scalar_fields(observed: Pass) -> dict:
    names = [f for f in Pass.__dataclass_fields__ if f not in ARRAY_FIELDS and f != "mag_corrected"]
    return {name: getattr(observed, name) for name in names}


def inject(
    template: Pass,
    model,
    truth: Mapping[str, float],
    *,
    noise_mag: float,
    rng: np.random.Generator,
    offset_mag: float = 0.0,
    label: str = "synthetic",
) -> Pass:
    """A pass whose magnitudes are `model` at `truth`, shifted by `offset_mag`, plus noise.

    Parameters
    ----------
    template : Pass
        Supplies times, site, band, exposure and element set; `model` must have been built on
        the same times (every sample of `template`).
    model : SpinStateModel
        The forward model.
    truth : mapping
        Parameter values the model reads.
    noise_mag : float
        Standard deviation of the Gaussian noise, also written as every sample's error.
    rng : numpy.random.Generator
    offset_mag : float
        Constant added to every magnitude (an unknown zero point for the fit).
    label : str
        Becomes the source name, with a hash of the magnitudes.

    Returns
    -------
    Pass
        Valid, unsaturated samples; `mag_corrected` None; flux NaN.
    """
    if model.n != len(template):
        raise ValueError(
            f"the model has {model.n} samples but the template pass {len(template)}; "
            "build the model on the template's times"
        )
    if not noise_mag > 0:
        raise ValueError(f"noise_mag={noise_mag!r} must be positive (it is also the quoted error)")
    clean = model.magnitudes(truth) + offset_mag
    if not np.all(np.isfinite(clean)):
        raise ValueError(
            "the model predicts an invisible object at some samples for these truths; "
            "choose other values or a window where the object is lit"
        )
    n = len(template)
    mag = clean + noise_mag * rng.standard_normal(n)
    digest = hashlib.sha256(mag.tobytes()).hexdigest()
    return template.replace(
        mag=mag,
        mag_err=np.full(n, float(noise_mag)),
        flux=np.full(n, np.nan),
        flux_err=np.full(n, np.nan),
        saturated=np.zeros(n, dtype=bool),
        valid=np.ones(n, dtype=bool),
        mag_corrected=None,
        source_name=f"{label}-{digest[:12]}",
        source_sha256=digest,
        source_format="synthetic",
        reduction=None,
    )


# -- injection-recovery coverage ---------------------------------------------------------------
@dataclass(frozen=True)
class Recovery:
    """One injected truth and what the fit recovered.

    Attributes
    ----------
    truth : mapping of str to float
        Injected values of the free parameters.
    median, p16, p84 : mapping of str to float
        Posterior summary (p16/p84 on the median's unrolled branch for wrapped angles).
    covered : mapping of str to bool
        Whether ``p16 <= truth <= p84`` (angles compared on the unrolled branch).
    quantile : mapping of str to float
        Fraction of the kept posterior draws below the truth (0..1). For a calibrated fit it
        is uniform over truths drawn from the prior; `covered` is ``0.16 <= quantile <= 0.84``
        up to the percentiles' interpolation.
    autocorr_lengths : float
        Kept chain length in autocorrelation times (the longest tau of any parameter).
    converged : bool
    verdict : str
    elapsed_s : float
    """

    truth: Mapping[str, float]
    median: Mapping[str, float]
    p16: Mapping[str, float]
    p84: Mapping[str, float]
    covered: Mapping[str, bool]
    quantile: Mapping[str, float]
    autocorr_lengths: float
    converged: bool
    verdict: str
    elapsed_s: float


def _covered(space, result, truth) -> dict[str, bool]:
    covered = {}
    for i, parameter in enumerate(space.free):
        value = truth[parameter.name]
        if parameter.period is not None:
            centre = result.median[i]
            value = centre + np.mod(value - centre + parameter.period / 2, parameter.period) - parameter.period / 2
        covered[parameter.name] = bool(result.p16[i] <= value <= result.p84[i])
    return covered


def _quantiles(space, result, truth) -> dict[str, float]:
    quantiles = {}
    for i, parameter in enumerate(space.free):
        draws = result.samples[:, i]
        value = truth[parameter.name]
        if parameter.period is not None:
            # The draws are unrolled around their circular mean: put the truth on their branch.
            centre = np.median(draws)
            value = centre + np.mod(value - centre + parameter.period / 2, parameter.period) - parameter.period / 2
        quantiles[parameter.name] = float(np.mean(draws < value))
    return quantiles


def draw_visible_truth(posterior, rng: np.random.Generator, attempts: int = 200) -> dict[str, float]:
    """Free-parameter values drawn from the prior at which the model is lit and visible everywhere."""
    space = posterior.space
    for _ in range(attempts):
        theta = space.sample_prior(rng, 1)[0]
        values = space.values(theta)
        with np.errstate(divide="ignore"):
            if np.all(np.isfinite(posterior.model.magnitudes(values))):
                return {name: values[name] for name in space.names}
    raise RuntimeError(f"no prior draw in {attempts} gave a visible object; narrow the priors")


def recover(template: Pass, config, seed: int, *, noise_mag: float, chain_dir) -> Recovery:
    """Draw a truth from the fit's prior, inject it on `template`, fit it, compare.

    The truth is drawn from the same prior the fit uses, so the 68% intervals of a correct
    sampler and likelihood contain it 68% of the time over many draws (simulation-based
    calibration). A truth ``jitter_mag`` adds that much extra Gaussian scatter beyond the
    quoted error `noise_mag`.

    Parameters
    ----------
    template : Pass
        Times, geometry and band (every sample is used: cut it with `window` first).
    config : FitConfig
        The fit; its spin-period prior must not come from a stored period.
    seed : int
        Seeds the truth, the noise and the sampler.
    noise_mag : float
        Quoted error of every sample.
    chain_dir : path
        Where the chain file goes.
    """
    rng = np.random.default_rng(seed)
    config = config.replace(sampler={"seed": int(seed)})
    started = time.perf_counter()
    reference = FitProblem.build(template, config)
    truth = draw_visible_truth(reference.posterior, rng)
    values = dict(reference.posterior.space.fixed, **truth)
    jitter = values.get("jitter_mag", 0.0)
    clean = reference.posterior.model.magnitudes(values)
    n = clean.size
    observed = template.replace(
        mag=clean + np.hypot(noise_mag, jitter) * rng.standard_normal(n),
        mag_err=np.full(n, float(noise_mag)),
        valid=np.ones(n, dtype=bool),
        saturated=np.zeros(n, dtype=bool),
        mag_corrected=None,
    )
    problem = FitProblem.build(observed, config)
    chain = Path(chain_dir) / f"coverage_{seed}.h5"
    run = run_sampler(
        problem.posterior,
        config.sampler,
        chain,
        restart=True,
        progress=False,
        search_posterior=problem.search_posterior,
    )
    result = FitResult.from_run(
        run,
        problem.posterior,
        pass_id=f"coverage-{seed}",
        name=config.name,
        time_utc=problem.time_utc,
        discard=config.discard,
    )
    chain.unlink(missing_ok=True)
    chain.with_name(chain.name + ".bak").unlink(missing_ok=True)
    names = problem.posterior.space.names
    return Recovery(
        truth,
        dict(zip(names, result.median.tolist())),
        dict(zip(names, result.p16.tolist())),
        dict(zip(names, result.p84.tolist())),
        _covered(problem.posterior.space, result, truth),
        _quantiles(problem.posterior.space, result, truth),
        float((result.n_steps - result.discard) / np.nanmax(result.autocorr_time)),
        result.converged,
        result.verdict,
        time.perf_counter() - started,
    )


def coverage_bounds(n: int, p: float = 0.68, sigmas: float = 3.0) -> tuple[float, float]:
    """Fractions within `sigmas` binomial standard deviations of `p` for `n` trials."""
    half = sigmas * math.sqrt(p * (1 - p) / n)
    return max(0.0, p - half), min(1.0, p + half)


def _recover_task(task) -> Recovery:
    template, record, seed, noise_mag, chain_dir = task

    return recover(template, FitConfig.from_dict(record), seed, noise_mag=noise_mag, chain_dir=chain_dir)


def coverage_study(
    template: Pass, config, seeds, *, noise_mag: float, chain_dir, processes: int | None = None, progress: bool = True
) -> list[Recovery]:
    """`recover` for every seed, in a process pool; results in seed order.

    Returns
    -------
    list of Recovery
    """
    record = config.replace(sampler={"processes": 1}).to_dict()
    tasks = [(template, record, int(seed), float(noise_mag), str(chain_dir)) for seed in seeds]
    return list(
        imap_in_pool(
            _recover_task,
            tasks,
            processes=processes,
            progress=progress,
            description="injection-recovery",
            ordered=True,
            chunksize=1,
        )
    )


def coverage_table(recoveries) -> dict[str, float]:
    """Fraction of truths inside the 68% interval, per parameter."""
    names = list(recoveries[0].covered)
    return {name: float(np.mean([r.covered[name] for r in recoveries])) for name in names}
