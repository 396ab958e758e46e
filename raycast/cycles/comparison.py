"""The scenes and frame sets on which the project's renderers are compared with Blender Cycles.

Six scenes (:func:`comparison_scenes`), each a `raycast.renderer.scene.Scene` and the
`CyclesMesh` of the same triangles, normals and materials:

* ``plate``: a 2 x 1 m plate, Principled dielectric;
* ``bus_wings``: a 1 x 1 x 2 m box bus (Principled dielectric) with two glossy wings beside
  it that shade it;
* ``cylinder``: a smooth-shaded 48-sided metallic Principled cylinder with dielectric caps;
* ``paper``: the reference paper's COSMOS 2502 mesh with its own materials;
* ``paper_diffuse``, ``paper_glossy``: the same mesh all Diffuse (0.5), all Glossy (0.5, r 0.3).

Two frame sets of body-frame Sun and observer directions:

* :func:`tumble_frames`: one 40 s spin about a tilted body axis while the phase angle runs from
  30 to 100 deg;
* :func:`hard_frames`: backlit (phase 150-172 deg), glints (the half vector within a lobe width
  of a flat panel's or the smooth surface's normal) and grazing (the Sun or the observer 2-5 deg
  above a panel's plane), drawn with a seed and kept where the scene reflects something.

:func:`mag_difference` compares two renders of a frame set in magnitudes, leaving out frames
too dark to observe; tests/test_render_cycles_agreement.py and ``bench/render.py --scenes`` render
the frame sets with Cycles and the project's renderers and compare them with it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math
from pathlib import Path

import numpy as np

from raycast.cycles.runner import CyclesMesh
from raycast.renderer.brdf import GGX, Lambertian, Principled
from raycast.renderer.direct import DirectRenderer
from raycast.renderer.scene import Part, Scene

__all__ = [
    "ComparisonScene",
    "comparison_scenes",
    "tumble_frames",
    "hard_frames",
    "FrameSet",
    "mag_difference",
    "SCENE_NAMES",
    "SPIN_PERIOD_S",
]

SCENE_NAMES = ("plate", "bus_wings", "cylinder", "paper", "paper_diffuse", "paper_glossy")
SPIN_PERIOD_S = 40.0
# Frames fainter than this fraction of the brightest are dark for magnitude differences (7.5 mag
# below the peak: no observation resolves them; one renderer's 0 against 1e-6 would be infinite).
DARK_FRACTION = 1e-3


@dataclass(frozen=True, eq=False)
class ComparisonScene:
    """A scene for both renderers.

    Attributes
    ----------
    name : str
    scene : Scene, for the project's renderers.
    mesh : CyclesMesh, the same triangles, shading normals and materials for Cycles.
    panels : (k, 3) float, unit normals of the largest flat faces (body frame): the planes the
        hard frames graze and the normals their glints come from.
    smooth_normals : (j, 3) float, shading normals of smooth-shaded surfaces (may be empty),
        where glints come from too.
    """

    name: str
    scene: Scene
    mesh: CyclesMesh
    panels: np.ndarray
    smooth_normals: np.ndarray


@dataclass(frozen=True, eq=False)
class FrameSet:
    """Body-frame Sun and observer unit vectors (m, 3) and a label per frame."""

    name: str
    sun_body: np.ndarray
    obs_body: np.ndarray
    kinds: tuple

    def __len__(self):
        return len(self.sun_body)

    def subset(self, index) -> FrameSet:
        index = np.asarray(index)
        return FrameSet(self.name, self.sun_body[index], self.obs_body[index], tuple(np.asarray(self.kinds)[index]))


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _rotation_about(axis, angle_rad):
    """(..., 3, 3) rotation matrices about unit ``axis`` (3,) by ``angle_rad`` (...)."""
    x, y, z = axis
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    t = 1.0 - c
    return np.stack(
        [
            np.stack([t * x * x + c, t * x * y - s * z, t * x * z + s * y], axis=-1),
            np.stack([t * x * y + s * z, t * y * y + c, t * y * z - s * x], axis=-1),
            np.stack([t * x * z - s * y, t * y * z + s * x, t * z * z + c], axis=-1),
        ],
        axis=-2,
    )


# ------------------------------------------------------------------------------------------
# Scenes

DIELECTRIC = Principled(base_color=0.5, roughness=0.5, ior=1.5)
GLOSSY = GGX(color=0.5, roughness=0.3)
METAL = Principled(base_color=0.7, metallic=1.0, roughness=0.35)
DIFFUSE = Lambertian(0.5)


def _plate():
    return Scene.from_parts([Part.plate("plate", 2.0, 1.0, "skin")], {"skin": DIELECTRIC}, name="plate")


def _bus_wings():
    """A box bus along z and two glossy wings, 2 m long, sticking out of its +-y faces (with a
    5 cm gap), turned 20 deg about their length: their shadows sweep across the bus's sides."""
    wing = Part.plate("wing", 1.2, 2.0, "wing")  # x across, y along the wing, normal +z
    turn = _rotation_about(np.array([0.0, 1.0, 0.0]), math.radians(20.0))
    stand = _rotation_about(np.array([0.0, 1.0, 0.0]), math.radians(90.0))  # normal +z -> -x
    parts = [
        Part.box("bus", (1.0, 1.0, 2.0), "bus"),
        wing.transformed(turn @ stand, (0.0, 1.55, 0.2)),
        wing.transformed(turn @ stand, (0.0, -1.55, -0.2)),
    ]
    return Scene.from_parts(parts, {"bus": DIELECTRIC, "wing": GLOSSY}, name="bus_wings")


