"""One entry point for synthetic light curves: ``render(scene, geometry, method="auto")``.

``geometry`` is anything with the attributes of :class:`raycast.geometry.BodyGeometry`:
``sun_body (n, k, 3)`` and ``obs_body (n, k, 3)`` unit vectors in the body frame, ``weights (k,)``
(exposure sub-samples, summing to 1), ``sunlit (n, k)`` (fraction of the solar disk not eclipsed
by the Earth), ``range_km (n,)`` and ``phase_angle_deg (n,)``. Each frame's I/E is the weighted
sum over its sub-samples of ``sunlit * I/E(sun, obs)``; sub-samples in the Earth's umbra are not
rendered.

Implementations (:data:`METHODS`)
-------------------------------
``"direct"``
    :class:`raycast.renderer.direct.DirectRenderer`, the reference: orthographic rays with shadow rays,
    pixel size chosen for ``accuracy_mag`` (or given as ``pixel_size_m``); the grid's first
    hits scan-converted for meshes of up to :data:`RASTER_MAX_TRIANGLES` triangles, adaptive
    ray sampling above (:func:`direct_sampling`).
``"cached"``
    :class:`raycast.renderer.cache.SceneCache`, precomputed elements and visibility with exact BRDFs;
    pass a prebuilt ``cache`` to reuse its one-off precomputation (what a fit does).
``"auto"``
    ``"cached"`` when a ``cache`` is given or when more than :data:`AUTO_CACHE_MIN_DIRECTIONS`
    direction pairs are to be rendered (building the cache then costs less than ray casting
    every frame), otherwise ``"direct"``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import warnings

import numpy as np

from raycast.renderer import photometry
from raycast.renderer.cache import SceneCache
from raycast.renderer.direct import AccuracyOutOfReach, DirectRenderer
from raycast.renderer.rays import SUN_RADIUS_RAD
from raycast.renderer.scene import Scene

__all__ = [
    "render",
    "LightCurveModel",
    "METHODS",
    "GlintUndersampledWarning",
    "AUTO_CACHE_MIN_DIRECTIONS",
    "RASTER_MAX_TRIANGLES",
    "direct_sampling",
]

AUTO_CACHE_MIN_DIRECTIONS = 3000
# Above this many triangles the direct renderer samples adaptively with rays instead of scan
# converting its grid: scan conversion gives the grid's result faster on small meshes, but its
# cost per frame grows with the triangle count (bench/render.py times both).
RASTER_MAX_TRIANGLES = 20_000


class GlintUndersampledWarning(UserWarning):
    """The exposure sub-samples are further apart than a material's glint is wide."""


@dataclass(frozen=True, eq=False)
class LightCurveModel:
    """A synthetic light curve.

    Attributes
    ----------
    intensity_m2_sr : (n,) float, I/E per frame (exposure- and sunlit-weighted), m^2/sr.
    range_km : (n,) float, observer-object range.
    phase_angle_deg : (n,) float
    band : str, the band of the magnitudes.
    method : str, the implementation used.
    settings : dict, the implementation's settings (pixel size, cache sizes, ...).
    """

    intensity_m2_sr: np.ndarray
    range_km: np.ndarray
    phase_angle_deg: np.ndarray
    band: str
    method: str
    settings: dict = field(default_factory=dict)

    @property
    def mag(self) -> np.ndarray:
        """(n,) apparent magnitude at the true range (+inf for dark frames)."""
        return photometry.magnitude(self.intensity_m2_sr, self.range_km, self.band)

    @property
    def mag_1000km(self) -> np.ndarray:
        """(n,) magnitude reduced to 1000 km, as in ccd_phot files."""
        return photometry.magnitude(self.intensity_m2_sr, photometry.REFERENCE_RANGE_KM, self.band)

    def to_pandas(self):
        """A DataFrame with one row per frame."""
        # pandas costs about half a second to import; only this conversion needs it.
        import pandas as pd

        return pd.DataFrame(
            {
                "intensity_m2_sr": self.intensity_m2_sr,
                "range_km": self.range_km,
                "phase_angle_deg": self.phase_angle_deg,
                "mag": self.mag,
                "mag_1000km": self.mag_1000km,
            }
        )

    def __len__(self):
        return len(self.intensity_m2_sr)


