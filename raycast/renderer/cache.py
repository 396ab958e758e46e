"""The fast path: precomputed surface elements and visibility, exact BRDFs at run time.

For a rigid body the brightness depends only on the body-frame Sun and observer directions.
:meth:`SceneCache.build` samples the surface once into *elements* (points with an area, a
material, a geometric and an interpolated shading normal, on one side of a triangle) and
precomputes, for the elements that can be shadowed at all, their visibility over a grid of
directions. At run time

    I/E = sum_e A_e f_e(s, o) max(n_s . s, 0) [n_g . s > 0] max(n_g . o, 0) V_e(s) V_e(o)

with V bilinearly interpolated on the direction grid and f evaluated analytically, so glints
keep their exact shape (no brightness table is interpolated across a glint). This is the same
integral the direct renderer estimates pixel by pixel (A (n_g . o) is an element's projected
area).

What is precomputed
-------------------
* A triangle side is *exposed* when no vertex of the mesh lies above its plane: nothing can
  shadow or hide it (every face of a convex part alone is exposed), so it needs no visibility
  and all its elements with the same normal and material merge into one (exactly).
* The inner sides of closed, consistently wound parts are skipped.
* Sides that are not exposed are cut into elements no larger than ``element_size_m``; each
  element's visibility is found by one ray per grid direction of its upper hemisphere
  (Open3D ``test_occlusions``). An element whose four quarters see differently in many
  directions (partly covered beside a mount or under a panel's edge) is replaced by its
  quarters. Elements that are never visible (the inner side of a closed part) are dropped;
  those never blocked are treated as exposed.
* Where an element sees out through a gap narrower than the grid (close above its plane, or
  between two parts anywhere in its sky: slats of a panel), the blocked grid nodes around such
  directions are its *gap nodes*, and the run time decides those directions by exact rays
  (``_horizon_gaps``, ``_slit_gaps``).
* Smooth-shaded triangles are cut finely enough that the shading normal varies by at most
  ``normal_step_deg`` within an element (a fraction of the narrowest specular lobe).
* The BRDF is evaluated once per frame and *shading class* (material and binned shading
  normal, shared by all faces), at the class's normal weighted by the lit-and-seen projected
  area of its groups in that frame.
* The direction grid is an equal-angle cube map: 6 faces of (N + 1)**2 directions, about
  90/N deg apart, ``N = grid_size``.
* Articulations (e.g. TOPEX's ``panel_pitch_deg``) are an extra axis: ``articulation_grid``
  builds one element set per value and :meth:`intensity` interpolates linearly between the
  two nearest values.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
import dataclasses
from dataclasses import dataclass, field
import functools
import itertools
import math
import os
import threading
import time
from typing import NamedTuple
import weakref

import numpy as np
from scipy import linalg, sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree
from tqdm.auto import tqdm

from raycast.renderer import _cache_kernels
from raycast.renderer.rays import check_directions, open3d_scene, orthonormal_basis, sun_samples_for
from raycast.renderer.scene import Scene
from raycast.renderer.shading import shaded_pairs

__all__ = ["SceneCache", "cube_grid_directions", "cube_grid_weights"]

# Rays per batch of the build's visibility casting (bounds its buffers, ~5 MB with Open3D's copies).
_MAX_BUILD_RAYS = 100_000
# Halvings per triangle at most: a piece is then 1/2**(_MAX_BISECTIONS/2) of the triangle's size.
_MAX_BISECTIONS = 24
# Groups of at most this many occludable elements keep their visibility columns as they are.
_FACTOR_MIN_ELEMENTS = 4
# A group is factorised only into fewer columns than its elements over this (_visibility_factors).
_FACTOR_ELEMENTS_PER_COLUMN = 8
# A group's factorisation is given up when its residual, falling as it fell over the last
# sketch's second half, would still exceed this many budgets at the largest rank allowed.
_FACTOR_GIVE_UP = 4.0
# Normals are grouped in bins of the material's normal step divided by this, by default
# (SceneCache.build's normal_bins_per_step).
_NORMAL_BINS_PER_STEP = 3.0
# Lobes whose share of the reflectance is at most this are weak (see _normal_step_rad).
_WEAK_LOBE_SHARE = 0.2
# Smooth-shaded triangles of a glossy material with a lobe narrower than this get finer elements.
_STRIP_LOBE_DEG = 10.0
# Frames per batch of the run time: as many as keep its buffer of lit (frame, class) pairs under
# _LIT_ROWS_PER_CHUNK at one row per class and frame (72 bytes a row), within these bounds.
# Fewer, longer batches save each batch's calls (whole TOPEX pass, 357 classes, one process:
# 124 ms an evaluation at 256 frames, 118 ms at 768-1 536, 126-141 ms at 2 048-4 640 as the
# buffers outgrow the caches).
_FRAMES_PER_CHUNK = (256, 1024)
_LIT_ROWS_PER_CHUNK = 2**20
# A light curve is shaded in parallel batches of at least this many frames, one per thread
# (the compiled loops release the GIL); see _threads.
_MIN_FRAMES_PER_THREAD = 32
# An element is cut in four where its quarters see differently in more than this fraction of
# its upper-hemisphere directions (see _split_where_partly_visible).
_SPLIT_FRACTION = 0.05
# Directions (rows of a group's factor matrix) taken at a time where a factorisation is tried.
_DIRECTION_ROWS = 512
# A shading class of a lobed material is merged into coarser bins (2, 4, ... times its own) in a
# frame where the bin is at most this fraction of its normal's angle from the half vector: there
# the lobe's tail varies slowly across the bin, and a smooth surface's classes tile it as a
# midpoint rule does (see _coarse_classes and docs/renderer.md). SceneCache.build's
# coarse_bin_ratio; 0 never merges.
_COARSE_BIN_RATIO = 1.0 / 6.0
# Coarse bins stop at the bin of a diffuse material (its step over the bins per step).
_DIFFUSE_STEP_DEG = 15.0
# A mixed (element, frame) pair of a pure-lobe material gets no exact ray where all its normals
# are more than this many lobe widths further from the half vector than the frame's nearest
# lobed class: its bits' bilinear interpolation counts it (see _far_elements). SceneCache.build's
# far_lobe_widths; inf: always rays.
_FAR_LOBES = 4.0


def cube_grid_directions(grid_size):
    """Unit directions of the equal-angle cube map, shape (6 (N + 1)**2, 3)."""
    n = grid_size
    angle = np.linspace(-math.pi / 4.0, math.pi / 4.0, n + 1)
    a, b = np.meshgrid(np.tan(angle), np.tan(angle), indexing="ij")
    faces = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            d = np.zeros(a.shape + (3,))
            d[..., axis] = sign
            d[..., (axis + 1) % 3] = a
            d[..., (axis + 2) % 3] = b
            faces.append(d.reshape(-1, 3))
    directions = np.concatenate(faces)
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


def cube_grid_weights(directions, grid_size):
    """Bilinear interpolation of the cube map at ``directions`` (m, 3).

    Returns
    -------
    index : (m, 4) int, grid direction indices.
    weight : (m, 4) float, weights summing to 1.
    """
    n = grid_size
    d = np.asarray(directions, dtype=float)
    axis = np.argmax(np.abs(d), axis=1)
    rows = np.arange(len(d))
    major = d[rows, axis]
    face = 2 * axis + (major < 0.0)
    a = d[rows, (axis + 1) % 3] / np.abs(major)
    b = d[rows, (axis + 2) % 3] / np.abs(major)
    fa = (np.arctan(a) + math.pi / 4.0) / (math.pi / 2.0) * n
    fb = (np.arctan(b) + math.pi / 4.0) / (math.pi / 2.0) * n
    ia = np.clip(np.floor(fa).astype(np.int64), 0, n - 1)
    ib = np.clip(np.floor(fb).astype(np.int64), 0, n - 1)
    ta, tb = np.clip(fa - ia, 0.0, 1.0), np.clip(fb - ib, 0.0, 1.0)
    base = face * (n + 1) ** 2
    index = np.stack(
        [
            base + ia * (n + 1) + ib,
            base + (ia + 1) * (n + 1) + ib,
            base + ia * (n + 1) + ib + 1,
            base + (ia + 1) * (n + 1) + ib + 1,
        ],
        axis=1,
    )
    weight = np.stack([(1 - ta) * (1 - tb), ta * (1 - tb), (1 - ta) * tb, ta * tb], axis=1)
    return index, weight


def _bisect(corners, normals, owner, too_big):
    """Split triangles at the midpoint of their longest edge until ``too_big`` says none is.

    Parameters
    ----------
    corners : (n, 3, 3) float, corner positions.
    normals : (n, 3, 3) float, corner shading normals, not renormalised: a midpoint takes the
        mean of its edge's two, so any point's normal is the barycentric interpolation the
        renderers use.
    owner : (n,) int, carried to the pieces.
    too_big : callable ``too_big(corners, normals, owner) -> (n,) bool``.

    Returns
    -------
    corners, normals, owner of the pieces. Slivers are cut across their length only, so a
    long thin triangle becomes a row of pieces, not a grid.
    """
    done = []
    for _ in range(_MAX_BISECTIONS):
        split = too_big(corners, normals, owner)
        done.append((corners[~split], normals[~split], owner[~split]))
        corners, normals, owner = corners[split], normals[split], owner[split]
        if len(corners) == 0:
            break
        edge = np.stack([np.linalg.norm(corners[:, (k + 1) % 3] - corners[:, k], axis=1) for k in range(3)], axis=1)
        k = np.argmax(edge, axis=1)
        rows = np.arange(len(k))
        a, b, c = k, (k + 1) % 3, (k + 2) % 3
        mid = 0.5 * (corners[rows, a] + corners[rows, b])
        mid_normal = 0.5 * (normals[rows, a] + normals[rows, b])
        first = np.stack([corners[rows, a], mid, corners[rows, c]], axis=1)
        second = np.stack([mid, corners[rows, b], corners[rows, c]], axis=1)
        first_n = np.stack([normals[rows, a], mid_normal, normals[rows, c]], axis=1)
        second_n = np.stack([mid_normal, normals[rows, b], normals[rows, c]], axis=1)
        corners = np.concatenate([first, second])
        normals = np.concatenate([first_n, second_n])
        owner = np.concatenate([owner, owner])
    else:
        done.append((corners, normals, owner))
    return tuple(np.concatenate([d[i] for d in done]) for i in range(3))


def _pieces(corners, normals, too_big, chunk=4096):
    """Shading pieces of triangles (:func:`_bisect` of ``chunk`` triangles at a time, so the
    pieces' corners are never all held): each piece's unit mean shading normal (p, 3), its
    area (p,) and the index of its triangle (p,)."""
    parts = []
    for begin in range(0, len(corners), chunk):
        end = min(begin + chunk, len(corners))
        c, n, parent = _bisect(corners[begin:end], normals[begin:end], np.arange(begin, end), too_big)
        mean = n.mean(axis=1)
        mean /= np.linalg.norm(mean, axis=1, keepdims=True)
        area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
        parts.append((mean, area, parent))
    if not parts:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=np.int64)
    return tuple(np.concatenate([part[i] for part in parts]) for i in range(3))


def _longest_edge_m(corners):
    """(n,) float, the longest edge of each triangle."""
    return np.max([np.linalg.norm(corners[:, (k + 1) % 3] - corners[:, k], axis=1) for k in range(3)], axis=0)


def _normal_spread_rad(normals):
    """(n,) float, the largest angle between two corner shading normals of each triangle."""
    unit = normals / np.linalg.norm(normals, axis=2, keepdims=True)
    cosines = [np.einsum("ij,ij->i", unit[:, a], unit[:, b]) for a, b in ((0, 1), (1, 2), (2, 0))]
    return np.arccos(np.clip(np.min(cosines, axis=0), -1.0, 1.0))


@dataclass(frozen=True, eq=False)
class _Pose:
    """Elements of one articulation pose."""

    normal_shade: np.ndarray  # (g, 3) float32 area-weighted mean shading normal per group
    group_class: np.ndarray  # (g,) int32: each group's shading class
    n_classes: int
    normal_geo: np.ndarray  # (g, 3) float32 per group
    area_exposed: np.ndarray  # (g,) float32 merged area of exposed elements
    factors: np.ndarray  # (d, r) float32 visibility factors, direction-major (see _visibility_factors)
    factor_starts: np.ndarray  # (k,) int64: first factor column of each factorised group
    factor_groups: np.ndarray  # (k,) int64: and that group
    raw_bits: np.ndarray  # (d, ceil(e / 64)) uint64: visibility bits of elements not factorised
    raw_count: int  # e, elements held as bits
    raw_area: object  # (g, e) CSC float32: area of each element's pieces in each group
    raw_corners: np.ndarray  # (e, 3, 3) float32: the bit-held elements' corners (ray origins)
    raw_normals: np.ndarray  # (e, 3) float32: and their geometric normals
    gap_ptr: np.ndarray  # (d + 1,) int64: CSR by node of the bit-held elements' gap nodes (_horizon_gaps, _slit_gaps)
    gap_word: np.ndarray  # (q,) int64: their words
    gap_mask: np.ndarray  # (q,) uint64: and bit masks
    vertices_m: np.ndarray  # (3t, 3) float32: the posed triangles' corners, for exact visibility rays
    ray_offset_m: float  # how far above its element a visibility ray starts
    n_elements: int
    n_occludable: int  # occludable elements before factorisation
    n_rays: int
    class_normal: np.ndarray  # (c, 3) float32: each class's nominal shading normal (area-weighted mean)
    class_lobed: np.ndarray  # (c,) bool: its material is a pure lobe (_pure_lobe)
    class_target: np.ndarray  # (l, c) int32: its coarse class at each coarser level (_coarse_classes)
    coarse_cos: np.ndarray  # (materials, l) float64: cosines to the half vector below which a level is taken
    target_material: np.ndarray  # (n_targets,) int32: the material of each class, then of each coarse class
    element_normal: np.ndarray  # (e, 3) float32: the bit-held elements' area-weighted mean shading normal
    element_far: np.ndarray  # (e, 3) float32: how far beyond the nearest lobe a pair needs no ray (-1: always
    # one), its cosine and sine


@dataclass(frozen=True, eq=False)
class SceneCache:
    """Precomputed elements and visibility of a scene; :meth:`intensity` is the fast renderer.

    Build with :meth:`build`. Attributes describe the settings and the one-off cost.
    """

    scene: Scene
    poses: tuple
    parameter: str | None
    parameter_values: np.ndarray
    grid_size: int
    element_size_m: float
    normal_step_deg: float
    sun_samples: tuple
    edge_rays_per_side: int
    precompute_s: float
    normal_bins_per_step: float = _NORMAL_BINS_PER_STEP
    coarse_bin_ratio: float = _COARSE_BIN_RATIO
    far_lobe_widths: float = _FAR_LOBES
    _grid: dict = field(default_factory=dict, repr=False)

    @classmethod
    def build(
        cls,
        scene,
        accuracy_mag=0.01,
        element_size_m=None,
        normal_step_deg=None,
        normal_bins_per_step=_NORMAL_BINS_PER_STEP,
        grid_size=32,
        articulation_grid=None,
        sun_samples=None,
        edge_rays_per_side=1,
        coarse_bin_ratio=_COARSE_BIN_RATIO,
        far_lobe_widths=_FAR_LOBES,
        progress=False,
    ) -> SceneCache:
        """Precompute the elements and visibility of ``scene``.

        Parameters
        ----------
        scene : Scene
        accuracy_mag : float, used for the defaults below.
        element_size_m : float, optional, largest element on shadowable sides
            (default: the mesh radius / 30, and half that on smooth-shaded triangles of a
            glossy material, see :func:`_glossy_strip`).
        normal_step_deg : float, optional, largest shading-normal change within an element of
            smooth-shaded triangles (default per material: half its specular lobe width alpha,
            between 0.5 and 3 deg; 15 deg for diffuse materials).
        normal_bins_per_step : float, shading classes bin the shading normals in cells of
            the normal step divided by this (default 3). Each class is shaded at its lit
            groups' mean normal in every frame, so the error is second order in the cell. 1
            runs the all-Glossy paper mesh 4x faster (57 000 classes become 8 500) at 0.0047
            against 0.0032 mag RMS from the direct renderer on tumble frames; a smooth
            metallic cylinder's glints move by 0.004 mag (docs/renderer.md).
        grid_size : int, cube-map resolution N (directions about 90/N deg apart).
        articulation_grid : dict, optional, ``{parameter: values}`` for one articulation parameter.
        sun_samples : int, optional, solar-disk samples in the BRDF of every material (default
            per material from its lobe width, see :func:`raycast.renderer.direct.sun_samples_for`).
        edge_rays_per_side : int, where a shadow or horizon edge crosses an element (its
            visibility bits differ at the grid nodes around a direction), rays toward the exact
            direction decide from k x k points spread over it (default 1: its centroid; 2 takes
            partial shadow into account, at about 4x the run time on COSMOS 2502).
        coarse_bin_ratio : float in [0, 1), a class of a lobed material is shaded in a bin 2, 4,
            ... times its own in a frame where that bin is at most this fraction of its angle
            from the half vector (default 1/6; 0: never). Larger is faster and less exact on
            glints: 1/3 shades the all-Glossy paper mesh's 150 tumble frames in 70 000 rows
            instead of 154 000, 0.0002 mag further from the direct renderer.
        far_lobe_widths : float, a mixed (element, frame) pair of a pure-lobe material whose
            normals are all this many lobe widths further from the half vector than the frame's
            nearest lobed class gets no exact rays: its bits' interpolation counts it (default
            4; inf: never). With 1/3 above, 2 casts 41 000 rays there instead of 69 000 at 3
            (elements radius / 30, 2 x 2 edge rays), the light curve the same to 0.0001 mag.
        progress : bool, show a progress bar over the visibility rays.
        """
        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be a raycast.renderer.scene.Scene, not {type(scene).__name__}")
        if not (isinstance(grid_size, (int, np.integer)) and 4 <= grid_size <= 256):
            raise ValueError(f"grid_size={grid_size!r} must be an integer in [4, 256]")
        if not (
            _is_number(normal_bins_per_step) and math.isfinite(normal_bins_per_step) and normal_bins_per_step >= 1.0
        ):
            raise ValueError(f"normal_bins_per_step={normal_bins_per_step!r} must be a number >= 1")
        if not (isinstance(edge_rays_per_side, (int, np.integer)) and 1 <= edge_rays_per_side <= 8):
            raise ValueError(f"edge_rays_per_side={edge_rays_per_side!r} must be an integer in [1, 8]")
        if not (_is_number(coarse_bin_ratio) and 0.0 <= coarse_bin_ratio < 1.0):
            raise ValueError(f"coarse_bin_ratio={coarse_bin_ratio!r} must be a number in [0, 1)")
        if not (_is_number(far_lobe_widths) and far_lobe_widths >= 0.0):
            raise ValueError(f"far_lobe_widths={far_lobe_widths!r} must be a number >= 0 (inf: never)")
        start = time.perf_counter()
        mesh = scene.posed()
        glossy_element_m = None
        if element_size_m is None:
            element_size_m = mesh.radius_m / 30.0
            glossy_element_m = element_size_m / 2.0
        if not (math.isfinite(element_size_m) and element_size_m > 0.0):
            raise ValueError(f"element_size_m={element_size_m!r} must be a positive number of metres")
        sun_samples = tuple(
            sun_samples_for(b, accuracy_mag) if sun_samples is None else int(sun_samples) for b in scene.brdfs
        )
        parameter, values = None, np.zeros(0)
        if articulation_grid:
            if len(articulation_grid) != 1:
                raise ValueError(f"articulation_grid={articulation_grid!r} must name exactly one parameter")
            parameter, raw = next(iter(articulation_grid.items()))
            values = np.unique(np.asarray(raw, dtype=float))
            if len(values) < 1 or not np.all(np.isfinite(values)):
                raise ValueError(f"articulation_grid[{parameter!r}] must hold finite values")
            scenes = [scene.with_parameters(**{parameter: v}) for v in values]
        else:
            scenes = [scene]
        directions = cube_grid_directions(grid_size)
        steps = np.array([_normal_step_rad(b, normal_step_deg) for b in scene.brdfs])
        tolerance = accuracy_mag / 1.0857 / 10.0
        quanta = np.array(
            [_normal_quantum_rad(b, step, normal_step_deg, normal_bins_per_step) for b, step in zip(scene.brdfs, steps)]
        )
        sizes = (element_size_m, glossy_element_m)
        # Coarse shading classes stop at a diffuse material's bin (_coarse_classes).
        cap = _normal_quantum_rad(None, math.radians(_DIFFUSE_STEP_DEG), None, normal_bins_per_step)
        tail = _LobeTail(cap, float(coarse_bin_ratio), float(far_lobe_widths))
        poses = tuple(_build_pose(s, directions, sizes, steps, quanta, tail, tolerance, progress) for s in scenes)
        return cls(
            scene,
            poses,
            parameter,
            values,
            grid_size,
            float(element_size_m),
            float(np.degrees(steps.min())),
            sun_samples,
            int(edge_rays_per_side),
            time.perf_counter() - start,
            float(normal_bins_per_step),
            float(coarse_bin_ratio),
            float(far_lobe_widths),
        )

    # ------------------------------------------------------------------ run time
    def intensity(self, sun_body, obs_body, **parameters):
        """I/E in m^2/sr for each direction pair.

        Parameters
        ----------
        sun_body : (m, 3) float, unit vectors toward the Sun, body frame.
        obs_body : (m, 3) float, unit vectors toward the observer, body frame.
        **parameters : the articulation parameter this cache was built over, e.g.
            ``panel_pitch_deg=14``; other parameters must equal the scene's.

        Returns
        -------
        (m,) float
        """
        sun_body, obs_body = check_directions(sun_body, obs_body)
        for key, value in parameters.items():
            if key != self.parameter and float(value) != float(self.scene.parameters.get(key, math.nan)):
                raise ValueError(
                    f"this cache was built for {key}={self.scene.parameters.get(key)!r} only; rebuild it with "
                    f"articulation_grid={{{key!r}: [...]}} to vary {key}"
                )
        if self.parameter is None:
            return self._pose_intensity(self.poses[0], sun_body, obs_body)
        value = float(parameters.get(self.parameter, self.scene.parameters[self.parameter]))
        grid = self.parameter_values
        if not grid[0] - 1e-9 <= value <= grid[-1] + 1e-9:
            raise ValueError(
                f"{self.parameter}={value} is outside the cached range [{grid[0]}, {grid[-1]}]; "
                "rebuild the cache with a wider articulation_grid"
            )
        if len(grid) == 1:
            return self._pose_intensity(self.poses[0], sun_body, obs_body)
        upper = int(np.clip(np.searchsorted(grid, value), 1, len(grid) - 1))
        t = (value - grid[upper - 1]) / (grid[upper] - grid[upper - 1])
        low = self._pose_intensity(self.poses[upper - 1], sun_body, obs_body) if t < 1.0 else 0.0
        high = self._pose_intensity(self.poses[upper], sun_body, obs_body) if t > 0.0 else 0.0
        return (1.0 - t) * low + t * high

    def _pose_intensity(self, pose, sun, obs):
        """(m,) I/E: batches of frames in parallel threads (the compiled loops release the GIL),
        with the exact rays of the batches running together in one call (Embree uses every core)."""
        total = np.zeros(len(sun))
        origins = _ray_origins(pose, _subpoint_weights(self.edge_rays_per_side))
        every = _Frames.of(sun, obs, self.grid_size)

        def pairs_of(sl):
            return _pairs_to_decide(pose, every[sl], origins)

        def shade(sl, pairs, occluded):
            frames = every[sl]
            lit = _lit_classes(pose, frames, self.grid_size, pairs, occluded, origins.shape[1], _thread_rows())
            total[sl] = self._shaded(pose, *lit, frames.sun, frames.obs)

        # A scene without bit-held elements (a convex one) shades in well under a millisecond:
        # handing its batches to threads would cost more than it saves.
        threads = _threads() if pose.raw_count else 1
        batches = _frame_batches(len(sun), threads, _chunk_frames(pose.n_classes))
        run = _executor(threads).map if threads > 1 and len(batches) > 1 else map
        for begin in range(0, len(batches), threads):
            running = batches[begin : begin + threads]
            pairs = list(run(pairs_of, running))
            occluded = _occluded(pose, [p.rays for p in pairs], threads)
            list(run(shade, running, pairs, occluded))
        return total

    def _shaded(self, pose, frames, classes, area, normal, geo, sun, obs):
        """(m,) I/E of the lit classes (:func:`_lit_classes`): each material's (frame, class)
        pairs shaded at the class's mean shading and geometric normals
        (raycast.renderer.shading.shaded_pairs)."""
        total = np.zeros(len(sun))
        bend = self.scene.specular_normals == "cycles"
        sun_u, sun_v = orthonormal_basis(sun)
        per_pair = [np.ascontiguousarray(a, dtype=float) for a in (area, normal, geo)]
        of_row = pose.target_material[classes]
        for material in np.unique(of_row):
            rows = np.flatnonzero(of_row == material)
            shaded_pairs(
                self.scene.brdfs[material],
                self.sun_samples[material],
                rows,
                frames,
                frames,
                *per_pair,
                obs,
                sun,
                sun_u,
                sun_v,
                bend,
                total,
            )
        return total

    @property
    def n_elements(self) -> int:
        """Elements of the first pose (exposed groups + occludable elements)."""
        return self.poses[0].n_elements

    @property
    def nbytes(self) -> int:
        """Memory held by the poses' arrays (visibility tables, elements, ray-casting triangles)."""
        total = 0
        for pose in self.poses:
            total += sum(
                getattr(pose, f.name).nbytes
                for f in dataclasses.fields(pose)
                if isinstance(getattr(pose, f.name), np.ndarray)
            )
            total += pose.raw_area.data.nbytes + pose.raw_area.indices.nbytes + pose.raw_area.indptr.nbytes
        return int(total)


