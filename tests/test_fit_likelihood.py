"""Likelihoods of rsodb.fit against exact answers: scipy's normal density, numerical
integration over the offset, and the published workflow's min-max normalisation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, stats

from rsodb.fit.likelihood import GaussianLikelihood, NormalisedLikelihood, make_likelihood


@pytest.fixture()
def data():
    rng = np.random.default_rng(42)
    n = 40
    model = 6.0 + 0.8 * np.sin(np.linspace(0, 6 * np.pi, n))
    err = rng.uniform(0.03, 0.2, n)
    obs = model + 0.37 + err * rng.standard_normal(n)
    return obs, err, model


def test_fixed_offset_equals_sum_of_normal_log_densities(data):
    obs, err, model = data
    jitter = 0.05
    like = GaussianLikelihood(obs, err, offset="none")
    expected = np.sum(stats.norm.logpdf(obs, loc=model, scale=np.hypot(err, jitter)))
    # Both are sums of 40 closed-form terms in double precision: agreement to ~1e-12 relative.
    assert like.log_likelihood(model, jitter) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("jitter", [0.0, 0.05, 0.4])
def test_marginalised_offset_equals_numerical_integral_over_offset(data, jitter):
    obs, err, model = data
    marginal = GaussianLikelihood(obs, err, offset="marginalised")
    fixed = GaussianLikelihood(obs, err, offset="none")
    c_hat = marginal.offset_mag(model, jitter)
    sigma_c = 1.0 / math.sqrt(np.sum(1.0 / (err**2 + jitter**2)))
    reference = fixed.log_likelihood(model + c_hat, jitter)

    def integrand(c):
        return math.exp(fixed.log_likelihood(model + c, jitter) - reference)

    # +-40 sigma of the offset holds all of the Gaussian's mass to far below double precision.
    value, abserr = integrate.quad(
        integrand, c_hat - 40 * sigma_c, c_hat + 40 * sigma_c, points=[c_hat], epsabs=0, epsrel=1e-12, limit=200
    )
    numerical = reference + math.log(value)
    # quad's relative error ~1e-12 becomes an absolute error ~1e-12 in ln L; 1e-9 leaves margin.
    assert marginal.log_likelihood(model, jitter) == pytest.approx(numerical, abs=1e-9)


def test_best_offset_is_the_weighted_mean_residual(data):
    obs, err, model = data
    like = GaussianLikelihood(obs, err)
    w = 1 / (err**2 + 0.1**2)
    # Closed form; the data were built with a 0.37 mag offset.
    assert like.offset_mag(model, 0.1) == pytest.approx(np.sum(w * (obs - model)) / np.sum(w), rel=1e-13)
    assert like.offset_mag(model, 0.1) == pytest.approx(0.37, abs=0.05)  # ~3 sigma of the mean of 40 points


def test_marginalised_likelihood_ignores_a_constant_shift_of_the_model(data):
    obs, err, model = data
    like = GaussianLikelihood(obs, err)
    # Exact invariance; only rounding of a 3-mag shift in 40 terms (~1e-13) separates them.
    assert like.log_likelihood(model + 3.0, 0.02) == pytest.approx(like.log_likelihood(model, 0.02), abs=1e-10)


def test_compared_model_is_shifted_by_the_best_offset(data):
    obs, err, model = data
    like = GaussianLikelihood(obs, err)
    observed, aligned, sigma = like.compared(model, 0.1)
    np.testing.assert_allclose(aligned - model, like.offset_mag(model, 0.1), rtol=0, atol=1e-14)
    np.testing.assert_allclose(sigma, np.hypot(err, 0.1), rtol=1e-14)
    # chi2 at the best offset is the minimum over offsets: shifting by 0.01 mag increases it.
    assert like.chi2(model, 0.1) < np.sum(((obs - aligned - 0.01) / sigma) ** 2)


def test_normalised_matches_the_published_min_max_comparison():
    obs = np.array([10.0, 11.0, 12.0, 10.5])
    model = np.array([5.0, 7.0, 6.0, 5.0])
    like = NormalisedLikelihood(obs, np.ones(4))
    # By hand: brightest = 1. obs -> [1, 0.5, 0, 0.75]; model -> [1, 0, 0.5, 1].
    d = np.array([1, 0.5, 0, 0.75]) - np.array([1, 0, 0.5, 1])
    assert like.log_likelihood(model) == pytest.approx(-0.5 * np.sum(d**2), abs=1e-15)
    assert like.offset_mag(model) == 0.0


def test_factory_and_validation_messages():
    assert isinstance(make_likelihood("normalised", [1.0, 2.0], [0.1, 0.1]), NormalisedLikelihood)
    with pytest.raises(ValueError, match="unknown likelihood 'chi2'; use one of gaussian, normalised"):
        make_likelihood("chi2", [1.0], [0.1])
    with pytest.raises(ValueError, match="mag_err has 1 non-positive values"):
        GaussianLikelihood([1.0, 2.0], [0.1, 0.0])
    with pytest.raises(ValueError, match=r"mag_err has shape \(3,\) but the magnitudes have \(2,\)"):
        GaussianLikelihood([1.0, 2.0], [0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match="mag_obs holds non-finite values"):
        GaussianLikelihood([1.0, np.nan], [0.1, 0.1])
    with pytest.raises(ValueError, match="offset='free' is not one of marginalised, none"):
        GaussianLikelihood([1.0, 2.0], [0.1, 0.1], offset="free")


# -- the correlated model error -----------------------------------------------------------------
def _times(n: int) -> np.ndarray:
    # Uneven spacing with a gap and a repeated time, as binned and windowed samples have.
    steps = np.random.default_rng(7).uniform(0.05, 0.6, n - 1)
    steps[10], steps[25] = 4.0, 0.0
    return np.concatenate([[0.0], np.cumsum(steps)])


def _dense_log_likelihood(residual, variance, t_s, error_mag, tau_s) -> float:
    """ln N(residual; 0, C) with C = diag(variance) + error^2 exp(-|dt| / tau), by Cholesky."""
    cov = np.diag(variance) + error_mag**2 * np.exp(-np.abs(t_s[:, None] - t_s[None, :]) / tau_s)
    return float(stats.multivariate_normal(mean=np.zeros(residual.size), cov=cov).logpdf(residual))


@pytest.mark.parametrize("error_mag, tau_s", [(0.05, 0.5), (0.3, 3.0), (0.01, 20.0)])
def test_correlated_error_equals_the_dense_gaussian(data, error_mag, tau_s):
    obs, err, model = data
    t_s, jitter = _times(obs.size), 0.05
    like = GaussianLikelihood(obs, err, "none", t_s, tau_s)
    expected = _dense_log_likelihood(obs - model, err**2 + jitter**2, t_s, error_mag, tau_s)
    assert like.log_likelihood(model, jitter, error_mag) == pytest.approx(expected, abs=1e-9)
    assert like.parameters == ("jitter_mag", "model_error_mag")


@pytest.mark.parametrize("error_mag, tau_s", [(0.05, 0.5), (0.3, 3.0)])
def test_correlated_error_marginalised_offset_equals_numerical_integral(data, error_mag, tau_s):
    obs, err, model = data
    t_s, jitter = _times(obs.size), 0.02
    marginal = GaussianLikelihood(obs, err, "marginalised", t_s, tau_s)
    fixed = GaussianLikelihood(obs, err, "none", t_s, tau_s)
    centre = float(np.mean(obs - model))
    reference = fixed.log_likelihood(model + centre, jitter, error_mag)

    def integrand(c):
        return math.exp(fixed.log_likelihood(model + c, jitter, error_mag) - reference)

    # The correlated error widens the offset's posterior up to ~error_mag; +-3 mag holds it all.
    value, _ = integrate.quad(integrand, centre - 3.0, centre + 3.0, points=[centre], epsabs=0, epsrel=1e-12, limit=400)
    assert marginal.log_likelihood(model, jitter, error_mag) == pytest.approx(reference + math.log(value), abs=1e-8)


def test_correlated_error_of_zero_is_the_white_likelihood_and_differs_otherwise(data):
    obs, err, model = data
    white = GaussianLikelihood(obs, err)
    correlated = GaussianLikelihood(obs, err, t_s=_times(obs.size), correlation_time_s=2.0)
    assert correlated.log_likelihood(model, 0.05, 0.0) == white.log_likelihood(model, 0.05)
    assert white.parameters == ("jitter_mag",)
    # A slow model error explains part of a slow residual: here the likelihood rises with it.
    drifted = model + 0.2 * np.sin(_times(obs.size) / 3.0)
    assert correlated.log_likelihood(drifted, 0.05, 0.15) > correlated.log_likelihood(drifted, 0.05, 0.0) + 1.0


def test_correlated_error_validation_messages(data):
    obs, err, _ = data
    with pytest.raises(ValueError, match="needs the sample times t_s"):
        GaussianLikelihood(obs, err, correlation_time_s=1.0)
    with pytest.raises(ValueError, match="t_s must be in time order"):
        GaussianLikelihood(obs, err, t_s=_times(obs.size)[::-1], correlation_time_s=1.0)
    with pytest.raises(ValueError, match=r"correlation_time_s=-1.0 must be seconds >= 0"):
        GaussianLikelihood(obs, err, t_s=_times(obs.size), correlation_time_s=-1.0)
    with pytest.raises(ValueError, match="needs the gaussian likelihood, not 'normalised'"):
        make_likelihood("normalised", obs, err, t_s=_times(obs.size), correlation_time_s=1.0)


# -- the model's error in flux ------------------------------------------------------------------
@pytest.fixture()
def deep():
    """A light curve 5 mag deep: the model's flux error matters only where it is faint."""
    rng = np.random.default_rng(3)
    n = 3000
    t_s = np.linspace(0.0, 300.0, n)
    model = 8.0 + 2.5 * (1.0 - np.cos(2 * np.pi * t_s / 37.0))
    err = np.full(n, 0.02)
    return rng, t_s, model, err


