"""Synthetic passes from known truths, for injection-recovery tests and benchmarks.

`inject` renders a forward model at chosen parameter values on the times of a template pass,
adds a magnitude offset and Gaussian noise, and returns a new `Pass` that can be archived and
fitted like an observation. `window` cuts a pass to a time range first (e.g. the published
workflow's 30 s), optionally binning consecutive samples into longer exposures (never taking
every k-th). `recover` is one injection-recovery trial with the truth drawn from the fit's own
prior (the coverage study of bench/fit_coverage.py and tests/test_fit_coverage.py);
`recover_observed` fits a pass rendered elsewhere (e.g. by Blender Cycles) against its truth.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
import hashlib
import math
from pathlib import Path
import time

import numpy as np

from ingest.observation import ARRAY_FIELDS, Pass
from rsodb.fit.config import FitConfig
from rsodb.fit.runner import FitProblem
from rsodb.fit.sampler import run_sampler
from rsodb.fit.selection import Selection
from rsodb.pool import imap_in_pool

__all__ = [
    "inject",
    "window",
    "Recovery",
    "recover",
    "recover_observed",
    "draw_visible_truth",
    "look_alike_turns",
    "bias_sigmas",
    "coverage_bounds",
    "coverage_study",
    "coverage_table",
]


def window(observed: Pass, start_s: float, duration_s: float, bin_size: int = 1) -> Pass:
    """The samples of `observed` with ``start_s <= t_s <= start_s + duration_s``.

    With ``bin_size > 1`` every `bin_size` consecutive samples become one sample: the magnitude
    of their mean flux at their mid-time, an exposure spanning them all (a remainder at the end
    is left out). Returns a plain `Pass` (an archived pass loses its archive identity).
    """
    t_s = observed.t_s
    index = np.flatnonzero((t_s >= start_s) & (t_s <= start_s + duration_s))
    if index.size < 2 * bin_size:
        raise ValueError(
            f"window start_s={start_s}, duration_s={duration_s} holds {index.size} samples of a "
            f"{observed.duration_s:.1f} s pass; choose a window inside the pass"
        )
    if not (isinstance(bin_size, int) and bin_size >= 1):
        raise ValueError(f"bin_size={bin_size!r} must be a whole number >= 1")
    arrays = {name: getattr(observed, name)[index] for name in ARRAY_FIELDS}
    corrected = None if observed.mag_corrected is None else observed.mag_corrected[index]
    cut = Pass(**{**_scalar_fields(observed), **arrays, "mag_corrected": corrected})
    if bin_size == 1:
        return cut
    whole = len(cut) // bin_size * bin_size
    groups = np.arange(whole).reshape(-1, bin_size)
    bins = Selection(np.ones(len(cut), dtype=bool), groups, "", None)
    # The bins hold the best magnitudes (corrected where the file needed it) as their `mag`.
    mag, mag_err = bins.magnitudes(cut)
    mean = {name: getattr(cut, name)[groups].mean(axis=1) for name in ("az_deg", "el_deg", "range_km")}
    return cut.replace(
        flux=cut.flux[groups].sum(axis=1),
        flux_err=np.sqrt(np.sum(cut.flux_err[groups] ** 2, axis=1)),
        exposure_s=bins.exposure_s(cut),
        time_utc=bins.time_utc(cut),
        mag=mag,
        mag_err=mag_err,
        saturated=cut.saturated[groups].any(axis=1),
        valid=cut.valid[groups].all(axis=1),
        mag_corrected=None,
        **mean,
    )


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
        up to the percentiles' interpolation, `covered95` is ``0.025 <= quantile <= 0.975``.
    autocorr_lengths : float
        Kept chain length in autocorrelation times (the longest tau of any parameter).
    converged : bool
    verdict : str
    elapsed_s : float
    bias_sigma : mapping of str to float
        (median - truth) over the posterior's sigma, half the 16-84% width.
    residual_rms_mag : float
        RMS of data minus best fit over every sample of the fitted window.
    look_alike_turns : mapping of str to float
        Angles scored modulo a turn that leaves the light curve unchanged (`look_alike_turns`),
        e.g. ``{"spin_phase_deg": 180.0}`` for a body that looks the same turned half a
        revolution about its spin axis; their median, p16 and p84 are on that fold.
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
    bias_sigma: Mapping[str, float] = field(default_factory=dict)
    residual_rms_mag: float = math.nan
    look_alike_turns: Mapping[str, float] = field(default_factory=dict)

    @property
    def covered95(self) -> dict[str, bool]:
        return {name: bool(0.025 <= q <= 0.975) for name, q in self.quantile.items()}


def _on_branch(value, centre: float, period: float | None):
    """`value` moved by whole periods of a wrapped angle to within half a period of `centre`."""
    if period is None:
        return value
    return centre + np.mod(value - centre + period / 2, period) - period / 2


def _circular_mean(draws: np.ndarray, period: float) -> float:
    angle = 2 * np.pi * draws / period
    return float(period * np.angle(np.mean(np.exp(1j * angle))) / (2 * np.pi))


# Orders of rotational symmetry tried for a wrapped angle, largest first (see `look_alike_turns`).
_SYMMETRY_ORDERS = (6, 4, 3, 2)


def look_alike_turns(model, values: Mapping[str, float], names, tolerance_mag: float) -> dict[str, float]:
    """The turn under which each wrapped angle leaves the light curve unchanged.

    A body that looks the same turned half a revolution about its spin axis gives the same light
    curve at spin phase phi and phi + 180 deg: the data cannot tell those states apart, and a
    posterior in either is right. For each angle in `names` whose parameter wraps (a phase), the
    model is rendered at `values` and with the angle turned by 360/n deg for n in 6, 4, 3, 2;
    the first turn whose light curve differs by less than `tolerance_mag` RMS (after removing the
    mean, which the fit's offset absorbs) is returned for that angle. Angles with no such turn are
    left out.
    """
    reference = model.magnitudes(dict(values))
    turns = {}
    for name in names:
        for order in _SYMMETRY_ORDERS:
            turned = dict(values, **{name: values[name] + 360.0 / order})
            difference = model.magnitudes(turned) - reference
            if np.all(np.isfinite(difference)):
                difference = difference - np.mean(difference)
                if np.sqrt(np.mean(difference**2)) < tolerance_mag:
                    turns[name] = 360.0 / order
                    break
    return turns


def _values_at_truth(space, median, truth) -> dict[str, float]:
    """Every parameter's value: the truth where there is one, else the posterior median (a
    parameter the data were not drawn with), else the fixed value."""
    return {**space.fixed, **dict(zip(space.names, np.asarray(median, dtype=float).tolist())), **truth}


def _wrapped(space, truth) -> list[str]:
    """The free wrapped angles that have a truth."""
    return [p.name for p in space.free if p.period is not None and p.name in truth]


def _scores(space, result, truth, turns: Mapping[str, float]):
    """Posterior summary and the truth's place in it, per free parameter with a truth.

    An angle in `turns` is folded at that turn (a look-alike turn of the body, shorter than its
    own period): its draws are unrolled around their circular mean at the turn and summarised
    again. Wrapped angles put the truth on the branch of the posterior median.

    Returns (median, p16, p84, covered, quantile, bias_sigma), mappings by name.
    """
    median, p16, p84, covered, quantile, bias = {}, {}, {}, {}, {}, {}
    for i, parameter in enumerate(space.free):
        name = parameter.name
        draws = result.samples[:, i]
        period = turns.get(name, parameter.period)
        if name in turns:
            centre = _circular_mean(draws, period)
            centre = parameter.prior.low + np.mod(centre - parameter.prior.low, period)
            draws = _on_branch(draws, centre, period)
            low, mid, high = (float(v) for v in np.percentile(draws, [16.0, 50.0, 84.0]))
        else:
            low, mid, high = float(result.p16[i]), float(result.median[i]), float(result.p84[i])
        median[name], p16[name], p84[name] = mid, low, high
        if name not in truth:
            continue
        covered[name] = bool(low <= _on_branch(truth[name], mid, period) <= high)
        # The draws are unrolled around their circular mean: put the truth on their branch.
        quantile[name] = float(np.mean(draws < _on_branch(truth[name], np.median(draws), period)))
        sigma = 0.5 * (high - low)
        bias[name] = float((mid - _on_branch(truth[name], mid, period)) / sigma) if sigma > 0 else math.inf
    return median, p16, p84, covered, quantile, bias


def bias_sigmas(space, result, truth: Mapping[str, float]) -> dict[str, float]:
    """Posterior median - truth of each free parameter with a truth, in posterior sigmas (half
    the 16-84% width; a wrapped angle's truth on the median's branch), as `Recovery.bias_sigma`."""
    return _scores(space, result, {n: float(v) for n, v in truth.items() if n in space.names}, {})[5]


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


def recover_observed(
    observed: Pass,
    config,
    truth: Mapping[str, float],
    seed: int,
    *,
    chain_dir,
    store=None,
    look_alike_mag: float | None = None,
) -> Recovery:
    """Fit `observed` and compare the posterior with the `truth` it was made from.

    Parameters
    ----------
    observed : Pass
        The pass to fit (rendered from `truth` by anything: the project's model, Blender Cycles).
    config : FitConfig
        The fit; its spin-period prior must not come from a stored period.
    truth : mapping
        True values of the fit's free parameters.
    seed : int
        Seeds the sampler; names the chain file.
    chain_dir : path
        Where the chain file goes (removed afterwards).
    store : ShapeStore, optional
        Shape caches (a process pool's workers share a disk store).
    look_alike_mag : float, optional
        Score a phase modulo a turn of the body that changes the fit's model light curve at the
        truth by less than this RMS (`look_alike_turns`): the data cannot tell those states
        apart. None (the default) scores every angle modulo its own period.
    """
    started = time.perf_counter()
    config = config.replace(sampler={"seed": int(seed)})
    problem = FitProblem.build(observed, config, store=store)
    chain = Path(chain_dir) / f"coverage_{seed}.h5"
    run = run_sampler(
        problem.posterior,
        config.sampler,
        chain,
        restart=True,
        progress=False,
        search_posterior=problem.search_posterior,
    )
    result = problem.summarise(run)
    chain.unlink(missing_ok=True)
    chain.with_name(chain.name + ".bak").unlink(missing_ok=True)
    space = problem.posterior.space
    names = space.names
    # A parameter the data were not drawn with (the jitter of passes with Gaussian noise only,
    # as the Cycles passes) has no truth to hold: it is fitted, not scored.
    truth = {name: float(truth[name]) for name in names if name in truth}
    turns = {}
    if look_alike_mag is not None:
        turns = look_alike_turns(
            problem.posterior.model,
            _values_at_truth(space, result.median, truth),
            _wrapped(space, truth),
            look_alike_mag,
        )
    median, p16, p84, covered, quantile, bias = _scores(space, result, truth, turns)
    return Recovery(
        truth,
        median,
        p16,
        p84,
        covered,
        quantile,
        float((result.n_steps - result.discard) / np.nanmax(result.autocorr_time)),
        result.converged,
        result.verdict,
        time.perf_counter() - started,
        bias,
        result.residual_rms_mag,
        turns,
    )


def recover(template: Pass, config, seed: int, *, noise_mag: float, chain_dir, store=None) -> Recovery:
    """Draw a truth from the fit's prior, inject it on `template`, fit it, compare.

    The truth is drawn from the same prior the fit uses, so the 68% intervals of a correct
    sampler and likelihood contain it 68% of the time over many draws (simulation-based
    calibration). A truth ``jitter_mag`` adds that much extra Gaussian scatter beyond the
    quoted error `noise_mag`. The truth is rendered on every sample of `template` (the fit
    itself may bin them, `config.data`).

    Parameters
    ----------
    template : Pass
        Times, geometry and band (cut it with `window` first).
    config : FitConfig
        The fit; its spin-period prior must not come from a stored period.
    seed : int
        Seeds the truth, the noise and the sampler.
    noise_mag : float
        Quoted error of every sample.
    chain_dir : path
        Where the chain file goes.
    store : ShapeStore, optional
    """
    rng = np.random.default_rng(seed)
    every_sample = config.replace(data=replace(config.data, max_points=0, start_s=0.0, duration_s=0.0))
    reference = FitProblem.build(template, every_sample, store=store)
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
    return recover_observed(observed, config, truth, seed, chain_dir=chain_dir, store=store)


def coverage_bounds(n: int, p: float = 0.68, sigmas: float = 3.0) -> tuple[float, float]:
    """Fractions within `sigmas` binomial standard deviations of `p` for `n` trials."""
    half = sigmas * math.sqrt(p * (1 - p) / n)
    return max(0.0, p - half), min(1.0, p + half)


def _recover_task(task) -> Recovery:
    template, record, seed, noise_mag, chain_dir, store = task
    return recover(template, FitConfig.from_dict(record), seed, noise_mag=noise_mag, chain_dir=chain_dir, store=store)


def coverage_study(
    template: Pass,
    config,
    seeds,
    *,
    noise_mag: float,
    chain_dir,
    processes: int | None = None,
    progress: bool = True,
    store=None,
) -> list[Recovery]:
    """`recover` for every seed, in a process pool; results in seed order.

    Returns
    -------
    list of Recovery
    """
    record = config.replace(sampler={"processes": 1}).to_dict()
    tasks = [(template, record, int(seed), float(noise_mag), str(chain_dir), store) for seed in seeds]
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


def coverage_table(recoveries, level: int = 68) -> dict[str, float]:
    """Fraction of truths inside the 68% (or, with ``level=95``, the 95%) interval, per parameter."""
    if level not in (68, 95):
        raise ValueError(f"level={level!r} must be 68 or 95")
    names = list(recoveries[0].covered)
    inside = [r.covered if level == 68 else r.covered95 for r in recoveries]
    return {name: float(np.mean([c[name] for c in inside])) for name in names}