def direct_sampling(scene):
    """The direct renderer's sampling for ``scene``: ``"raster"`` (scan conversion, its cost
    grows with triangles x pixels) up to :data:`RASTER_MAX_TRIANGLES` triangles, ``"adaptive"``
    (Embree rays, cost growing with the log of the triangle count) above."""
    return "raster" if scene.n_triangles <= RASTER_MAX_TRIANGLES else "adaptive"


def _direct(scene, sun, obs, accuracy_mag, cache, pixel_size_m, progress):
    sampling = direct_sampling(scene)
    if pixel_size_m is not None:
        renderer = DirectRenderer(scene, float(pixel_size_m), accuracy_mag=accuracy_mag, sampling=sampling)
    else:
        renderer = DirectRenderer.from_accuracy(scene, sun, obs, accuracy_mag, sampling=sampling)
    return renderer.intensity(sun, obs), {"pixel_size_m": renderer.pixel_size_m, "sampling": sampling}


def _cached(scene, sun, obs, accuracy_mag, cache, pixel_size_m, progress):
    if cache is None:
        cache = SceneCache.build(scene, accuracy_mag=accuracy_mag, progress=progress)
    elif cache.scene is not scene and cache.scene.name != scene.name:
        raise ValueError(f"the cache was built for {cache.scene.name!r}, not {scene.name!r}; build one for this scene")
    parameters = {cache.parameter: scene.parameters[cache.parameter]} if cache.parameter else {}
    return cache.intensity(sun, obs, **parameters), {
        "n_elements": cache.n_elements,
        "grid_size": cache.grid_size,
        "element_size_m": cache.element_size_m,
        "normal_step_deg": cache.normal_step_deg,
        "precompute_s": cache.precompute_s,
    }


METHODS = {"direct": _direct, "cached": _cached}