def test_flux_error_in_magnitudes_grows_as_the_model_fades():
    from rsodb.fit.likelihood import flux_error_mag

    # 2.5 / ln 10 * f * 10^(0.4 (m - min m)): 1x, 10^0.4x and 10x at 0, 1 and 2.5 mag below the peak.
    scale = 2.5 / math.log(10.0) * 0.01
    got = flux_error_mag(np.array([11.0, 10.0, 12.5, np.inf]), 0.01)
    assert got[:3] == pytest.approx(scale * np.array([10**0.4, 1.0, 10.0]), rel=1e-14)
    assert got[3] == math.inf


def test_flux_error_adds_its_variance_to_each_sample(deep):
    rng, t_s, model, err = deep
    obs = model + err * rng.standard_normal(model.size)
    fraction, jitter = 0.004, 0.01
    sigma = np.sqrt(err**2 + jitter**2 + (2.5 / math.log(10.0) * fraction * 10 ** (0.4 * (model - model.min()))) ** 2)
    like = GaussianLikelihood(obs, err, offset="none", flux_error=True)
    expected = np.sum(stats.norm.logpdf(obs, loc=model, scale=sigma))
    assert like.log_likelihood(model, jitter, 0.0, fraction) == pytest.approx(expected, rel=1e-12)
    assert like.parameters == ("jitter_mag", "model_flux_error")
    # The offset neither moves the term (it is relative to the model's own brightest sample) nor
    # is it left out of the best offset's weights.
    marginal = GaussianLikelihood(obs, err, flux_error=True)
    assert marginal.log_likelihood(model + 0.3, jitter, 0.0, fraction) == pytest.approx(
        marginal.log_likelihood(model, jitter, 0.0, fraction), abs=1e-9
    )
    w = 1.0 / sigma**2
    assert marginal.offset_mag(model, jitter, fraction) == pytest.approx(np.sum(w * (obs - model)) / np.sum(w))
    assert marginal.compared(model, jitter, fraction)[2] == pytest.approx(sigma, rel=1e-12)
    # Off (the default), the term is ignored whatever value is passed.
    white = GaussianLikelihood(obs, err)
    assert white.log_likelihood(model, jitter, 0.0, fraction) == white.log_likelihood(model, jitter)


