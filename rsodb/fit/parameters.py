"""Fit parameters: names, units, wrap-around, priors, and the vector the sampler moves.

The catalogue `KNOWN` lists every parameter the forward models and likelihoods understand,
with a plot label, a wrap period for angles and a default prior. A `ParameterSpace` picks the
free ones (each with its prior) and pins the rest to fixed values; it converts between the
sampler's vector ``theta (ndim,)`` and the ``{name: value}`` mapping the model reads.

Angles that wrap (phases, pole right ascension) are not bounded for the sampler: a walker
that crosses 360 deg keeps going and the value is reduced into ``[low, low + period)`` before
the prior and the model see it. Summaries of such parameters use circular statistics
(`wrap_samples` centres the samples on their circular mean before taking percentiles), so a
posterior that straddles 0/360 deg is reported as one interval, not two half-modes.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
import math
from types import MappingProxyType

import numpy as np

from raycast.models import topex
from rsodb.fit.priors import Prior, Uniform, prior_from_dict

__all__ = ["Parameter", "ParameterSpace", "KNOWN", "Known", "describe"]


@dataclass(frozen=True)
class Known:
    """What the project knows about one parameter name."""

    label: str
    unit: str
    period: float | None
    default_prior: Prior
    description: str
    # The values the quantity can take at all (a prior bound there is physical, not a choice).
    limits: tuple[float, float] = (-math.inf, math.inf)


# Default priors are wide; the configuration narrows them (the spin period from the stored
# periodogram result).
KNOWN: Mapping[str, Known] = MappingProxyType(
    {
        "spin_period_s": Known(
            "P", "s", None, Uniform(0.5, 1000.0), "spin period about the body spin axis", (0.0, math.inf)
        ),
        "spin_phase_deg": Known(
            "phi", "deg", 360.0, Uniform(0.0, 360.0), "spin phase at the reference epoch (the pass mid-time)"
        ),
        "precession_period_s": Known(
            "P_pr",
            "s",
            None,
            Uniform(50.0, 5000.0),
            "period of the spin axis around the precession cone",
            (0.0, math.inf),
        ),
        "precession_phase_deg": Known(
            "phi_pr", "deg", 360.0, Uniform(0.0, 360.0), "precession phase at the reference epoch (the pass mid-time)"
        ),
        "precession_angle_deg": Known(
            "theta",
            "deg",
            None,
            Uniform(0.0, 90.0),
            "half-angle of the precession cone about the satellite-to-Earth-centre direction",
            (0.0, 180.0),
        ),
        "pole_ra_deg": Known(
            "RA_pole", "deg", 360.0, Uniform(0.0, 360.0), "right ascension of an inertial spin pole (GCRS)"
        ),
        "pole_dec_deg": Known(
            "Dec_pole", "deg", None, Uniform(-90.0, 90.0), "declination of an inertial spin pole (GCRS)", (-90.0, 90.0)
        ),
        "axis_tilt_deg": Known(
            "tilt",
            "deg",
            None,
            Uniform(0.0, 30.0),
            "angle between the spin axis and the body axis named by spin_axis (inertial_tilted)",
            (0.0, 180.0),
        ),
        "axis_tilt_azimuth_deg": Known(
            "tilt_az",
            "deg",
            360.0,
            Uniform(0.0, 360.0),
            "direction of that tilt about the body axis, from the next body axis in cyclic order (inertial_tilted)",
        ),
        "inertia_ratio_2": Known(
            "I2/I1", "", None, Uniform(0.2, 5.0), "principal moment about body y over that about x", (0.0, math.inf)
        ),
        "inertia_ratio_3": Known(
            "I3/I1", "", None, Uniform(0.2, 5.0), "principal moment about body z over that about x", (0.0, math.inf)
        ),
        "omega_polar_deg": Known(
            "omega_pol",
            "deg",
            None,
            Uniform(0.0, 180.0),
            "angle of the angular velocity from body +z at the epoch (torque-free body)",
            (0.0, 180.0),
        ),
        "omega_azimuth_deg": Known(
            "omega_az",
            "deg",
            360.0,
            Uniform(0.0, 360.0),
            "azimuth of the angular velocity from body +x toward +y at the epoch",
        ),
        "panel_pitch_deg": Known("pitch", "deg", None, Uniform(-90.0, 90.0), "solar-array pitch angle (articulation)"),
        "albedo_scale": Known(
            "a",
            "",
            None,
            Uniform(0.1, 3.0),
            "factor on every material's reflectance (degenerate with a free magnitude offset)",
            (0.0, math.inf),
        ),
        "roughness": Known(
            "r", "", None, Uniform(0.05, 1.0), "roughness (Blender's, alpha = r^2) of every glossy material", (0.0, 1.0)
        ),
        "jitter_mag": Known(
            "s_jit",
            "mag",
            None,
            Uniform(0.0, 1.0),
            "extra Gaussian scatter added in quadrature to the observed errors",
            (0.0, math.inf),
        ),
        "model_error_mag": Known(
            "s_model",
            "mag",
            None,
            Uniform(0.0, 0.05),
            "RMS of the forward model's error, correlated over [likelihood] correlation_time_s",
            (0.0, math.inf),
        ),
        "model_flux_error": Known(
            "f_model",
            "",
            None,
            Uniform(0.0, 0.02),
            "the forward model's error in flux, a fraction of its brightest sample ([likelihood] flux_error)",
            (0.0, math.inf),
        ),
        "spin_period_rate_s_per_day": Known(
            "dP/dt",
            "s/day",
            None,
            Uniform(-1.0, 1.0),
            "change of the spin period per day between the passes of a joint fit (rsodb.fit.joint)",
        ),
        # The TOPEX model's surface classes, with the prior ranges docs/models.md gives sources for.
        **{
            # Reflectances, weights and roughnesses: fractions, 0-1 at most.
            name: Known(name, "", None, Uniform(spec.low, spec.high), f"TOPEX model: {spec.meaning}", (0.0, 1.0))
            for name, spec in topex.LOUVERED_SURFACE_PARAMETERS.items()
        },
    }
)


# Parameters that became parameters after chains were stored, with the value the models held
# them at before: a chain started then continues in a run that holds the parameter fixed at that
# value (rsodb.fit.sampler), since its model is the same. A parameter added later gets its entry
# here, its default being that former value.
FORMERLY_FIXED: Mapping[str, float] = MappingProxyType({"antenna_albedo": topex.ANTENNA_ALBEDO})


def describe(name: str) -> Known:
    """What the project knows about a parameter: its `KNOWN` entry, or, for another name ending
    in ``_deg``, an articulation angle of a mesh model (``[model] articulations``), or, for
    ``NAME@K``, parameter NAME of pass K of a joint fit (`rsodb.fit.joint`).

    Raises
    ------
    ValueError
        For any other name.
    """
    if name in KNOWN:
        return KNOWN[name]
    base, at, index = name.rpartition("@") if isinstance(name, str) else ("", "", "")
    if at and index.isdigit() and int(index) >= 1 and "@" not in base:
        known = describe(base)
        return replace(known, label=f"{known.label}@{index}", description=f"{known.description}, of pass {index}")
    if isinstance(name, str) and name.endswith("_deg") and name.isidentifier():
        return Known(
            name.removesuffix("_deg"), "deg", None, Uniform(-180.0, 180.0), "articulation angle of a mesh part"
        )
    raise ValueError(
        f"unknown parameter {name!r}; known parameters: {', '.join(KNOWN)} "
        "(and articulation angles of a mesh, named ..._deg)"
    )


@dataclass(frozen=True)
class Parameter:
    """One free parameter.

    Parameters
    ----------
    name : str
        A key of `KNOWN` (e.g. ``"spin_period_s"``).
    prior : Uniform or BoundedNormal
        Its prior; for a wrapped angle the prior's bounds set the wrap window.
    """

    name: str
    prior: Prior

    def __post_init__(self):
        known = describe(self.name)
        period = known.period
        if period is not None and not np.isclose(self.prior.high - self.prior.low, period):
            raise ValueError(
                f"{self.name} wraps every {period:g} {known.unit} but its prior covers "
                f"[{self.prior.low:g}, {self.prior.high:g}]; give a uniform prior one period wide"
            )

    @property
    def period(self) -> float | None:
        """Wrap period (360 for phases), or None for an ordinary parameter."""
        return describe(self.name).period

    @property
    def label(self) -> str:
        """Short plot label with unit, e.g. ``"P [s]"``."""
        known = describe(self.name)
        return f"{known.label} [{known.unit}]" if known.unit else known.label

    @classmethod
    def default(cls, name: str) -> Parameter:
        """The parameter with its default prior from `KNOWN`."""
        return cls(name, describe(name).default_prior)


@dataclass(frozen=True)
class ParameterSpace:
    """Free parameters (ordered: the sampler's vector) and fixed values.

    Parameters
    ----------
    free : tuple of Parameter
        The sampled parameters, in vector order.
    fixed : mapping of str to float
        Parameters pinned to a value.
    """

    free: tuple[Parameter, ...]
    fixed: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self):
        free = tuple(self.free)
        fixed = {str(k): float(v) for k, v in dict(self.fixed).items()}
        names = [p.name for p in free]
        if len(set(names)) != len(names):
            raise ValueError(f"parameters {names} repeat a name; list each free parameter once")
        both = sorted(set(names) & set(fixed))
        if both:
            raise ValueError(f"parameters {both} are both free and fixed; choose one")
        for name in fixed:
            describe(name)
        if not free:
            raise ValueError("a parameter space needs at least one free parameter")
        object.__setattr__(self, "free", free)
        object.__setattr__(self, "fixed", MappingProxyType(fixed))

    def __reduce__(self):
        # mappingproxy does not pickle; rebuild from plain values (the process pool needs this).
        return ParameterSpace, (self.free, dict(self.fixed))

    # -- shape ----------------------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """Free parameter names in vector order."""
        return tuple(p.name for p in self.free)

    @property
    def all_names(self) -> frozenset[str]:
        """Free and fixed names."""
        return frozenset(self.names) | frozenset(self.fixed)

    @property
    def ndim(self) -> int:
        return len(self.free)

    @property
    def labels(self) -> list[str]:
        return [p.label for p in self.free]

    @property
    def bounds(self) -> np.ndarray:
        """(ndim, 2) prior support per free parameter."""
        return np.array([p.prior.bounds for p in self.free])

    @property
    def periods(self) -> np.ndarray:
        """(ndim,) wrap period per free parameter, NaN where it does not wrap."""
        return np.array([np.nan if p.period is None else p.period for p in self.free])

    # -- conversions ----------------------------------------------------------------------
    def wrap(self, theta: np.ndarray) -> np.ndarray:
        """Reduce wrapped angles into their prior window; `theta` (..., ndim)."""
        theta = np.asarray(theta, dtype=float)
        periods = self.periods
        low = self.bounds[:, 0]
        wrapped = low + np.mod(theta - low, np.where(np.isnan(periods), 1.0, periods))
        return np.where(np.isnan(periods), theta, wrapped)

    def values(self, theta: np.ndarray) -> dict[str, float]:
        """``{name: value}`` for free (wrapped) and fixed parameters from a vector (ndim,)."""
        theta = self.wrap(theta)
        values = dict(self.fixed)
        values.update(zip(self.names, (float(v) for v in theta)))
        return values

    def vector(self, values: Mapping[str, float]) -> np.ndarray:
        """(ndim,) vector of the free parameters from a mapping that has them all."""
        missing = [n for n in self.names if n not in values]
        if missing:
            raise ValueError(f"values lack the free parameters {missing}; give every free parameter")
        return np.array([float(values[n]) for n in self.names])

    # -- prior ----------------------------------------------------------------------------
    def log_prior(self, theta: np.ndarray) -> float:
        """Sum of the free parameters' log priors at `theta` (ndim,), angles wrapped first."""
        theta = self.wrap(theta)
        return float(sum(p.prior.log_prob(v) for p, v in zip(self.free, theta)))

    def sample_prior(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """(size, ndim) independent draws from the priors."""
        return np.column_stack([p.prior.sample(rng, size) for p in self.free])

    def ppf(self, u: np.ndarray) -> np.ndarray:
        """Map (..., ndim) unit-cube points through each prior's quantile function."""
        u = np.asarray(u, dtype=float)
        return np.stack([p.prior.ppf(u[..., i]) for i, p in enumerate(self.free)], axis=-1)

    def wrap_samples(self, samples: np.ndarray) -> np.ndarray:
        """(m, ndim) samples with wrapped angles unrolled around their circular mean.

        Percentiles of the result are meaningful even when a posterior straddles the wrap
        point; values may fall outside ``[low, low + period)`` by less than half a period.
        """
        samples = np.array(samples, dtype=float)
        for i, period in enumerate(self.periods):
            if np.isnan(period):
                continue
            angle = 2 * np.pi * samples[:, i] / period
            centre = period * np.arctan2(np.mean(np.sin(angle)), np.mean(np.cos(angle))) / (2 * np.pi)
            low = self.free[i].prior.low
            centre = low + np.mod(centre - low, period)
            samples[:, i] = centre + np.mod(samples[:, i] - centre + period / 2, period) - period / 2
        return samples

    # -- new spaces -----------------------------------------------------------------------
    def with_prior(self, name: str, prior: Prior) -> ParameterSpace:
        """A copy with `name` free under `prior` (added at the end when it was not free)."""
        fixed = {k: v for k, v in self.fixed.items() if k != name}
        if name in self.names:
            free = tuple(Parameter(name, prior) if p.name == name else p for p in self.free)
        else:
            free = self.free + (Parameter(name, prior),)
        return ParameterSpace(free, fixed)

    def with_fixed(self, name: str, value: float) -> ParameterSpace:
        """A copy with `name` pinned to `value`."""
        fixed = dict(self.fixed)
        fixed[name] = value
        return ParameterSpace(tuple(p for p in self.free if p.name != name), fixed)

    @classmethod
    def from_names(cls, names: Iterable[str], fixed: Mapping[str, float] | None = None) -> ParameterSpace:
        """Free parameters with their default priors, plus fixed values."""
        return cls(tuple(Parameter.default(n) for n in names), fixed or {})

    # -- records --------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain dict form (JSON/TOML-friendly); ``free`` is a list, so the vector order survives."""
        return {"free": [{"name": p.name, "prior": p.prior.to_dict()} for p in self.free], "fixed": dict(self.fixed)}

    @classmethod
    def from_dict(cls, record: Mapping) -> ParameterSpace:
        """Inverse of `to_dict`."""
        free = tuple(Parameter(item["name"], prior_from_dict(item["prior"], item["name"])) for item in record["free"])
        return cls(free, dict(record.get("fixed", {})))