def render(
    scene: Scene,
    geometry,
    method: str = "auto",
    band: str = "V",
    accuracy_mag: float = 0.005,
    cache: SceneCache | None = None,
    pixel_size_m: float | None = None,
    progress: bool = False,
    **parameters,
) -> LightCurveModel:
    """Render the light curve of ``scene`` along ``geometry``.

    Parameters
    ----------
    scene : Scene
    geometry : BodyGeometry-like (see the module docstring).
    method : {"auto", "direct", "cached"}
    band : str, band of the magnitudes (solar magnitude from :mod:`raycast.renderer.photometry`).
    accuracy_mag : float, requested accuracy; sets the direct renderer's pixel size.
    cache : SceneCache, optional, a prebuilt cache for ``method="cached"``.
    pixel_size_m : float, optional, a fixed pixel size for ``method="direct"``.
    progress : bool, progress bars on long work.
    **parameters : articulation parameters, e.g. ``panel_pitch_deg=12``.

    Returns
    -------
    LightCurveModel
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a raycast.renderer.scene.Scene, not {type(scene).__name__}")
    if method not in ("auto", *METHODS):
        raise ValueError(f"method={method!r} is unknown; use 'auto', {', '.join(map(repr, METHODS))}")
    photometry.solar_magnitude(band)
    sun, obs, weights, sunlit, range_km, phase = _check_geometry(geometry)
    if parameters:
        scene = scene.with_parameters(**parameters)
    n, k = sunlit.shape
    lit = sunlit.reshape(-1) > 0.0
    chosen = method
    if method == "auto":
        method = "cached" if cache is not None or lit.sum() > AUTO_CACHE_MIN_DIRECTIONS else "direct"
    _warn_undersampled_glints(scene, sun, obs)
    flat = np.zeros(n * k)
    settings = {}
    if lit.any():
        arguments = (scene, sun.reshape(-1, 3)[lit], obs.reshape(-1, 3)[lit], accuracy_mag, cache, pixel_size_m)
        try:
            values, settings = METHODS[method](*arguments, progress)
        except AccuracyOutOfReach as error:
            if chosen != "auto":
                raise
            # "auto" promises a light curve: the cache samples every direction pair without
            # refining a pixel grid, so a glint too narrow for the grid still gets its share.
            warnings.warn(f"{error}; rendering with the cached method instead", RuntimeWarning, stacklevel=2)
            method = "cached"
            values, settings = METHODS[method](*arguments, progress)
        flat[lit] = values
    intensity = (flat.reshape(n, k) * sunlit * weights[None, :]).sum(axis=1)
    return LightCurveModel(intensity, range_km, phase, str(band).upper(), method, settings)


def _warn_undersampled_glints(scene, sun, obs):
    """Warn when consecutive exposure sub-samples move the half vector by more than the
    narrowest lobe is wide: a glint could fall between them."""
    if sun.shape[1] < 2:
        return
    widths = [
        (b.lobe_width_rad, name)
        for b, name in zip(scene.brdfs, scene.material_names)
        if b is not None and b.lobe_width_rad
    ]
    if not widths:
        return
    width, name = min(widths)
    width = max(width, SUN_RADIUS_RAD / 2.0)
    half = sun + obs
    half /= np.maximum(np.linalg.norm(half, axis=2, keepdims=True), 1e-12)
    step = np.arccos(np.clip(np.einsum("nkj,nkj->nk", half[:, 1:], half[:, :-1]), -1.0, 1.0)).max()
    if step > width:
        needed = int(math.ceil(sun.shape[1] * step / width))
        warnings.warn(
            f"exposure sub-samples are {math.degrees(step):.2f} deg apart in half-vector direction but the "
            f"glint of material {name!r} is {math.degrees(width):.2f} deg wide; compute the geometry with "
            f"n_sub >= {needed} so glints are not missed",
            GlintUndersampledWarning,
            stacklevel=3,
        )


def _check_geometry(geometry):
    try:
        sun = np.asarray(geometry.sun_body, dtype=float)
        obs = np.asarray(geometry.obs_body, dtype=float)
        weights = np.asarray(geometry.weights, dtype=float)
        sunlit = np.asarray(geometry.sunlit, dtype=float)
        range_km = np.asarray(geometry.range_km, dtype=float)
        phase = np.asarray(geometry.phase_angle_deg, dtype=float)
    except AttributeError as missing:
        raise TypeError(
            f"geometry lacks {missing.name!r}; pass a BodyGeometry (sun_body, obs_body, weights, "
            "sunlit, range_km, phase_angle_deg)"
        ) from None
    if sun.ndim != 3 or sun.shape[2] != 3 or obs.shape != sun.shape:
        raise ValueError(f"sun_body {sun.shape} and obs_body {obs.shape} must both be (n, k, 3)")
    n, k = sun.shape[:2]
    if weights.shape != (k,) or abs(weights.sum() - 1.0) > 1e-9 or np.any(weights < 0.0):
        raise ValueError(f"weights has shape {weights.shape} and sum {weights.sum():.6g}; expected ({k},) summing to 1")
    if sunlit.shape != (n, k) or np.any(sunlit < 0.0) or np.any(sunlit > 1.0) or not np.all(np.isfinite(sunlit)):
        raise ValueError(f"sunlit has shape {sunlit.shape}; expected ({n}, {k}) fractions in [0, 1]")
    if range_km.shape != (n,) or phase.shape != (n,):
        raise ValueError(f"range_km {range_km.shape} and phase_angle_deg {phase.shape} must be ({n},)")
    for name, value in (("sun_body", sun), ("obs_body", obs)):
        norms = np.linalg.norm(value, axis=2)
        if not np.all(np.isfinite(norms)) or np.any(np.abs(norms - 1.0) > 1e-6):
            raise ValueError(f"{name} must hold finite unit vectors; check the attitude and geometry")
    return sun, obs, weights, sunlit, range_km, phase