def test_flux_error_enters_the_correlated_likelihood_as_white_variance(deep):
    rng, t_s, model, err = deep
    # The first 300 samples (a dense 3000^2 reference is slow); they hold the brightest (t = 0).
    t_s, model, err = t_s[:300], model[:300], err[:300]
    obs, fraction = model + err * rng.standard_normal(model.size), 0.003
    like = GaussianLikelihood(obs, err, "none", t_s, 5.0, flux_error=True)
    variance = err**2 + (2.5 / math.log(10.0) * fraction * 10 ** (0.4 * (model - model.min()))) ** 2
    expected = _dense_log_likelihood(obs - model, variance, t_s, 0.02, 5.0)
    assert like.log_likelihood(model, 0.0, 0.02, fraction) == pytest.approx(expected, abs=1e-8)
    assert like.log_likelihood(model, 0.0, 0.02, 0.0) != pytest.approx(expected, abs=1e-3)
    assert like.parameters == ("jitter_mag", "model_error_mag", "model_flux_error")


def test_a_dark_model_sample_is_not_forgiven_by_the_flux_error(deep):
    rng, t_s, model, err = deep
    like = GaussianLikelihood(model + 0.01, err, flux_error=True)
    dark = model.copy()
    dark[100] = np.inf
    assert like.log_likelihood(dark, 0.0, 0.0, 0.01) == -math.inf


def test_injected_flux_error_is_recovered(deep):
    """Data scattered by a model error of 0.5% of the peak flux (plus 0.02 mag noise): the
    likelihood's best flux error over a grid lands within 15% of it, and a fit without the
    term would need a jitter (the same at every sample) far above the bright samples' scatter."""
    rng, t_s, model, err = deep
    fraction = 0.005
    flux = 10 ** (-0.4 * (model - model.min()))
    scattered = flux + fraction * rng.standard_normal(model.size)
    keep = scattered > 0.2 * fraction  # (a flux error cannot take a sample below zero in magnitudes)
    obs = model.min() - 2.5 * np.log10(scattered[keep]) + err[keep] * rng.standard_normal(keep.sum())
    like = GaussianLikelihood(obs, err[keep], flux_error=True)
    grid = np.linspace(0.001, 0.012, 221)
    values = [like.log_likelihood(model[keep], 0.0, 0.0, f) for f in grid]
    assert grid[int(np.argmax(values))] == pytest.approx(fraction, rel=0.15)
    white = GaussianLikelihood(obs, err[keep])
    jitters = np.linspace(0.0, 0.5, 501)
    best_jitter = jitters[int(np.argmax([white.log_likelihood(model[keep], j) for j in jitters]))]
    assert best_jitter > 0.05  # the faint samples' scatter, spread over every sample
    assert max(values) > max(white.log_likelihood(model[keep], j) for j in jitters) + 50.0
