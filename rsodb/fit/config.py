"""Fit configuration: a TOML file (or dict) with the model, data selection, likelihood,
parameters and sampler settings of a fit.

Every key is optional; `FitConfig()` is the default fit. configs/standard.toml writes every
default out, and docs/fitting.md describes each key with an example.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
import math
from pathlib import Path
import tomllib
from types import MappingProxyType
from typing import Any

from rsodb.fit.likelihood import LIKELIHOODS, OFFSET_MODES
from rsodb.fit.model import ATTITUDES
from rsodb.fit.parameters import Parameter, ParameterSpace, describe
from rsodb.fit.priors import Uniform, prior_from_dict
from rsodb.fit.sampler import SamplerSettings, whole_number
from rsodb.fit.shapes import SHAPES, articulation_from_dict

__all__ = ["FitConfig", "ModelConfig", "DataConfig", "LikelihoodConfig", "PERIODS_PRIOR", "read_toml"]

# The default spin-period prior: +-1% around the stored (sidereal) period.
PERIODS_PRIOR = MappingProxyType(
    {"from": "periods", "width": 0.01, "multiple": 1.0, "frame": "sidereal", "force": False}
)


def _non_negative(value) -> bool:
    """A finite number >= 0 (not true or false)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0


DEFAULT_JITTER_PRIOR = Uniform(0.0, 0.5)


def _check_keys(section: str, record: Mapping, allowed) -> None:
    unknown = sorted(set(record) - set(allowed))
    if unknown:
        raise ValueError(f"fit configuration [{section}] has unknown keys {unknown}; allowed: {', '.join(allowed)}")


@dataclass(frozen=True)
class ModelConfig:
    """The forward model: shape (a built-in name or a mesh file), attitude family and renderer.

    ``mesh`` (OBJ, PLY, glTF) with ``materials`` (its materials JSON) and ``articulations``
    (tables of ``parameter``, ``part``, ``axis``, ``point_m``, ``rest_deg``) fits any scene;
    relative paths in a TOML file are relative to that file. ``grid_size`` is the shape cache's
    direction grid (0: chosen from the fit's planned work, `rsodb.fit.shapes.cache_grid_size`);
    ``element_size_m`` its largest surface element on shadowable sides (0: the renderer's
    default, the mesh radius / 30; the cached model's error against the direct renderer falls
    about in proportion, docs/fitting.md); ``normal_bins_per_step`` its shading classes per
    normal step (0: the renderer's default, 3; 1 shades a smooth glossy mesh with a few times
    fewer classes, faster, at a glint's peak 0.5% off instead of 0.1%, docs/renderer.md).
    ``n_sub`` is the exposure sub-samples per sample (0: chosen). Chosen, they turn the body at
    most 2 deg each at the prior's fastest spin, or, with ``sub_tolerance_mag`` > 0, as few as
    the model's own curve needs: doubled from one until its magnitudes at a few prior draws move
    by less than that RMS (`rsodb.fit.subsampling`).
    """

    shape: str = "auto"
    mesh: str = ""
    materials: str = ""
    articulations: tuple = ()
    repair_mesh: bool = False
    attitude: str = "precessing"
    spin_axis: str = "z"
    renderer: str = "cached"
    accuracy_mag: float = 0.01
    n_sub: int = 0
    sub_tolerance_mag: float = 0.0
    grid_size: int = 0
    element_size_m: float = 0.0
    normal_bins_per_step: float = 0.0

    def __post_init__(self):
        if self.shape != "auto" and self.shape not in SHAPES:
            raise ValueError(
                f"[model] shape={self.shape!r} is not auto or one of {', '.join(SHAPES)} "
                "(for a mesh file give mesh = PATH instead)"
            )
        for key in ("mesh", "materials"):
            if not isinstance(getattr(self, key), str):
                raise ValueError(f"[model] {key}={getattr(self, key)!r} must be a file path (text)")
        if self.mesh and self.shape != "auto":
            raise ValueError(f"[model] gives both shape={self.shape!r} and mesh={self.mesh!r}; keep one")
        if (self.materials or self.articulations) and not self.mesh:
            raise ValueError("[model] materials and articulations describe a mesh file: give mesh = PATH too")
        if isinstance(self.articulations, Mapping) or not isinstance(self.articulations, (list, tuple)):
            raise ValueError(
                f"[model] articulations={self.articulations!r} must be a list of tables "
                "(parameter, part, axis, point_m, rest_deg)"
            )
        for record in self.articulations:
            if not isinstance(record, Mapping):
                raise ValueError(f"[model] articulations: {record!r} must be a table (parameter, part, axis, ...)")
            articulation_from_dict(record)
        object.__setattr__(self, "articulations", tuple(dict(a) for a in self.articulations))
        if self.attitude not in ATTITUDES:
            raise ValueError(f"[model] attitude={self.attitude!r} is not one of {', '.join(ATTITUDES)}")
        if self.spin_axis not in ("x", "y", "z"):
            raise ValueError(f"[model] spin_axis={self.spin_axis!r} must be 'x', 'y' or 'z'")
        if self.renderer not in ("cached", "direct"):
            raise ValueError(f"[model] renderer={self.renderer!r} must be 'cached' or 'direct'")
        if not (whole_number(self.n_sub) and 0 <= self.n_sub <= 64):
            raise ValueError(f"[model] n_sub={self.n_sub!r} must be a whole number 0..64 (0 chooses it)")
        if not (_non_negative(self.sub_tolerance_mag) and self.sub_tolerance_mag < 1):
            raise ValueError(
                f"[model] sub_tolerance_mag={self.sub_tolerance_mag!r} must be 0 (2 deg of turn per "
                "sub-sample) or a small positive number of magnitudes"
            )
        if self.sub_tolerance_mag and self.n_sub:
            raise ValueError(
                f"[model] gives both n_sub={self.n_sub} and sub_tolerance_mag={self.sub_tolerance_mag}; "
                "the tolerance chooses n_sub, keep one"
            )
        if not (whole_number(self.grid_size) and (self.grid_size == 0 or 4 <= self.grid_size <= 256)):
            raise ValueError(
                f"[model] grid_size={self.grid_size!r} must be 0 (chosen from the fit's planned work) "
                "or a whole number 4..256"
            )
        if not _non_negative(self.element_size_m):
            raise ValueError(
                f"[model] element_size_m={self.element_size_m!r} must be 0 (the renderer's default) or a size in metres"
            )
        bins = self.normal_bins_per_step
        if not (_non_negative(bins) and (bins == 0 or bins >= 1)):
            raise ValueError(
                f"[model] normal_bins_per_step={bins!r} must be 0 (the renderer's default) or a number >= 1"
            )
        if not (_non_negative(self.accuracy_mag) and 0 < self.accuracy_mag < 1):
            raise ValueError(
                f"[model] accuracy_mag={self.accuracy_mag!r} must be a small positive number of magnitudes"
            )

    @property
    def attitude_settings(self) -> dict:
        return {"spin_axis": self.spin_axis} if "spin_axis" in ATTITUDES[self.attitude].settings else {}