def _cylinder():
    part = Part.cylinder("tank", 0.8, 3.0, "side", segments=48, cap_material="cap")
    return Scene.from_parts([part], {"side": METAL, "cap": DIELECTRIC}, name="cylinder")


def _paper(models_dir):
    models_dir = Path(models_dir)
    return Scene.from_file(
        models_dir / "cosmos2502_lotos.obj", materials=models_dir / "cosmos2502_lotos.materials.json"
    )


def _panels(scene, count):
    """Unit normals of the ``count`` largest flat faces (coplanar flat triangles summed)."""
    posed = scene.posed()
    flat = np.abs(posed.corner_normals - posed.face_normals[:, None, :]).max(axis=(1, 2)) < 1e-6
    normals = posed.face_normals[flat]
    areas = posed.areas_m2[flat]
    offsets = np.einsum("ij,ij->i", normals, posed.corners_m[flat, 0])
    key = np.column_stack([np.round(normals * 1e3), np.round(offsets * 1e2)]).astype(np.int64)
    _, plane, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    plane = plane.reshape(-1)
    total = np.bincount(plane, weights=areas)
    order = np.argsort(total)[::-1]
    chosen, out = set(), []
    for index in order:
        normal = normals[np.flatnonzero(plane == index)[0]]
        direction = tuple(np.round(normal, 3))
        if direction in chosen:
            continue
        chosen.add(direction)
        out.append(normal)
        if len(out) == count:
            break
    return np.asarray(out)


def _smooth_normals(scene, count, rng):
    posed = scene.posed()
    smooth = np.abs(posed.corner_normals - posed.face_normals[:, None, :]).max(axis=(1, 2)) > 1e-6
    normals = posed.corner_normals[smooth].reshape(-1, 3)
    if len(normals) == 0:
        return np.zeros((0, 3))
    return _unit(normals[rng.choice(len(normals), size=min(count, len(normals)), replace=False)])


def comparison_scenes(models_dir, names=SCENE_NAMES) -> dict:
    """The comparison scenes by name (module docstring); ``models_dir`` holds the paper's
    ``cosmos2502_lotos.obj`` and its ``.materials.json`` (../shared/data/models)."""
    unknown = [name for name in names if name not in SCENE_NAMES]
    if unknown:
        raise ValueError(f"unknown comparison scene {unknown[0]!r}; use some of {SCENE_NAMES}")
    rng = np.random.default_rng(2502)
    out = {}
    for name in names:
        if name == "plate":
            scene = _plate()
        elif name == "bus_wings":
            scene = _bus_wings()
        elif name == "cylinder":
            scene = _cylinder()
        else:
            scene = _paper(models_dir)
            if name == "paper_diffuse":
                scene = scene.with_brdfs(**{m: DIFFUSE for m in scene.material_names})
            elif name == "paper_glossy":
                scene = scene.with_brdfs(**{m: GLOSSY for m in scene.material_names})
            scene = replace(scene, name=name)
        out[name] = ComparisonScene(
            name, scene, CyclesMesh.from_scene(scene), _panels(scene, 6), _smooth_normals(scene, 64, rng)
        )
    return out


# ------------------------------------------------------------------------------------------
# Frame sets

# The tumble's spin axis in the body frame: off every box axis, so faces turn through the light.
_SPIN_AXIS = _unit([0.36, 0.52, 0.77])


def tumble_frames(n_frames=150, period_s=SPIN_PERIOD_S, phase_deg=(30.0, 100.0)) -> FrameSet:
    """One spin of the body about a tilted body axis in ``n_frames`` steps, the phase angle
    running linearly over ``phase_deg`` meanwhile.

    In the inertial frame the Sun lies along +x and the observer turns from the Sun in the x-y
    plane; the body turns by 2 pi t / period about ``_SPIN_AXIS`` (held along the inertial
    direction (0.2, 0.5, 0.84)), so each body-frame direction is the inertial one rotated back.
    """
    t = np.arange(n_frames) * period_s / n_frames
    phase = np.radians(np.linspace(phase_deg[0], phase_deg[1], n_frames))
    sun_inertial = np.tile([1.0, 0.0, 0.0], (n_frames, 1))
    obs_inertial = np.column_stack([np.cos(phase), np.sin(phase), np.zeros(n_frames)])
    # Body axes: the spin axis along a fixed inertial direction, turning about it with time.
    axis_inertial = _unit([0.2, 0.5, 0.84])
    align = _aligning_rotation(_SPIN_AXIS, axis_inertial)  # body -> inertial at t = 0
    spin = _rotation_about(axis_inertial, 2.0 * np.pi * t / period_s)  # (m, 3, 3)
    body_to_inertial = spin @ align
    sun = np.einsum("mji,mj->mi", body_to_inertial, sun_inertial)
    obs = np.einsum("mji,mj->mi", body_to_inertial, obs_inertial)
    return FrameSet("tumble", _unit(sun), _unit(obs), ("tumble",) * n_frames)