def _threads():
    """Threads the run time shades a light curve with: the cores this process may use, or one
    where ``OMP_NUM_THREADS=1`` says the process is one of several workers
    (rsodb.pool.SINGLE_THREAD_ENV)."""
    if os.environ.get("OMP_NUM_THREADS") == "1":
        return 1
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


_EXECUTOR = (None, 0, None)  # (process id, threads, ThreadPoolExecutor)


def _executor(threads):
    """The run time's pool of ``threads`` threads, made once per process (a forked child makes
    its own: threads do not survive a fork). Starting threads at every call cost ~3 ms a light
    curve on COSMOS 2502."""
    global _EXECUTOR
    pid, size, executor = _EXECUTOR
    if pid != os.getpid() or size < threads:
        executor = ThreadPoolExecutor(threads, thread_name_prefix="rsodb-cache")
        _EXECUTOR = (os.getpid(), threads, executor)
    return executor


def _chunk_frames(n_classes):
    """Frames per batch for a pose of `n_classes` shading classes (see _FRAMES_PER_CHUNK)."""
    low, high = _FRAMES_PER_CHUNK
    return int(np.clip(_LIT_ROWS_PER_CHUNK // max(n_classes, 1), low, high))


def _frame_batches(m, threads, chunk):
    """Slices of the m frames: contiguous, at most `chunk` long, and one per thread (each at
    least _MIN_FRAMES_PER_THREAD) where there are enough frames."""
    n = max(-(-m // chunk), min(threads, m // _MIN_FRAMES_PER_THREAD), 1)
    edges = np.linspace(0, m, n + 1).round().astype(int)
    return [slice(a, b) for a, b in itertools.pairwise(edges)]


def _exposed_sides(vertices, corners, normals, tolerance):
    """(t, 2) bool: no vertex lies above the plane of this triangle side (+ normal, - normal).

    Such a plane supports the convex hull of the mesh, so the test is a lookup of the side's
    plane among the hull's facet planes (Qhull); a flat mesh has no hull and both sides of
    every triangle are exposed.
    """
    offsets = np.einsum("ij,ij->i", corners[:, 0], normals)
    scale = float(np.abs(vertices).max()) or 1.0
    try:
        hull = ConvexHull(vertices)
    except QhullError:
        return np.ones((len(corners), 2), dtype=bool)
    # Hull facets: n . x + c <= 0 inside, so the plane is n . x = -c.
    planes = np.column_stack([hull.equations[:, :3], -hull.equations[:, 3] / scale])
    tree = cKDTree(planes)
    exposed = np.zeros((len(corners), 2), dtype=bool)
    for side, sign in ((0, 1.0), (1, -1.0)):
        keys = np.column_stack([sign * normals, sign * offsets / scale])
        distance, _ = tree.query(keys, distance_upper_bound=1e-5)
        exposed[:, side] = np.isfinite(distance)
    return exposed


_RAYCASTERS = weakref.WeakKeyDictionary()


@functools.cache
def _subpoint_weights(per_side: int) -> np.ndarray:
    """(per_side**2, 3) barycentric weights of the centroids of a triangle cut into per_side**2."""
    points = []
    for i in range(per_side):
        for j in range(per_side - i):
            points.append((i + 1 / 3, j + 1 / 3))
            if i + j < per_side - 1:
                points.append((i + 2 / 3, j + 2 / 3))
    uv = np.array(points) / per_side
    return np.column_stack([1.0 - uv.sum(axis=1), uv]).astype(np.float32)


_ORIGINS = weakref.WeakKeyDictionary()


def _ray_origins(pose, edge_weights):
    """(e, k, 3) float32: the bit-held elements' points at the barycentric ``edge_weights``
    (k, 3), lifted clear of their triangle; computed once per pose and setting."""
    per_pose = _ORIGINS.setdefault(pose, {})
    key = edge_weights.tobytes()
    if key not in per_pose:
        origins = np.einsum("kc,ecx->ekx", edge_weights, pose.raw_corners)
        origins += np.float32(pose.ray_offset_m) * pose.raw_normals[:, None, :]
        per_pose[key] = np.ascontiguousarray(origins, dtype=np.float32)
    return per_pose[key]


_BYTE_AREAS = weakref.WeakKeyDictionary()


def _byte_areas(pose):
    """The pose's tables of bytes of bit-held elements in one group
    (:func:`raycast.renderer._cache_kernels.byte_areas`), made on first use in each process
    (a few milliseconds; 128 bytes an element at most, so they are not stored)."""
    if pose not in _BYTE_AREAS:
        area = pose.raw_area
        _BYTE_AREAS[pose] = _cache_kernels.byte_areas(area.indptr, area.indices, area.data, pose.raw_bits.shape[1])
    return _BYTE_AREAS[pose]


def _raycaster(pose):
    """The pose's Open3D scene, built on first use in each process (it does not pickle)."""
    if pose not in _RAYCASTERS:
        _RAYCASTERS[pose] = open3d_scene(pose)  # the pose's vertices_m is a triangle soup, as a mesh's
    return _RAYCASTERS[pose]


def _ray_offset_m(mesh):
    """Visibility rays start this far above their element (clear of its own triangle)."""
    return 1e-4 * max(mesh.radius_m, 1.0)


@dataclass(frozen=True, eq=False)
class _Frames:
    """A light curve's directions as the run time's loops read them; ``frames[sl]`` is a batch."""

    sun: np.ndarray  # (m, 3) float64 unit vectors, body frame
    obs: np.ndarray
    sun32: np.ndarray  # the same in float32
    obs32: np.ndarray
    sun_nodes: np.ndarray  # (m, 4) int64, the cube-map nodes around each direction
    obs_nodes: np.ndarray
    sun_weights: np.ndarray  # (m, 4) float64, their bilinear weights
    obs_weights: np.ndarray

    @classmethod
    def of(cls, sun, obs, grid_size):
        # Once for the whole light curve: per batch, numpy's call overhead was ~4 ms of a whole
        # TOPEX pass's 140 ms (19 batches of 256 frames).
        (sun_nodes, sun_weights), (obs_nodes, obs_weights) = (cube_grid_weights(d, grid_size) for d in (sun, obs))
        thin = (np.ascontiguousarray(d, dtype=np.float32) for d in (sun, obs))
        nodes = (n.astype(np.int64) for n in (sun_nodes, obs_nodes))
        weights = (np.ascontiguousarray(w, dtype=float) for w in (sun_weights, obs_weights))
        return cls(sun, obs, *thin, *nodes, *weights)

    def __getitem__(self, sl):
        return _Frames(*(getattr(self, f.name)[sl] for f in dataclasses.fields(self)))


@dataclass(frozen=True, eq=False)
class _FramePairs:
    """A batch's (frame, element) pairs to decide by exact rays (:func:`_pairs_to_decide`)."""

    frames: np.ndarray  # (p,) int64, in frame order
    elements: np.ndarray  # (p,) int64
    need: np.ndarray  # (p,) uint8, see raycast.renderer._cache_kernels.mixed_pairs (0 where blended)
    blend: np.ndarray  # (p,) float32, the interpolated visibility of pairs far from every lobe, -1 for the others
    rays: np.ndarray  # (r, 6) float32, raycast.renderer._cache_kernels.pair_rays


def _pairs_to_decide(pose, batch, origins):
    """A ``batch`` of :class:`_Frames`' bit-held (element, frame) pairs that exact rays decide, and those rays.

    Where an element's bits at the four grid nodes around the Sun and the four around the
    observer are all set (98% of visible pairs on COSMOS 2502) it counts whole; where they
    differ, a shadow or horizon edge crosses the grid cell and bilinear mixing of the bits would
    smear it: rays toward the exact direction decide, from the element's points ``origins``
    (e, k, 3) (:func:`_ray_origins`; :func:`_lit_classes` counts the element by the fraction
    of them both lit and seen, as the direct renderer's shadow rays). Elements facing away from
    the exact Sun or observer get no rays. So do pairs near a gap in the bits narrower than the
    grid (:func:`_horizon_gaps`). Pairs whose element's pure-lobe normals are all far from the
    frame's half vector get none either: the interpolation of their bits counts them
    (:func:`_far_elements`, :func:`raycast.renderer._cache_kernels.far_pairs`).
    """
    sun32, obs32, sun_nodes, obs_nodes = batch.sun32, batch.obs32, batch.sun_nodes, batch.obs_nodes
    frames, elements = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    need, rays = np.zeros(0, dtype=np.uint8), np.zeros((0, 6), dtype=np.float32)
    blend = np.zeros(0, dtype=np.float32)
    if pose.raw_count:
        frames, elements, need = _cache_kernels.mixed_pairs(
            pose.raw_bits, sun_nodes, obs_nodes, sun32, obs32, pose.raw_normals
        )
        if len(pose.gap_word):
            gap = _cache_kernels.gap_pairs(
                pose.raw_bits,
                pose.gap_ptr,
                pose.gap_word,
                pose.gap_mask,
                sun_nodes,
                obs_nodes,
                sun32,
                obs32,
                pose.raw_normals,
            )
            if len(gap[0]):
                frames, elements, need = _cache_kernels.merged_by_frame((frames, elements, need), gap)
        blend = np.full(len(frames), -1.0, dtype=np.float32)
        if len(frames) and np.any(pose.element_far[:, 0] >= 0.0):
            nearest = _cache_kernels.nearest_lobes(pose.class_normal, pose.class_lobed, batch.sun, batch.obs)
            need, blend = _cache_kernels.far_pairs(
                need,
                frames,
                elements,
                pose.raw_bits,
                sun_nodes,
                batch.sun_weights,
                obs_nodes,
                batch.obs_weights,
                pose.element_normal,
                pose.element_far,
                batch.sun,
                batch.obs,
                nearest,
            )
        if len(frames):
            rays = _cache_kernels.pair_rays(need, frames, elements, origins, pose.raw_normals, sun32, obs32)
    return _FramePairs(frames, elements, need, blend, rays)


def _occluded(pose, rays, threads):
    """Each of a list of (r, 6) ray arrays' occlusion flags, from one call to Embree on
    ``threads`` threads (1 in a pool's worker: the other cores are the other workers')."""
    counts = [len(r) for r in rays]
    if not sum(counts):
        return [np.zeros(0, dtype=bool) for _ in rays]
    flags = _raycaster(pose).test_occlusions(np.concatenate(rays), nthreads=1 if threads == 1 else 0).numpy()
    return np.split(flags, np.cumsum(counts)[:-1])


def _thread_rows():
    """This thread's :class:`raycast.renderer._cache_kernels.RowBuffers` (the run time's
    threads each shade one batch at a time, and use its rows before the next)."""
    rows = getattr(_ROWS, "buffers", None)
    if rows is None:
        rows = _ROWS.buffers = _cache_kernels.RowBuffers()
    return rows


_ROWS = threading.local()


def _lit_classes(pose, frames, grid_size, pairs, occluded, k, rows=None):
    """Each frame's shading classes with light (:func:`raycast.renderer._cache_kernels.lit_classes`).

    ``frames`` a batch of :class:`_Frames`; ``pairs`` its :func:`_pairs_to_decide` and its
    rays' ``occluded`` flags, ``k`` rays a pair and way. Returns (k,) frames and classes, the
    classes' lit, seen and projected areas (k,), and their mean shading and geometric normals
    (k, 3), weighted by those areas in each frame (so a class shared by faces that are gated or
    shadowed differently is shaded where its light comes from). Factorised groups add the
    product of their interpolated factors. ``rows``: buffers to write into
    (:func:`_thread_rows`; the arrays returned are then views of them).
    """
    m = len(frames.sun)
    area = pose.raw_area
    open_ = np.zeros(0, dtype=np.float32)
    if len(pairs.frames):
        open_ = _cache_kernels.open_fraction(pairs.need, occluded, k, pairs.blend)
    factor_weight = np.zeros((m, 0), dtype=np.float32)
    if pose.factors.shape[1]:
        product = _interpolation_matrix(frames.sun, grid_size, len(pose.factors)) @ pose.factors
        product *= _interpolation_matrix(frames.obs, grid_size, len(pose.factors)) @ pose.factors
        factor_weight = np.ascontiguousarray(np.add.reduceat(product, pose.factor_starts, axis=1))
    return _cache_kernels.lit_classes(
        pose.raw_bits,
        frames.sun_nodes,
        frames.obs_nodes,
        area.indptr,
        area.indices,
        area.data,
        *_byte_areas(pose),
        pairs.frames,
        pairs.elements,
        open_,
        pose.area_exposed,
        factor_weight,
        pose.factor_groups,
        pose.normal_geo,
        pose.normal_shade,
        pose.group_class,
        frames.sun32,
        frames.obs32,
        pose.n_classes,
        pose.class_normal,
        pose.target_material,
        pose.coarse_cos,
        pose.class_target,
        len(pose.target_material),
        rows=rows,
    )


def _interpolation_matrix(directions, grid_size, n_directions):
    """Bilinear interpolation on the cube map as a sparse (m, d) float32 matrix (4 entries a row)."""
    index, weight = cube_grid_weights(directions, grid_size)
    m = len(directions)
    return sparse.csr_matrix(
        (weight.astype(np.float32).reshape(-1), index.reshape(-1), np.arange(0, 4 * m + 1, 4)), shape=(m, n_directions)
    )


def _normal_step_rad(brdf, normal_step_deg):
    """Largest shading-normal change within one element for this material."""
    if normal_step_deg is not None:
        return math.radians(normal_step_deg)
    if brdf is None or not brdf.lobe_width_rad:
        # Diffuse shading is linear in the normal except where the cosine clips at the
        # terminator, so an element's mean normal is exact away from it.
        return math.radians(15.0)
    # A glossy lobe needs pieces of at most half its width, capped at 3 deg; a weak lobe on a
    # diffuse base (Principled dielectric, F0 0.04) only half its width.
    cap = 3.0 if brdf.lobe_share > _WEAK_LOBE_SHARE else 15.0
    return math.radians(float(np.clip(math.degrees(brdf.lobe_width_rad) / 2.0, 0.5, cap)))


def _normal_quantum_rad(brdf, step_rad, normal_step_deg, bins_per_step=_NORMAL_BINS_PER_STEP):
    """Bin width of shading normals merged into one shading class for this material.

    The piece step over ``bins_per_step`` (by default a third of it); for a weak lobe on a
    diffuse base (lobe share under 20%, e.g. Principled dielectric with F0 0.04), half the lobe
    when that is wider: such a BRDF varies little over 7 deg at roughness 0.5, and a
    smooth-shaded tube's pieces then fall into thousands of groups instead of a hundred
    thousand. (A class is shaded at the per-frame weighted normal of its groups, so the error
    stays second order in the bin.)
    """
    if normal_step_deg is not None or brdf is None or not brdf.lobe_width_rad or brdf.lobe_share > _WEAK_LOBE_SHARE:
        return step_rad / bins_per_step
    return max(step_rad / bins_per_step, brdf.lobe_width_rad / 2.0)


def _build_pose(
    scene, directions, element_sizes_m, normal_step_rad, normal_quantum_rad, tail, factor_tolerance, progress
):
    mesh = scene.posed()
    element_size_m, glossy_element_m = element_sizes_m
    size_m = np.full(len(mesh.face_normals), element_size_m)
    if glossy_element_m is not None:
        size_m[_glossy_strip(scene, mesh)] = glossy_element_m
    corners, n_geo = mesh.corners_m, mesh.face_normals
    vertices = np.unique(np.round(mesh.vertices_m, 9), axis=0)
    tolerance = 1e-6 * max(mesh.radius_m, 1.0)
    exposed = _exposed_sides(vertices, corners, n_geo, tolerance)
    inner = mesh.inner_sides()
    # Visibility is sampled on *elements* of about element_size_m (their longest edge at most
    # sqrt(2) times that: a right triangle with legs element_size_m; shadows are spatial);
    # shading on *pieces* of elements small enough that the interpolated normal turns by at
    # most the material's step within one (the cosine and glints are angular). A piece takes
    # the visibility of its element. Both are cut by longest-edge bisection, so the long thin
    # triangles of a smooth-shaded tube become rows of pieces.
    step = normal_step_rad[mesh.material_index]
    el_corners, el_normals, el_tri, el_side = [], [], [], []
    for side in (0, 1):
        tris = np.flatnonzero(~inner[:, side])
        if len(tris) == 0:
            continue
        # Elements: only the sides that can be shadowed need visibility, so only they are cut by size.
        c, n, t = _bisect(
            corners[tris],
            mesh.corner_normals[tris],
            tris,
            lambda c, n, t: ~exposed[t, side] & (_longest_edge_m(c) > math.sqrt(2.0) * size_m[t]),
        )
        el_corners.append(c)
        el_normals.append(n)
        el_tri.append(t)
        el_side.append(np.full(len(t), side))
    el_corners, el_normals = np.concatenate(el_corners), np.concatenate(el_normals)
    el_tri, el_side = np.concatenate(el_tri), np.concatenate(el_side)
    el_exposed = exposed[el_tri, el_side]
    visibility = np.zeros((0, -(-len(directions) // 8)), dtype=np.uint8)
    row_of, seen, blocked = np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, bool)
    n_rays = 0
    # Two grid spacings: every node a grazing direction interpolates from.
    band = math.sin(2.0 * _grid_spacing_rad(directions))
    if not el_exposed.all():
        (el_corners, el_normals, el_tri, el_side, el_exposed, (visibility, row_of, seen, blocked), n_rays) = (
            _split_where_partly_visible(
                mesh, el_corners, el_normals, el_tri, el_side, el_exposed, n_geo, directions, band, progress
            )
        )
    parent_geo = _side_normals(n_geo, el_tri, el_side)
    # Pieces: cut from the elements until the shading normal turns by at most the material's step.
    normals, area, piece_parent = _pieces(
        el_corners, el_normals, lambda c, n, p: _normal_spread_rad(n) > step[el_tri[p]]
    )
    del el_normals
    el_corners = el_corners.astype(np.float32)  # read from here on only as the raw elements' corners, in 32 bits
    tri, geo = el_tri[piece_parent], parent_geo[piece_parent]
    normals[np.einsum("ij,ij->i", normals, geo) < 0.0] *= -1.0
    is_exposed = el_exposed[piece_parent]
    el = dict(
        normal=normals,
        geo=geo,
        area=area,
        material=mesh.material_index[tri],
        exposed=is_exposed,
        parent=np.where(is_exposed, -1, piece_parent),
    )
    # Only el is read from here on: the build's peak memory comes later, with the tables.
    del piece_parent, tri, geo, normals, area, is_exposed
    # Only the visibility elements of sides that are not exposed were cast; they come first, so
    # an element's index is its place in seen and blocked, and row_of[element] its row of
    # visibility (kept only for the elements both seen and blocked somewhere).
    cast = np.flatnonzero(~el_exposed)
    if len(cast):
        of_element = el["parent"].copy()
        occludable = of_element >= 0
        # Never blocked: exposed after all. Never seen: dropped.
        never_blocked = occludable & ~blocked[np.maximum(of_element, 0)]
        el["exposed"][never_blocked] = True
        drop = occludable & ~seen[np.maximum(of_element, 0)] & blocked[np.maximum(of_element, 0)]
        keep = ~drop
        for key in el:  # one array at a time, each let go as its copy is made
            el[key] = el[key][keep]
        of_element = of_element[keep]
        of_element[el["exposed"]] = -1
        el["column"] = of_element
    else:
        el["column"] = np.full(len(el["area"]), -1)
    occl = np.flatnonzero(el["column"] >= 0)
    # Group pieces by geometric normal (exactly: its gates [n_g.s > 0] and max(n_g.o, 0) are
    # discontinuous, merging faces would move the terminator and the limb) and shading class
    # (material and shading normal quantised by the material's quantum, _normal_quantum_rad):
    # a group's visibility is factorised together (_visibility_factors), and at run time its
    # area-weighted mean shading normal enters its class's per-frame normal.
    quantum = normal_quantum_rad[el["material"]][:, None]
    weight_area = el["area"]
    # Shading classes: material and binned shading normal, shared by every face. The BRDF is
    # evaluated once per class and frame; a smooth-shaded tube's normals then fall into a ring
    # of classes instead of (faces x bins).
    shade_class, _ = _row_ids(
        len(quantum),
        itertools.chain([el["material"]], (np.round(el["normal"][:, k] / quantum[:, 0]) for k in range(3))),
    )
    n_classes = int(shade_class.max()) + 1 if len(shade_class) else 0
    class_material = np.zeros(n_classes, dtype=np.int64)
    class_material[shade_class] = el["material"]
    # Each class's area-weighted mean normal lies in its cell (a cube of normal space), so it
    # rounds to the cell's key; normalised, it is the class's nominal normal.
    class_normal = np.column_stack(
        [np.bincount(shade_class, weights=el["normal"][:, k] * weight_area, minlength=n_classes) for k in range(3)]
    )
    class_normal /= np.bincount(shade_class, weights=weight_area, minlength=n_classes)[:, None]
    class_key = np.round(class_normal / normal_quantum_rad[class_material][:, None]).astype(np.int64)
    class_normal /= np.linalg.norm(class_normal, axis=1, keepdims=True)
    lobes = np.array([b.lobe_width_rad or 0.0 for b in scene.brdfs])
    class_target, target_material, coarse_cos = _coarse_classes(
        class_key, class_material, normal_quantum_rad, lobes, tail.cap_rad, tail.bin_ratio
    )
    class_lobed = np.array([_pure_lobe(b) for b in scene.brdfs], dtype=bool)[class_material]
    # Class first in the key, so np.unique sorts the groups by class (each class is summed in
    # one run at run time, _cache_kernels.lit_classes) and so into one block per material.
    group, counts = _row_ids(
        len(shade_class), itertools.chain([shade_class], (np.round(el["geo"][:, k] / 1e-6) for k in range(3)))
    )
    n_groups = len(counts)
    group_class = np.zeros(n_groups, dtype=np.int64)
    group_class[group] = shade_class
    normal_shade = np.zeros((n_groups, 3))
    np.add.at(normal_shade, group, el.pop("normal") * weight_area[:, None])
    normal_shade /= np.linalg.norm(normal_shade, axis=1, keepdims=True)
    normal_geo = np.zeros((n_groups, 3))
    np.add.at(normal_geo, group, el.pop("geo") * weight_area[:, None])
    normal_geo /= np.linalg.norm(normal_geo, axis=1, keepdims=True)
    area_exposed = np.zeros(n_groups)
    exposed_mask = el["exposed"].copy()
    exposed_mask[occl] = False
    np.add.at(area_exposed, group[exposed_mask], weight_area[exposed_mask])
    # Pieces of one group sharing a visibility element add their areas to one (group, element) pair.
    # One integer per pair, group-major, so its sort is the pairs' (a two-column unique copies
    # the pieces several times over).
    span = int(el["column"].max()) + 1 if len(occl) else 1
    pair_key, pair_of = np.unique(group[occl] * span + el["column"][occl], return_inverse=True)
    pairs = np.column_stack([pair_key // span, pair_key % span])
    pair_area = np.bincount(pair_of.reshape(-1), weights=weight_area[occl], minlength=len(pairs))
    del el, pair_key, pair_of, weight_area, exposed_mask, group, shade_class
    starts = np.flatnonzero(np.r_[True, np.diff(pairs[:, 0]) != 0]) if len(pairs) else np.zeros(0, int)
    factors, factor_starts, factorised = _visibility_factors(
        visibility, len(directions), row_of[pairs[:, 1]], pair_area, starts, factor_tolerance
    )

    factor_groups = pairs[starts[factorised], 0] if len(pairs) else np.zeros(0, int)
    # The other groups keep their elements' visibility as bits, and each (group, element)
    # pair's area: an (elements, groups) sparse matrix.
    in_raw_group = (
        np.repeat(~factorised, np.diff(np.r_[starts, len(pairs)]).astype(int)) if len(pairs) else np.zeros(0, bool)
    )
    raw_columns, raw_element = np.unique(pairs[in_raw_group, 1], return_inverse=True)
    raw_element = raw_element.reshape(-1)
    # Elements in group order, so the run time adds a frame's elements to its groups in sequence.
    first_group = np.full(len(raw_columns), n_groups)
    np.minimum.at(first_group, raw_element, pairs[in_raw_group, 0])
    order = np.argsort(first_group, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    raw_columns, raw_element = raw_columns[order], rank[raw_element]
    raw_area = sparse.csc_matrix(
        (pair_area[in_raw_group].astype(np.float32), (pairs[in_raw_group, 0], raw_element)),
        shape=(n_groups, len(raw_columns)),
    )
    raw_area.sort_indices()
    element_normal, element_far = _far_elements(
        raw_area,
        normal_shade,
        group_class,
        class_lobed,
        normal_quantum_rad[class_material],
        lobes[class_material],
        tail.far_lobes,
    )
    raw_geo, raw_corners = parent_geo[raw_columns], el_corners[raw_columns]
    # Let go of all but what the bits are made from before they are: here the visibility and its
    # bits are both held, the build's peak on a glossy mesh.
    n_pairs = len(pairs)
    del pairs, pair_area, in_raw_group, raw_element, first_group, order, rank, parent_geo, el_corners, seen, blocked
    # Bits are cleared for directions further below an element's plane than the horizon band
    # (_visibility leaves them set for the cosine gate): an element facing well away from the
    # Sun or the observer then has no bit set around it, and the run time passes over it.
    raw_bits = np.zeros((len(directions), -(-len(raw_columns) // 64)), dtype=np.uint64)
    for begin in range(0, len(raw_columns), 64):  # a word at a time: (d, 64) float temporaries
        columns = raw_columns[begin : begin + 64]
        above = directions @ raw_geo[begin : begin + 64].T > -band
        words = _cache_kernels.pack_words(_unpacked(visibility[row_of[columns]], len(directions)).astype(bool) & above)
        raw_bits[:, begin // 64 : begin // 64 + words.shape[1]] = words
    del visibility  # the element-major copy: the bits and factors hold what the run time needs
    gaps, raycaster = _GapPairs(len(raw_columns)), open3d_scene(mesh)  # one scene for both searches
    # The gap search's band is an angle of the scene, not of the grid (_GAP_BAND_MIN_RAD).
    gap_band = max(band, math.sin(_GAP_BAND_MIN_RAD))
    gap_rays = _horizon_gaps(gaps, mesh, raycaster, raw_corners, raw_geo, raw_bits, directions, gap_band)
    gap_rays += _slit_gaps(gaps, mesh, raycaster, raw_corners, raw_geo, raw_bits, directions, element_size_m)
    del raycaster
    gap_ptr, gap_word, gap_mask = _gap_table(gaps.merged(), len(raw_columns), len(directions))
    del gaps
    return _Pose(
        normal_shade.astype(np.float32),
        group_class.astype(np.int32),
        n_classes,
        normal_geo.astype(np.float32),
        area_exposed.astype(np.float32),
        factors,
        np.asarray(factor_starts, dtype=np.int64),
        factor_groups.astype(np.int64),
        raw_bits,
        len(raw_columns),
        raw_area,
        raw_corners,
        raw_geo.astype(np.float32) if len(raw_columns) else np.zeros((0, 3), np.float32),
        gap_ptr,
        gap_word,
        gap_mask,
        mesh.vertices_m.astype(np.float32),
        _ray_offset_m(mesh),
        n_groups + n_pairs,
        n_pairs,
        n_rays + gap_rays,
        class_normal.astype(np.float32),
        class_lobed,
        class_target,
        coarse_cos,
        target_material,
        element_normal,
        element_far,
    )


class _LobeTail(NamedTuple):
    """How a build treats a lobe's tail (SceneCache.build's coarse_bin_ratio, far_lobe_widths)."""

    cap_rad: float  # coarse bins stop at this size (a diffuse material's bin)
    bin_ratio: float  # see _coarse_classes
    far_lobes: float  # see _far_elements


def _is_number(value):
    """A real number (not a bool): an option's check before its range."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def _pure_lobe(brdf):
    """Whether ``brdf`` is a specular lobe and nothing else (no diffuse part): far from its
    half vector only the lobe's tail is left (a Mix of two such lobes is one too)."""
    if not brdf.lobe_width_rad:
        return False
    parts = [getattr(brdf, name) for name in ("first", "second") if hasattr(brdf, name)]
    if parts:
        return all(_pure_lobe(part) for part in parts)
    return brdf.lobe_share >= 1.0 - 1e-9


def _coarse_classes(class_key, class_material, quantum_rad, lobe_rad, cap_rad, ratio=_COARSE_BIN_RATIO):
    """Coarser shading classes, for the frames where a class is far from the half vector.

    A class is a cell of its material's normal quantum q (``class_key``: its normal over q,
    rounded); at level l its cells merge 2^l to a side (the key floor-divided by 2^l), as long as
    2^l q is at most ``cap_rad`` (a diffuse material's bin: a lobeless material, or a lobe's
    diffuse base, is not binned coarser than that anywhere). At run time a class of a lobed
    material joins its level-l cell where its nominal normal is at least 2^l q / ratio from the
    frame's half vector (``ratio``, 0: never; the cell's shading normal is its lit classes'
    weighted mean, as a class's is of its groups).

    Returns
    -------
    class_target : (l, c) int32, each class's coarse class at level 1..l, numbered from c up.
    target_material : (n,) int32, each class's material, then each coarse class's.
    coarse_cos : (materials, l) float64, the cosine to the half vector under which a class of
        the material takes each level (-2: never).
    """
    n_classes = len(class_key)
    with np.errstate(divide="ignore"):
        levels = np.where(lobe_rad > 0.0, np.floor(np.log2(cap_rad / quantum_rad) + 1e-9), 0).clip(0, 6).astype(int)
    n_levels = int(levels.max()) if len(levels) else 0
    coarse_cos = np.full((len(quantum_rad), n_levels), -2.0)
    # A ratio of 0 leaves every cosine at -2: no level is ever taken.
    for material, (count, q) in enumerate(zip(levels, quantum_rad) if ratio > 0.0 else ()):
        for level in range(1, count + 1):
            angle = 2**level * q / ratio
            if angle < math.pi:
                coarse_cos[material, level - 1] = math.cos(angle)
    class_target = np.zeros((n_levels, n_classes), dtype=np.int32)
    target_material = [class_material]
    first = n_classes
    for level in range(1, n_levels + 1):
        cell = np.floor_divide(class_key, 2**level)
        ids, counts = _row_ids(n_classes, itertools.chain([class_material], cell.T))
        class_target[level - 1] = first + ids
        material = np.zeros(len(counts), dtype=np.int64)
        material[ids] = class_material
        target_material.append(material)
        first += len(counts)
    return class_target, np.concatenate(target_material).astype(np.int32), coarse_cos


def _far_elements(
    raw_area, normal_shade, group_class, class_lobed, class_quantum_rad, class_lobe_rad, far_lobes=_FAR_LOBES
):
    """Each bit-held element's mean shading normal and how far beyond the frame's nearest lobe
    the half vector must be from it for its mixed pairs to need no exact ray.

    Every group of the element must be of a pure-lobe material (:func:`_pure_lobe`); the reach
    is the largest angle between the mean and its groups' normals, plus a class cell's
    half-diagonal (sqrt(3)/2 q: a group's pieces lie in its cell), plus ``far_lobes`` lobe widths
    (inf: every element always gets rays).
    There the lobe's tail is what lights the element, and the bilinear interpolation of its
    bits (a shadow or horizon edge smeared over a grid cell) is off by a share of that tail.

    Returns
    -------
    element_normal : (e, 3) float32.
    far : (e, 3) float32, that angle (-1 where the element always gets rays), its cosine and sine.
    """
    n = raw_area.shape[1]
    if n == 0:
        return np.zeros((0, 3), dtype=np.float32), np.zeros((0, 3), dtype=np.float32)
    groups, ptr = raw_area.indices, raw_area.indptr
    column = np.repeat(np.arange(n), np.diff(ptr))
    normals = normal_shade.astype(float)
    mean = np.column_stack(
        [np.bincount(column, weights=raw_area.data * normals[groups, k], minlength=n) for k in range(3)]
    )
    mean /= np.linalg.norm(mean, axis=1, keepdims=True)
    entry_class = group_class[groups]
    cosine = np.einsum("ij,ij->i", normals[groups], mean[column]).clip(-1.0, 1.0)
    reach = np.arccos(cosine) + math.sqrt(3.0) / 2.0 * class_quantum_rad[entry_class]
    starts = ptr[:-1]
    lobed = np.minimum.reduceat(class_lobed[entry_class].astype(np.int8), starts) > 0
    if math.isfinite(far_lobes):
        far = np.maximum.reduceat(reach, starts) + far_lobes * np.minimum.reduceat(class_lobe_rad[entry_class], starts)
        far = np.where(lobed, far, -1.0)
    else:
        far = np.full(n, -1.0)
    return mean.astype(np.float32), np.column_stack([far, np.cos(far), np.sin(far)]).astype(np.float32)


def _row_ids(n, columns):
    """Dense ids of the n rows of integer-valued ``columns`` (an iterable of (n,) arrays, read
    one at a time), numbered in the rows'
    lexicographic order, and each id's count: ``np.unique(np.column_stack(columns), axis=0,
    return_inverse=True, return_counts=True)[1:]`` without its (n, k) copies (on the all-Glossy
    COSMOS 2502 mesh, 390 000 pieces, those were the build's peak memory).
    """
    ids = np.zeros(n, dtype=np.int64)
    if n == 0:
        return ids, np.zeros(0, dtype=np.int64)
    counts = np.array([n])
    for column in columns:
        column = np.asarray(column).astype(np.int64)
        low = column.min()
        # ids < n and the column's span < 2^32 here, so the key cannot overflow.
        _, ids, counts = np.unique(
            ids * (int(column.max()) - int(low) + 1) + (column - low), return_inverse=True, return_counts=True
        )
        ids = ids.reshape(-1)
    return ids, counts


def _glossy_strip(scene, mesh):
    """(t,) bool: smooth-shaded triangles (corner normals more than half a degree off the
    face's) of a glossy material (lobe share over ``_WEAK_LOBE_SHARE``, lobe narrower than
    ``_STRIP_LOBE_DEG``), whose elements are cut to half the default size.

    On such a surface the light comes from a strip where the lobe meets the curved normals,
    not evenly from each face, so a shadow edge quantised by an element moves a larger share of
    it: the all-Glossy COSMOS 2502 (GGX, roughness 0.3, 5 deg lobe) is 0.0103 mag RMS off the
    direct renderer on tumble frames at radius / 30 elements everywhere and 0.0079 at radius /
    60 (pieces, edge rays, solar-disk samples and grid 48 leave it unchanged). Broad or weak
    lobes (Principled dielectrics, 14 deg) and flat faces are uniformly lit per face and keep
    the default.
    """
    glossy = np.array(
        [
            b is not None
            and bool(b.lobe_width_rad)
            and b.lobe_share > _WEAK_LOBE_SHARE
            and math.degrees(b.lobe_width_rad) < _STRIP_LOBE_DEG
            for b in scene.brdfs
        ]
    )
    if not glossy.any():
        return np.zeros(len(mesh.face_normals), dtype=bool)
    spread = np.einsum("tkx,tx->tk", mesh.corner_normals, mesh.face_normals).min(axis=1)
    return glossy[mesh.material_index] & (spread < math.cos(math.radians(0.5)))


def _quarters(corners, normals):
    """Midpoint subdivision: (n, 4, 3, 3) corners and normals of each triangle's four children.

    The fourth child is the middle one; its centroid is the parent's.
    """
    a, b, c = (corners[:, k] for k in range(3))
    na, nb, nc = (normals[:, k] for k in range(3))
    ab, bc, ca = 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)
    nab, nbc, nca = 0.5 * (na + nb), 0.5 * (nb + nc), 0.5 * (nc + na)
    quarter_corners = np.stack(
        [np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))], axis=1
    )
    quarter_normals = np.stack(
        [np.stack(t, axis=1) for t in ((na, nab, nca), (nab, nb, nbc), (nca, nbc, nc), (nab, nbc, nca))], axis=1
    )
    return quarter_corners, quarter_normals


# Directions cast around a gap node's grid direction: this many on each ring, the rings this
# many grid spacings away.
_GAP_PROBES = 8
_GAP_RINGS = (0.25, 0.5)
# The gap search covers nodes up to this far above an element's plane, or two grid spacings where
# those are wider. Where a line of sight grazes a tube between its fittings is the scene's
# geometry, not the grid's: with two spacings alone the 64-node grid searched 2.8 deg and missed
# the gaps the 32-node grid found at 3-5.6 deg (the paper's COSMOS 2502 tube seen end-on: 0.0110
# mag RMS from the direct renderer against 0.0069 at 32 nodes, up to 0.086 on dim frames;
# 0.0062 with this floor).
_GAP_BAND_MIN_RAD = math.radians(5.625)
# Rays from an edge's samples look for a gap across it in the edge's triangle's plane and
# tilted this many degrees out of it (_slits).
_SLIT_TILTS_DEG = (-60.0, -30.0, 0.0, 30.0, 60.0)


def _horizon_gaps(gaps, mesh, raycaster, corners, normals, raw_bits, directions, band):
    """Grid nodes close above a bit-held element's horizon where it sees out through a gap
    narrower than the grid.

    An element of a long tube looks along the tube a few degrees above its plane; there a line
    of sight can pass between fittings through a gap narrower than the grid spacing, so the
    four nodes around the exact direction are blocked while the direction is open, and the
    bits count the element unseen (the paper's COSMOS 2502 seen nearly end-on: 0.13-0.30 mag
    too faint). For each blocked node less than ``band`` (a sine: two grid spacings, at least
    ``_GAP_BAND_MIN_RAD``) above an element's plane, ``_GAP_PROBES`` rays on each of the rings
    ``_GAP_RINGS`` grid spacings around it are cast (those above the plane); a node with one of
    them open inside a grid cell whose four nodes are all blocked is a *gap node* (where a node
    is open, the run time's mixed pairs already cast rays), and at run time
    (:func:`_lit_classes`) a pair with a gap node among its four nodes is decided by rays toward
    the exact direction.

    Rays go into ``raycaster`` (the mesh's Open3D scene). Adds the gap pairs to ``gaps`` (a
    :class:`_GapPairs`; :func:`_gap_table` makes the run time's table of them) and returns the
    number of rays cast.
    """
    n_elements = len(corners)
    if n_elements == 0 or not _GAP_RINGS:
        return 0
    offset = _ray_offset_m(mesh)
    grid_size = _grid_size_of(directions)
    u, v = orthonormal_basis(directions)
    angles = 2.0 * np.pi * (np.arange(_GAP_PROBES) + 0.5 * np.arange(len(_GAP_RINGS))[:, None]) / _GAP_PROBES
    radius = np.tan(np.array(_GAP_RINGS)[:, None] * _grid_spacing_rad(directions)) * np.ones_like(angles)
    angles, radius = angles.ravel(), radius.ravel()
    around = directions[:, None, :] + radius[None, :, None] * (
        np.cos(angles)[None, :, None] * u[:, None, :] + np.sin(angles)[None, :, None] * v[:, None, :]
    )
    around /= np.linalg.norm(around, axis=2, keepdims=True)  # (d, probes, 3)
    origins = corners.astype(float).mean(axis=1) + offset * normals
    n_rays = 0
    # Elements per batch, whole words, so that a batch casts about _MAX_BUILD_RAYS: a node is
    # within the band above an element's plane for a share band / 2 of the directions.
    per_element = max(1, int(len(directions) * band / 2.0) * around.shape[1])
    # (node, element) pairs, probes each: a quarter of _MAX_BUILD_RAYS, as each ray also takes
    # its probe's direction in 64 bits and a few indices (on a small scene such as the bus and
    # wings, full batches were a third of the build's peak memory).
    pairs_per_batch = max(1, _MAX_BUILD_RAYS // (4 * around.shape[1]))
    chunk = 64 * max(1, _MAX_BUILD_RAYS // (64 * per_element))
    for begin in range(0, n_elements, chunk):
        end = min(begin + chunk, n_elements)
        height = directions @ normals[begin:end].T  # (d, c)
        bits = np.unpackbits(
            np.ascontiguousarray(raw_bits[:, begin // 64 : -(-end // 64)]).view(np.uint8), axis=1, bitorder="little"
        )[:, : end - begin].astype(bool)
        in_band = np.nonzero((height > 0.0) & (height < band) & ~bits)
        del height
        # (node, element) pairs a batch of rays' worth at a time.
        for first in range(0, len(in_band[0]), pairs_per_batch):
            node = in_band[0][first : first + pairs_per_batch]
            element = in_band[1][first : first + pairs_per_batch] + begin
            toward = around[node]  # (p, probes, 3)
            pair, probe = np.nonzero(np.einsum("pkx,px->pk", toward, normals[element]) > 0.0)  # probes above the plane
            rays = np.empty((len(pair), 6), dtype=np.float32)
            rays[:, :3] = origins[element[pair]]
            rays[:, 3:] = toward[pair, probe]
            del toward
            open_ = ~raycaster.test_occlusions(rays).numpy()
            n_rays += len(rays)
            # An open probe is a gap only inside a cell whose four nodes are all blocked: where one of
            # them is open, the pair is a mixed pair and rays decide it already.
            seen = np.flatnonzero(open_)
            corners_of = cube_grid_weights(rays[seen, 3:].astype(float), grid_size)[0]
            shut = ~bits[corners_of, (element[pair[seen]] - begin)[:, None]].any(axis=1)
            gap = np.zeros(len(node), dtype=bool)
            gap[pair[seen[shut]]] = True
            gaps.add(node[gap], element[gap])
    return n_rays


class _GapPairs:
    """The gap searches' (node, element) pairs, merged as they are found: sorted unique int64
    keys ``node * n_elements + element``, 8 bytes a pair (on the all-Glossy paper mesh the
    searches find 4 million pairs, many of them several times over)."""

    def __init__(self, n_elements):
        self.n_elements = n_elements
        self._keys = np.zeros(0, np.int64)
        self._pending, self._n_pending = [], 0

    def add(self, node, element):
        batch = np.unique(np.asarray(node, dtype=np.int64) * self.n_elements + element)
        self._pending.append(batch)
        self._n_pending += len(batch)
        if self._n_pending > max(len(self._keys), _MAX_BUILD_RAYS):  # merged at least each doubling
            self._merge()

    def _merge(self):
        if not self._pending:
            return
        merged = np.concatenate([self._keys, *self._pending])
        self._keys, self._pending, self._n_pending = None, [], 0
        merged.sort()  # in place, and deduplicated into one copy: three times the keys at most
        self._keys = merged[np.r_[True, merged[1:] != merged[:-1]]] if len(merged) else merged

    def merged(self):
        """All pairs' keys, sorted and unique."""
        self._merge()
        return self._keys


def _gap_table(keys, n_elements, n_directions, chunk=1 << 18):
    """The run time's gap table of gap pairs (sorted unique keys of :class:`_GapPairs`): CSR
    by node (d + 1,) of (word, bit mask) of the elements for which the node is a gap node."""
    keys = np.asarray(keys, dtype=np.int64)
    words, masks, counts = [], [], np.zeros(n_directions, dtype=np.int64)
    begin = 0
    while begin < len(keys):  # in chunks of whole nodes, so that no (node, word) run is cut
        end = min(begin + chunk, len(keys))
        end = int(np.searchsorted(keys, (keys[end - 1] // n_elements + 1) * n_elements))
        node, element = np.divmod(keys[begin:end], n_elements)
        word = element // 64
        # Sorted by node then element: the pairs of one (node, word) are a run, their bits ORed.
        starts = np.flatnonzero(np.r_[True, (node[1:] != node[:-1]) | (word[1:] != word[:-1])])
        masks.append(np.bitwise_or.reduceat(np.left_shift(np.uint64(1), (element % 64).astype(np.uint64)), starts))
        words.append(word[starts])
        counts += np.bincount(node[starts], minlength=n_directions)
        begin = end
    gap_ptr = np.r_[0, np.cumsum(counts)].astype(np.int64)
    if not words:
        return gap_ptr, np.zeros(0, np.int64), np.zeros(0, np.uint64)
    return gap_ptr, np.concatenate(words), np.concatenate(masks)


def _slits(mesh, raycaster, width_max_m, spacing_m):
    """Segments (s, 2, 3) running along the gaps between the mesh's parts.

    A panel built of slats (the paper's COSMOS 2502: 1.2-2.2 cm between them) or a part mounted
    a little off another lets light through a gap that from most elements is narrower than the
    grid: the four nodes around a direction through it are blocked, so the bits count the
    element dark where it is lit or seen (the paper's tube behind its panels: up to 3% of the
    whole light too faint at phase 90-110 deg, the cached model's main error on such passes).
    Every edge is sampled every ``spacing_m``; rays go into ``raycaster`` (the mesh's Open3D
    scene). A sample's gap is the nearer of: the nearest sample of another connected part, and
    the nearest hit of rays leaving it outward across the edge in its triangle's plane and
    tilted out of it (_SLIT_TILTS_DEG); it counts where it
    is narrower than ``width_max_m`` and its middle is clear of the mesh by a quarter of its
    width (parts touching along a seam have none). Returned are three lines along each gap (its
    near side, middle and far side) between consecutive samples of an edge, so a direction
    through the gap lies in a cell that one of them crosses. Also returns the rays cast.
    """
    corners = mesh.corners_m
    if len(corners) == 0:
        return np.zeros((0, 2, 3)), 0
    tolerance = 1e-6 * max(mesh.radius_m, 1.0)
    _, vertex = np.unique(np.round(corners.reshape(-1, 3) / tolerance), axis=0, return_inverse=True)
    vertex = vertex.reshape(-1, 3).astype(np.int64)
    ends = np.stack([vertex, np.roll(vertex, -1, axis=1)], axis=2)  # (t, 3, 2): edge k runs from corner k
    key = ends.min(axis=2) * (int(vertex.max()) + 1) + ends.max(axis=2)
    _, first_of = np.unique(key.reshape(-1), return_index=True)  # each edge once, from one of its triangles
    tri, k = np.divmod(first_of, 3)
    start, end, third = corners[tri, k], corners[tri, (k + 1) % 3], corners[tri, (k + 2) % 3]
    normal = mesh.face_normals[tri]
    along = end - start
    outward = np.cross(along, normal)
    outward /= np.maximum(np.linalg.norm(outward, axis=1, keepdims=True), 1e-300)
    outward[np.einsum("ij,ij->i", third - start, outward) > 0.0] *= -1.0
    # Samples: each edge's ends and points at most spacing_m apart between them.
    per_edge = np.maximum(np.ceil(np.linalg.norm(along, axis=1) / spacing_m).astype(int), 1) + 1
    edge = np.repeat(np.arange(len(tri)), per_edge)
    first = np.r_[0, np.cumsum(per_edge)[:-1]]
    fraction = (np.arange(len(edge)) - first[edge]) / (per_edge[edge] - 1)
    fraction = np.clip(fraction, 0.01, 0.99)  # off the corners, where the next triangle begins
    points = start[edge] + fraction[:, None] * along[edge]
    offset = _ray_offset_m(mesh)
    reach = np.full(len(points), np.inf)
    far = points.copy()
    for tilt in np.radians(_SLIT_TILTS_DEG):
        direction = math.cos(tilt) * outward[edge] + math.sin(tilt) * normal[edge]
        rays = np.hstack([points + offset * direction, direction]).astype(np.float32)
        hit = raycaster.cast_rays(rays)["t_hit"].numpy().astype(float)
        nearer = hit < reach
        reach[nearer] = hit[nearer]
        far[nearer] = points[nearer] + hit[nearer, None] * direction[nearer]
    # Gaps between two edges (slats side by side or meeting at a ridge may face each other
    # edge-on, where rays across miss both): the nearest sample of another connected part.
    part = _connected_parts(vertex)[tri[edge]]
    tree = cKDTree(points)
    across, partner = np.full(len(points), np.inf), np.zeros(len(points), dtype=np.int64)
    for begin in range(0, len(points), 4096):  # (samples, 32) arrays a block at a time
        block = slice(begin, begin + 4096)
        distance, neighbour = tree.query(points[block], k=min(32, len(points)), distance_upper_bound=width_max_m)
        distance, neighbour = distance.reshape(len(distance), -1), neighbour.reshape(len(neighbour), -1)
        other = (distance > offset) & np.isfinite(distance)
        other &= part[np.minimum(neighbour, len(points) - 1)] != part[block, None]
        column = np.argmax(other, axis=1)
        rows = np.arange(len(column))
        across[block] = np.where(other[rows, column], distance[rows, column], np.inf)
        partner[block] = neighbour[rows, column]
    closer = across < reach
    reach[closer] = across[closer]
    far[closer] = points[partner[closer]]
    gap = np.flatnonzero((reach < width_max_m) & (reach > offset))
    is_gap = np.zeros(len(points), dtype=bool)
    if len(gap):
        middle = 0.5 * (points[gap] + far[gap])
        is_gap[gap[raycaster.compute_distance(middle.astype(np.float32)).numpy() >= 0.25 * reach[gap]]] = True
    lines = np.stack([points, 0.5 * (points + far), far], axis=1)  # (samples, 3, 3)
    # Segments between consecutive samples of one edge that both see a gap.
    pair = np.flatnonzero((edge[1:] == edge[:-1]) & is_gap[1:] & is_gap[:-1])
    segments = np.stack([lines[pair], lines[pair + 1]], axis=2)  # (p, 3 lines, 2 ends, 3)
    return segments.reshape(-1, 2, 3), len(points) * len(_SLIT_TILTS_DEG)


def _connected_parts(vertex):
    """(t,) int: the connected part of each triangle of a mesh whose corners are the vertex
    ids ``vertex`` (t, 3) (triangles sharing a vertex are connected)."""
    n_triangles, n_vertices = len(vertex), int(vertex.max()) + 1
    graph = sparse.coo_matrix(
        (np.ones(vertex.size), (np.repeat(np.arange(n_triangles), 3), n_triangles + vertex.reshape(-1))),
        shape=(n_triangles + n_vertices,) * 2,
    )
    return connected_components(graph, directed=False)[1][:n_triangles]


def _slit_gaps(gaps, mesh, raycaster, corners, normals, raw_bits, directions, element_size_m):
    """Gap pairs of bit-held elements that see out through a slit (:func:`_slits`).

    Gaps up to the width the grid resolves from the far side of the mesh are taken (two radii
    times the grid spacing; wider ones open whole grid cells, whose mixed pairs rays decide
    already), sampled every half element. An element sees out through a stretch of gap where
    the direction toward its middle lies in a cell whose four nodes it has blocked and a ray
    that way escapes; then its directions toward the stretch's three lines, half a grid
    spacing apart, mark the four nodes of every such cell they cross
    (:func:`raycast.renderer._cache_kernels.slit_gap_nodes`): at run time a pair with a gap
    node among its four nodes is decided by rays (:func:`_lit_classes`).

    Rays go into ``raycaster`` (the mesh's Open3D scene). Adds the pairs to ``gaps`` (a
    :class:`_GapPairs`) and returns the number of rays cast.
    """
    if len(corners) == 0:
        return 0
    spacing = _grid_spacing_rad(directions)
    segments, n_rays = _slits(mesh, raycaster, 2.0 * mesh.radius_m * spacing, element_size_m / 2.0)
    if len(segments) == 0:
        return n_rays
    segments = segments.reshape(-1, 3, 2, 3)
    middles = segments[:, 1].mean(axis=1)
    origins = corners.astype(float).mean(axis=1) + _ray_offset_m(mesh) * normals
    normals = np.ascontiguousarray(normals, dtype=float)
    grid_size = _grid_size_of(directions)
    chunk = 64 * max(1, _MAX_BUILD_RAYS // (64 * len(middles)))  # elements a batch: whole words
    for begin in range(0, len(origins), chunk):
        end = min(begin + chunk, len(origins))
        words = np.ascontiguousarray(raw_bits[:, begin // 64 : -(-end // 64)])
        batch = (words, origins[begin:end], normals[begin:end])  # the kernels' first arguments

        def pairs(kernel, *arguments):
            return _cache_kernels.collected(kernel, 1 << 16, (np.int64, np.int64), *batch, *arguments)

        element, segment = pairs(_cache_kernels.slit_candidates, middles, grid_size)
        toward = middles[segment] - origins[begin + element]
        toward /= np.linalg.norm(toward, axis=1, keepdims=True)
        rays = np.hstack([origins[begin + element], toward]).astype(np.float32)
        escapes = ~raycaster.test_occlusions(rays).numpy().astype(bool) if len(rays) else np.zeros(0, bool)
        n_rays += len(rays)
        node, local = pairs(
            _cache_kernels.slit_gap_nodes, segments, grid_size, spacing / 2.0, element[escapes], segment[escapes]
        )
        gaps.add(node, local + begin)
    return n_rays


def _split_where_partly_visible(mesh, corners, normals, tri, side, exposed, n_geo, directions, band, progress):
    """Visibility of the elements that need it; elements partly covered in many directions are quartered.

    One centroid ray per direction decides a whole element, which is wrong where an element is
    partly covered or shadowed in many directions at once: beside a mount, under a panel's
    edge (COSMOS 2502's tube beside its panels: 2% too faint over whole stretches of the pass at
    0.29 m elements). The centroids of each element's four quarters are first cast toward a
    coarse cube map (a quarter of the grid's resolution); where they disagree in more than
    ``_SPLIT_FRACTION`` of the element's upper-hemisphere directions, the element is replaced
    by its quarters, each with its own visibility on the full grid; elsewhere its centroid
    decides. A shadow edge that only passes over an element is left to the run time's exact
    rays.

    Returns the elements' corners, normals, tri, side and exposed flags after splitting (the
    non-exposed ones first), what their rays found, and the rays cast. What they found is
    (visibility, row_of, seen, blocked): for each non-exposed element whether some direction
    above its plane is open (seen) and whether some is blocked, and the visibility bits
    (element-major, see :func:`_visibility`) of those both seen and blocked only, element
    ``i``'s at row ``row_of[i]`` (-1 for the others).
    """
    cast = np.flatnonzero(~exposed)
    geo = _side_normals(n_geo, tri, side)
    raycaster, offset = open3d_scene(mesh), _ray_offset_m(mesh)
    coarse = cube_grid_directions(max(4, _grid_size_of(directions) // 4))
    split = np.zeros(len(cast), dtype=bool)
    n_rays = 0
    chunk = max(1, _MAX_BUILD_RAYS // (4 * len(coarse)))
    for begin in range(0, len(cast), chunk):
        sl = slice(begin, begin + chunk)
        element_geo = geo[cast[sl]]
        quarter_points = _quarters(corners[cast[sl]], normals[cast[sl]])[0].mean(axis=2)
        bits, rays = _visibility(
            raycaster, offset, quarter_points.reshape(-1, 3), np.repeat(element_geo, 4, axis=0), coarse, band
        )
        n_rays += rays
        vis = _unpacked(bits, len(coarse)).reshape(len(coarse), -1, 4)
        upper = (coarse @ element_geo.T) > 0.0
        differ = (vis.min(axis=2) != vis.max(axis=2)) & upper
        split[sl] = differ.sum(axis=0) > _SPLIT_FRACTION * np.maximum(upper.sum(axis=0), 1)
    whole = cast[~split]
    quarter_corners, quarter_normals = _quarters(corners[cast[split]], normals[cast[split]])
    new_corners = np.concatenate([corners[whole], quarter_corners.reshape(-1, 3, 3), corners[exposed]])
    new_normals = np.concatenate([normals[whole], quarter_normals.reshape(-1, 3, 3), normals[exposed]])
    new_tri = np.concatenate([tri[whole], np.repeat(tri[cast[split]], 4), tri[exposed]])
    new_side = np.concatenate([side[whole], np.repeat(side[cast[split]], 4), side[exposed]])
    n_cast = len(whole) + 4 * int(split.sum())
    del quarter_corners, quarter_normals
    new_exposed = np.r_[np.zeros(n_cast, dtype=bool), np.ones(int(exposed.sum()), dtype=bool)]
    points = new_corners[:n_cast].mean(axis=1)
    new_geo = _side_normals(n_geo, new_tri[:n_cast], new_side[:n_cast])
    # Most elements are never blocked (exposed after all) or never seen: only the bits of the
    # others are kept, so the build holds about as much as the tables it makes.
    seen, blocked = np.zeros(n_cast, dtype=bool), np.zeros(n_cast, dtype=bool)
    visibility = _Rows(-(-len(directions) // 8))
    bar = None
    if progress:
        bar = tqdm(total=n_cast, unit="element", desc="visibility")
    chunk = max(1, 4 * _MAX_BUILD_RAYS // len(directions))
    for begin in range(0, n_cast, chunk):
        sl = slice(begin, begin + chunk)
        bits, rays = _visibility(raycaster, offset, points[sl], new_geo[sl], directions, band)
        n_rays += rays
        end = min(begin + chunk, n_cast)
        for first in range(begin, end, 64):  # (directions, elements) arrays are large
            few = slice(first, min(first + 64, end))
            upper = (directions @ new_geo[few].T) > 0.0
            open_ = _unpacked(bits[few.start - begin : few.stop - begin], len(directions)).astype(bool)
            seen[few], blocked[few] = (open_ & upper).any(axis=0), (~open_ & upper).any(axis=0)
        visibility.append(bits[seen[sl] & blocked[sl]])
        if bar is not None:
            bar.update(len(points[sl]))
    if bar is not None:
        bar.close()
    row_of = np.full(n_cast, -1, dtype=np.int64)
    row_of[seen & blocked] = np.arange(len(visibility))
    return new_corners, new_normals, new_tri, new_side, new_exposed, (visibility, row_of, seen, blocked), n_rays


class _Rows:
    """Rows of a uint8 table kept as the blocks they were made in (never copied into one array);
    ``rows[index]`` gathers (len(index), width) like an array's fancy indexing."""

    def __init__(self, width):
        self.width, self.blocks, self.ends = width, [], [0]

    def append(self, block):
        self.blocks.append(block)
        self.ends.append(self.ends[-1] + len(block))

    def __len__(self):
        return self.ends[-1]

    def __getitem__(self, index):
        index = np.asarray(index, dtype=np.int64)
        out = np.empty((len(index), self.width), dtype=np.uint8)
        block = np.searchsorted(self.ends, index, side="right") - 1
        for b in np.unique(block):
            here = block == b
            out[here] = self.blocks[b][index[here] - self.ends[b]]
        return out


def _side_normals(n_geo, tri, side):
    """(n, 3) geometric normals of triangle sides: ``n_geo[tri]`` for side 0, its negative for side 1."""
    return np.where(side[:, None] == 0, 1.0, -1.0) * n_geo[tri]


def _grid_size_of(directions):
    """N of the cube map ``cube_grid_directions(N)`` that gave ``directions``."""
    return round(math.sqrt(len(directions) / 6.0)) - 1


def _grid_spacing_rad(directions):
    """The cube map's largest spacing between neighbouring directions (at the face centres)."""
    return math.pi / 2.0 / _grid_size_of(directions)


class _GroupMatrix:
    """A group's ``M^T = diag(sqrt(A)) V^T`` (e, d), read from the element-major visibility bits
    a block of rows at a time, so no e x d float array is ever held."""

    _ROWS = 64

    def __init__(self, visibility, columns, weights, n_directions):
        self.visibility, self.columns, self.n_directions = visibility, columns, n_directions
        self.roots = np.sqrt(weights).astype(np.float32)

    def _blocks(self):
        for begin in range(0, len(self.columns), self._ROWS):
            rows = slice(begin, begin + self._ROWS)
            bits = np.unpackbits(self.visibility[self.columns[rows]], axis=1, count=self.n_directions)
            yield rows, bits.astype(np.float32) * self.roots[rows, None]

    def times(self, x):
        """M^T x: (d, k) -> (e, k)."""
        out = np.empty((len(self.columns), x.shape[1]), dtype=np.float32)
        for rows, block in self._blocks():
            out[rows] = block @ x
        return out

    def transposed_times(self, y):
        """M y: (e, k) -> (d, k)."""
        # Accumulated in place by BLAS (Fortran order, beta = 1): ``out += block.T @ y`` would
        # allocate a second (d, k) array per block.
        out = np.zeros((self.n_directions, y.shape[1]), dtype=np.float32, order="F")
        for rows, block in self._blocks():
            out = linalg.blas.sgemm(1.0, block, y[rows], beta=1.0, c=out, trans_a=1, overwrite_c=1)
        return out

    def row_norms(self):
        """(d,) |M(s)|^2 = sum over elements of A_e V_e(s)."""
        out = np.zeros(self.n_directions)
        for _, block in self._blocks():
            out += (block.astype(np.float64) ** 2).sum(axis=0)
        return out


def _group_basis(matrix, n_elements, budget, rng):
    """(e, r) orthonormal Q with ``max_s |M(s)|^2 - |M(s) Q|^2 <= budget`` and r < e / 8, or None.

    Randomised range finding (a Gaussian sketch of M's row space, two power iterations), the
    sketch then rotated to M's singular directions so its columns fall in importance and the
    leading r are kept; tried with 16, 32, ... columns.
    """
    row_norm2 = matrix.row_norms()
    rank = min(16, max(1, n_elements // 16))
    while rank < n_elements / _FACTOR_ELEMENTS_PER_COLUMN:
        width = min(rank + 8, n_elements)
        sketch = matrix.times(rng.standard_normal((matrix.n_directions, width), dtype=np.float32))
        for _ in range(2):
            sketch = matrix.times(matrix.transposed_times(_orthonormal(sketch)))
        basis = _orthonormal(sketch)
        del sketch
        projected = matrix.transposed_times(basis)  # (d, k) = M Q
        # M's singular directions within the sketch: eigenvectors of the k x k Gram matrix.
        gram = sum(block.T @ block for _, block in _row_blocks(projected))
        rotation = np.linalg.eigh(gram)[1][:, ::-1]
        basis = basis @ rotation.astype(np.float32)
        # worst[r - 1] = max over directions of |R(s)|^2 when the first r columns are kept; a
        # block of directions at a time, so only M Q itself is held whole (in 32 bits).
        worst = np.full(projected.shape[1], -np.inf)
        for first, block in _row_blocks(projected):
            rotated = block @ rotation
            np.square(rotated, out=rotated)
            np.cumsum(rotated, axis=1, out=rotated)
            np.subtract(row_norm2[first : first + len(block), None], rotated, out=rotated)
            np.maximum(worst, rotated.max(axis=0), out=worst)
        del projected
        good = np.flatnonzero(worst <= budget)
        if len(good) and good[0] + 1 < n_elements / _FACTOR_ELEMENTS_PER_COLUMN:
            return basis[:, : int(good[0]) + 1].copy()
        if _hopeless(worst, budget, n_elements / _FACTOR_ELEMENTS_PER_COLUMN):
            return None
        rank *= 2
    return None


def _hopeless(worst, budget, largest_rank):
    """Whether a residual curve ``worst`` (largest |R(s)|^2 with the first 1, 2, ... columns
    kept) extrapolates to more than ``_FACTOR_GIVE_UP`` budgets at ``largest_rank`` columns.

    At the default grid (32, 6534 directions) no group of the comparison scenes, COSMOS 2502 or
    TOPEX factorises (the budget is 1e-3 of a group's area, and shadow edges fall differently on
    each element): their first sketch (24 columns) stays 13-270 budgets off, and the doubled
    sketches that followed were most of the build's time and its peak memory. The rule only
    decides when to stop trying; a group given up keeps its exact bits.
    """
    width = len(worst)
    if worst[-1] <= budget or width < 4:
        return False
    per_doubling = max(worst[width // 2 - 1] / worst[-1], 1.0)
    doublings = max(math.log2(largest_rank / width), 0.0)
    return worst[-1] / per_doubling**doublings > _FACTOR_GIVE_UP * budget


def _orthonormal(sketch):
    """Q of the (e, k) float32 sketch's thin QR, in 32 bits (the sketch may be overwritten).

    Q's columns are orthonormal to ~1e-6, far inside the budget (1e-3 of a group's area);
    numpy's QR computes in 64 bits, and its copies of a large group's sketch were the build's
    peak memory (five times the sketch).
    """
    return linalg.qr(sketch, mode="economic", overwrite_a=True, check_finite=False)[0]


def _row_blocks(array):
    """(first row, block): ``array`` (n, k) in 64-bit blocks of ``_DIRECTION_ROWS`` rows."""
    for first in range(0, len(array), _DIRECTION_ROWS):
        yield first, array[first : first + _DIRECTION_ROWS].astype(np.float64)


def _visibility_factors(visibility, n_directions, columns_of_pairs, area, starts, tolerance, seed=0):
    """Compress each group's visibility into a few columns whose products give its lit-and-seen area.

    For a group (pieces sharing material and normals) the run time needs only
    ``W(s, o) = sum_e A_e V_e(s) V_e(o) = M(s) . M(o)`` with ``M = V diag(sqrt(A))`` (d, e).
    For any e x r matrix Q with orthonormal columns and ``P = M Q``,
    ``M(s) . M(o) = P(s) . P(o) + R(s) . R(o)`` with ``R = M (I - Q Q^T)`` and
    ``|R(s)|^2 = |M(s)|^2 - |P(s)|^2`` exactly; r is the smallest count with
    ``max_s |R(s)|^2 <= tolerance * sum(A)`` over the grid directions (bilinear interpolation
    mixes rows convexly, so the bound holds between them too): the group's W is then off by at
    most ``tolerance`` of its area. Q comes from a randomised range finder (Halko, Martinsson
    and Tropp 2011; :func:`_group_basis`). A group is factorised only when that keeps fewer
    than one column per ``_FACTOR_ELEMENTS_PER_COLUMN`` elements (a column of 32-bit floats
    holds as much as 32 elements' visibility bits); the others (a few elements each, as on a
    smooth-shaded tube whose pieces spread over many groups) keep their elements' bits. The
    work is O(d e r) per group and its memory d x r plus a block of rows of M, never the e x e
    Gram matrix of an eigensolver nor a float copy of the visibility; the factors are
    allocated once, after every group's rank is known.

    Parameters
    ----------
    visibility : (E, ceil(d / 8)) uint8, element-major visibility bits (:func:`_visibility`).
    n_directions : int, d.
    columns_of_pairs : (p,) int, the element of each (group, element) pair, pairs sorted by group.
    area : (p,) float, the pairs' areas.
    starts : (k,) int, first pair of each group.
    tolerance : float, largest error of W as a fraction of the group's area.
    seed : int, of the sketches (the result is deterministic).

    Returns
    -------
    factors : (d, r) float32, starts : (k',) int, first factor column of each factorised group,
    factorised : (k,) bool.
    """
    rng = np.random.default_rng(seed)
    ends = np.r_[starts[1:], len(columns_of_pairs)].astype(int)
    bases, factorised = [], np.zeros(len(starts), dtype=bool)
    for index, (begin, end) in enumerate(zip(starts, ends)):
        if end - begin <= _FACTOR_MIN_ELEMENTS:
            continue
        matrix = _GroupMatrix(visibility, columns_of_pairs[begin:end], area[begin:end], n_directions)
        basis = _group_basis(matrix, end - begin, tolerance * area[begin:end].sum(), rng)
        if basis is not None:
            factorised[index] = True
            bases.append((matrix, basis))
    widths = [basis.shape[1] for _, basis in bases]
    factors = np.empty((n_directions, sum(widths)), dtype=np.float32)
    new_starts = np.r_[0, np.cumsum(widths)[:-1]].astype(int) if widths else np.zeros(0, int)
    for (matrix, basis), first, width in zip(bases, new_starts, widths):
        factors[:, first : first + width] = matrix.transposed_times(basis)
    return factors, new_starts, factorised


def _visibility(raycaster, offset_m, points, normals, directions, horizon_band):
    """Element-major visibility bits: (e, ceil(d / 8)) uint8 (``numpy.packbits`` of each
    element's d directions, 1 where the ray from element e toward direction d escapes the
    mesh), and the number of rays cast.

    Directions within ``horizon_band`` (a sine) below an element's plane take the visibility
    of their mirror image above it, so that bilinear interpolation toward a grazing Sun or
    observer continues the visibility just above the horizon (a face grazed by the Sun along a
    stepped tube is shadowed by the steps; filling the band with 1 would light it). Directions
    further below are not cast and set to 1: the cosine gate removes them. Rays start
    ``offset_m`` above their element and are cast into ``raycaster`` (the pose's Open3D scene);
    they are built and their results stored by compiled loops, in batches of at most
    ``_MAX_BUILD_RAYS``.
    """
    points = np.ascontiguousarray(points, dtype=float)
    normals = np.ascontiguousarray(normals, dtype=float)
    bits = np.full((len(points), -(-len(directions) // 8)), 255, dtype=np.uint8)
    chunk = max(1, _MAX_BUILD_RAYS // len(directions))
    total = 0
    for begin in range(0, len(points), chunk):
        sl = slice(begin, begin + chunk)
        rays, element, direction = _cache_kernels.visibility_rays(
            points[sl], normals[sl], directions, horizon_band, offset_m
        )
        occluded = raycaster.test_occlusions(rays).numpy()
        _cache_kernels.clear_bits(bits[sl], element, direction, occluded)
        total += len(rays)
    return bits, total


def _unpacked(bits, n_directions):
    """(d, e) uint8 visibility of element-major bits (e, ceil(d / 8)) from :func:`_visibility`."""
    return np.unpackbits(bits, axis=1, count=n_directions).T