@dataclass(frozen=True)
class DataConfig:
    """Which samples of the pass are fitted (`rsodb.fit.selection`).

    The window (``start_s``, ``duration_s``) is what residuals cover; ``max_points`` limits what
    the likelihood sees, by binning consecutive samples (each bin turning the body by at most
    ``bin_turn_deg`` at the fastest spin of the prior) and then contiguous windows (``windows``;
    0 chooses as many as keep each a cycle long), never by a stride.
    """

    start_s: float = 0.0
    duration_s: float = 0.0
    max_points: int = 0
    bin_turn_deg: float = 10.0
    windows: int = 0
    keep_saturated: bool = False
    mag_err_floor: float = 0.0

    def __post_init__(self):
        for name in ("start_s", "duration_s", "mag_err_floor", "bin_turn_deg"):
            value = getattr(self, name)
            if not _non_negative(value):
                raise ValueError(f"[data] {name}={value!r} must be a number >= 0")
        if not (whole_number(self.max_points) and (self.max_points == 0 or self.max_points >= 10)):
            raise ValueError(f"[data] max_points={self.max_points!r} must be 0 (no limit) or a whole number >= 10")
        if not (whole_number(self.windows) and self.windows >= 0):
            raise ValueError(f"[data] windows={self.windows!r} must be 0 (chosen) or a whole number >= 1")


@dataclass(frozen=True)
class LikelihoodConfig:
    """How model and data are compared (`rsodb.fit.likelihood`)."""

    kind: str = "gaussian"
    offset: str = "marginalised"
    correlation_time_s: float = 0.0
    flux_error: bool = False

    def __post_init__(self):
        if self.kind not in LIKELIHOODS:
            raise ValueError(f"[likelihood] kind={self.kind!r} is not one of {', '.join(LIKELIHOODS)}")
        if self.offset not in OFFSET_MODES:
            raise ValueError(f"[likelihood] offset={self.offset!r} is not one of {', '.join(OFFSET_MODES)}")
        tau = self.correlation_time_s
        if not _non_negative(tau):
            raise ValueError(
                f"[likelihood] correlation_time_s={tau!r} must be seconds >= 0 (0: no correlated model error)"
            )
        if tau > 0 and self.kind != "gaussian":
            raise ValueError(f"[likelihood] correlation_time_s needs kind = 'gaussian', not {self.kind!r}")
        if not isinstance(self.flux_error, bool):
            raise ValueError(f"[likelihood] flux_error={self.flux_error!r} must be true or false")
        if self.flux_error and self.kind != "gaussian":
            raise ValueError(f"[likelihood] flux_error needs kind = 'gaussian', not {self.kind!r}")