def _aligning_rotation(a, b):
    """(3, 3) rotation taking unit ``a`` to unit ``b``."""
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3)
    return _rotation_about(v / np.linalg.norm(v), math.acos(max(-1.0, min(1.0, c))))


def _perpendicular(v, rng):
    w = _unit(np.cross(v, rng.normal(size=3)))
    return w


def _tilted(normal, elevation_deg, rng):
    """A unit vector ``elevation_deg`` above the plane of ``normal``, at a random azimuth."""
    along = _perpendicular(normal, rng)
    e = math.radians(elevation_deg)
    return _unit(math.cos(e) * along + math.sin(e) * normal)


def _candidates(comparison, kind, count, rng):
    """``count`` candidate (sun, obs) pairs of one hard kind."""
    suns, observers = [], []
    panels = comparison.panels
    glint_normals = np.vstack([panels, -panels, comparison.smooth_normals])
    width = max((b.lobe_width_rad for b in comparison.scene.brdfs if b is not None and b.lobe_width_rad), default=0.1)
    for _ in range(count):
        if kind == "backlit":
            sun = _unit(rng.normal(size=3))
            phase = math.radians(rng.uniform(150.0, 172.0))
            side = _perpendicular(sun, rng)
            obs = math.cos(phase) * sun + math.sin(phase) * side
        elif kind == "glint":
            normal = glint_normals[rng.integers(len(glint_normals))]
            half = _unit(normal + rng.uniform(0.0, 1.0) * width * _perpendicular(normal, rng))
            half_phase = math.radians(rng.uniform(20.0, 120.0)) / 2.0
            side = _perpendicular(half, rng)
            sun = math.cos(half_phase) * half + math.sin(half_phase) * side
            obs = math.cos(half_phase) * half - math.sin(half_phase) * side
        else:  # grazing
            normal = panels[rng.integers(len(panels))] * rng.choice([-1.0, 1.0])
            low = _tilted(normal, rng.uniform(2.0, 5.0), rng)
            other = _unit(normal + rng.normal(size=3) * 0.6)
            if other @ normal < 0.2:
                other = _unit(other + normal)
            sun, obs = (low, other) if rng.random() < 0.5 else (other, low)
        suns.append(sun)
        observers.append(obs)
    return _unit(np.array(suns)), _unit(np.array(observers))


def hard_frames(comparison, per_kind=6, seed=0, pixel_size_m=None, keep_fraction=0.01) -> FrameSet:
    """Backlit, glint and grazing frames of one scene (module docstring), ``per_kind`` of each.

    Candidates are drawn with ``seed``; a quick direct render (pixels of ``pixel_size_m``, by
    default the mesh radius / 40) keeps those where the scene reflects at least
    ``keep_fraction`` of its brightest tumble frame, so no frame is dark for both renderers.
    """
    rng = np.random.default_rng(seed)
    scene = comparison.scene
    if pixel_size_m is None:
        pixel_size_m = scene.posed().radius_m / 40.0
    renderer = DirectRenderer(scene, pixel_size_m, sampling="raster")
    tumble = tumble_frames(24)
    floor = keep_fraction * renderer.intensity(tumble.sun_body, tumble.obs_body).max()
    suns, observers, kinds = [], [], []
    for kind in ("backlit", "glint", "grazing"):
        kept = 0
        for _ in range(40):
            sun, obs = _candidates(comparison, kind, 4 * per_kind, rng)
            value = renderer.intensity(sun, obs)
            good = np.flatnonzero(value > floor)[: per_kind - kept]
            suns.append(sun[good])
            observers.append(obs[good])
            kept += len(good)
            if kept == per_kind:
                break
        kinds += [kind] * kept
    return FrameSet("hard", np.vstack(suns), np.vstack(observers), tuple(kinds))


def mag_difference(value, reference, dark_fraction=DARK_FRACTION):
    """(m,) 2.5 log10(value / reference), NaN where the reference is dark (below
    ``dark_fraction`` of its brightest frame)."""
    value, reference = np.asarray(value, dtype=float), np.asarray(reference, dtype=float)
    lit = reference > dark_fraction * reference.max()
    out = np.full(len(reference), np.nan)
    out[lit] = 2.5 * np.log10(np.maximum(value[lit], 1e-300) / reference[lit])
    return out