def _check_parameter_spec(name: str, spec) -> None:
    try:
        describe(name)
    except ValueError as error:
        raise ValueError(f"[parameters] {error}") from None
    if isinstance(spec, bool) or not isinstance(spec, (int, float, Mapping)):
        raise ValueError(
            f"[parameters] {name} = {spec!r} must be a number (fixed) or a table (prior; {{}} for its default prior)"
        )
    if isinstance(spec, (int, float)) and not math.isfinite(spec):
        raise ValueError(f"[parameters] {name} = {spec!r} must be a finite number")
    if isinstance(spec, Mapping) and "from" in spec:
        if spec["from"] != "periods" or name != "spin_period_s":
            raise ValueError(f'[parameters] {name}: only spin_period_s can take its prior from = "periods"')
        _check_keys(f"parameters.{name}", spec, tuple(PERIODS_PRIOR))
    elif isinstance(spec, Mapping) and spec:
        prior = prior_from_dict(spec, name)
        Parameter(name, prior)  # checks wrap windows of angles


def read_toml(path: Path, what: str) -> dict:
    """The record of a TOML file; `what` names the file in the errors (missing or invalid)."""
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} {path} does not exist; give the path of a .toml file") from None
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{path}: not valid TOML ({error})") from None


@dataclass(frozen=True)
class FitConfig:
    """Everything that defines a fit (see the module docstring for the TOML form)."""

    name: str = "default"
    model: ModelConfig = field(default_factory=ModelConfig)
    data: DataConfig = field(default_factory=DataConfig)
    likelihood: LikelihoodConfig = field(default_factory=LikelihoodConfig)
    parameters: Mapping[str, Any] = field(default_factory=dict)
    sampler: SamplerSettings = field(default_factory=SamplerSettings)
    discard: int | None = None
    band_draws: int = 50

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"fit name {self.name!r} must be a non-empty string")
        if not (whole_number(self.band_draws) and 0 <= self.band_draws <= 1000):
            raise ValueError(
                f"band_draws={self.band_draws!r} must be a whole number 0..1000 (posterior draws of the model band)"
            )
        for name, spec in dict(self.parameters).items():
            _check_parameter_spec(name, spec)
        object.__setattr__(self, "parameters", MappingProxyType(dict(self.parameters)))
        if self.discard is not None and not (whole_number(self.discard) and 0 <= self.discard < self.sampler.n_steps):
            raise ValueError(f"discard={self.discard!r} must be a whole number below n_steps={self.sampler.n_steps}")

    def __reduce__(self):
        return _config_from_dict, (self.to_dict(),)

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, record: Mapping) -> FitConfig:
        """Build from the dict form (what `tomllib` returns)."""
        sections = {"model": ModelConfig, "data": DataConfig, "likelihood": LikelihoodConfig}
        _check_keys("top level", record, ("name", "discard", "band_draws", "parameters", "sampler", *sections))
        kwargs: dict[str, Any] = {k: record[k] for k in ("name", "discard", "band_draws") if k in record}
        for key, cls_ in sections.items():
            section = record.get(key, {})
            if key == "data" and "stride" in section:
                raise ValueError(
                    "[data] stride is gone: a fixed stride strobes a periodic light curve; "
                    "use max_points (bins and contiguous windows) or start_s/duration_s"
                )
            _check_keys(key, section, cls_.__dataclass_fields__)
            kwargs[key] = cls_(**section)
        sampler = record.get("sampler", {})
        _check_keys("sampler", sampler, SamplerSettings.__dataclass_fields__)
        kwargs["sampler"] = SamplerSettings(**sampler)
        kwargs["parameters"] = dict(record.get("parameters", {}))
        return cls(**kwargs)

    @classmethod
    def from_toml(cls, path: str | Path) -> FitConfig:
        """Read a TOML fit configuration."""
        path = Path(path)
        record = read_toml(path, "fit configuration")
        model = record.get("model")
        if isinstance(model, dict):
            # Mesh paths in a file are relative to the file, wherever the fit runs from.
            for key in ("mesh", "materials"):
                if isinstance(model.get(key), str) and model[key] and not Path(model[key]).is_absolute():
                    model[key] = str((path.parent / model[key]).resolve())
        try:
            return cls.from_dict(record)
        except (TypeError, ValueError) as error:
            raise ValueError(f"{path}: {error}") from None

    def to_dict(self) -> dict:
        """The dict form (JSON/TOML-friendly)."""
        return {
            "name": self.name,
            "discard": self.discard,
            "band_draws": self.band_draws,
            "model": dict(asdict(self.model), articulations=[dict(a) for a in self.model.articulations]),
            "data": asdict(self.data),
            "likelihood": asdict(self.likelihood),
            "parameters": dict(self.parameters),
            "sampler": self.sampler.to_dict(),
        }

    def replace(self, **changes) -> FitConfig:
        """A copy with top-level fields changed; ``sampler=`` may be a dict of sampler changes."""
        if isinstance(changes.get("sampler"), Mapping):
            changes["sampler"] = self.sampler.replace(**changes["sampler"])
        return replace(self, **changes)

    # -- the parameter space ------------------------------------------------------------------
    def with_model(self, **changes) -> FitConfig:
        """A copy with ``[model]`` keys changed (e.g. ``mesh=``, ``spin_axis=``)."""
        return replace(self, model=replace(self.model, **changes))

    def parameter_specs(self, shape_parameters: Mapping[str, float]) -> dict[str, Any]:
        """Every parameter's spec (defaults overlaid with the configured ones), model order."""
        specs: dict[str, Any] = {}
        for name in ATTITUDES[self.model.attitude].parameters:
            specs[name] = dict(PERIODS_PRIOR) if name == "spin_period_s" else "default"
        specs.update(shape_parameters)
        if self.likelihood.kind == "gaussian":
            specs["jitter_mag"] = DEFAULT_JITTER_PRIOR.to_dict()
        if self.likelihood.correlation_time_s > 0:
            specs["model_error_mag"] = "default"
        if self.likelihood.flux_error:
            specs["model_flux_error"] = "default"
        specs.update(self.parameters)
        return specs

    def parameter_space(self, shape_parameters: Mapping[str, float], periods=None) -> ParameterSpace:
        """Resolve the specs into a `ParameterSpace`.

        Parameters
        ----------
        shape_parameters : mapping of str to float
            The shape's articulation and surface parameters with their default values (fixed
            unless the configuration frees them).
        periods : rsodb.periods.PeriodResult or None
            The stored period, needed when spin_period_s takes its prior from it.
        """
        free, fixed = [], {}
        for name, spec in self.parameter_specs(shape_parameters).items():
            if isinstance(spec, (int, float)):
                fixed[name] = float(spec)
            elif spec == "default" or not spec:  # {} in a configuration: free, with its default prior
                free.append(Parameter.default(name))
            elif "from" in spec:
                free.append(Parameter(name, _period_prior(spec, periods)))
            else:
                free.append(Parameter(name, prior_from_dict(spec, name)))
        return ParameterSpace(tuple(free), fixed)


def _period_prior(spec: Mapping, periods) -> Uniform:
    if periods is None:
        raise ValueError(
            "spin_period_s takes its prior from the stored period but the pass has none; run "
            "'rsodb periods' on it first, or give spin_period_s a prior in the fit configuration"
        )
    width = float(spec.get("width", PERIODS_PRIOR["width"]))
    multiple = float(spec.get("multiple", PERIODS_PRIOR["multiple"]))
    force = spec.get("force", PERIODS_PRIOR["force"])
    if not isinstance(force, bool):
        raise ValueError(f"[parameters] spin_period_s: force={force!r} must be true or false")
    if not (math.isfinite(multiple) and multiple > 0):
        raise ValueError(f"[parameters] spin_period_s: multiple={multiple!r} must be a positive number (e.g. 2 for 2P)")
    if not math.isfinite(periods.best_period_s):
        raise ValueError(
            f"pass {periods.pass_id or periods.label!r} has no stored period (verdict {periods.verdict!r}: "
            f"{periods.reason}); give spin_period_s a prior in the fit configuration"
        )
    if not force and not periods.has_period:
        raise ValueError(
            f"the stored period of pass {periods.pass_id or periods.label!r} has verdict {periods.verdict!r} "
            f"({periods.reason}); give spin_period_s a prior in the fit configuration, or use that period "
            "anyway with --force (force = true in [parameters] spin_period_s)"
        )
    low, high = periods.prior_interval_s(width_frac=width, frame=spec.get("frame", PERIODS_PRIOR["frame"]), force=force)
    return Uniform(low * multiple, high * multiple)


def _config_from_dict(record):
    return FitConfig.from_dict(record)
