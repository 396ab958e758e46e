"""Shape caches built once and kept on disk, keyed by what they were built from.

Building the fast renderer's precomputed tables (`raycast.renderer.cache.SceneCache`) takes
from tens of seconds (TOPEX) to minutes (the paper's COSMOS 2502 mesh). A `ShapeStore` keeps
each cache as a pickle in a directory (``<archive>/shapes/`` for fits of archived passes),
under the SHA-256 of

* the scene's content: triangles, shading normals, materials and their BRDFs, parts,
  articulations and the articulation values (so a mesh file and its materials JSON are keyed by
  what they hold, not by their names);
* the build settings (accuracy, articulation grid, glint sampling);
* the source of the modules whose objects the pickle holds (a changed renderer builds anew).

Fits of many passes, and the workers of a campaign, load the cache the first fit built. A
builder holds an exclusive lock on ``<key>.lock`` while it builds, so a second process asking
for the same cache waits for it instead of building it twice; the pickle is written to a
temporary file and renamed into place, so a reader never sees half a file. Within one process
the last few caches stay in memory.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Mapping
import fcntl
import hashlib
import importlib.util
import json
import os
from pathlib import Path
import pickle
import tempfile

import numpy as np

__all__ = ["ShapeStore", "code_fingerprint", "scene_fingerprint"]

# Modules whose classes and behaviour a stored cache depends on.
_CODE_MODULES = (
    "raycast.renderer.cache",
    "raycast.renderer._cache_kernels",
    "raycast.renderer.scene",
    "raycast.renderer.brdf",
    "raycast.renderer.rays",
    "rsodb.fit.shape_store",
)
_IN_MEMORY = 4
_MEMORY: OrderedDict = OrderedDict()


def code_fingerprint() -> str:
    """SHA-256 of the source of the modules a shape cache is built and evaluated with (the
    forward model's code): part of every cache's key, so a change to them rebuilds."""
    digest = hashlib.sha256()
    for name in _CODE_MODULES:
        origin = importlib.util.find_spec(name).origin
        digest.update(name.encode())
        digest.update(Path(origin).read_bytes())
    return digest.hexdigest()


def scene_fingerprint(scene) -> str:
    """SHA-256 of a `raycast.renderer.scene.Scene`'s content (geometry, materials, articulations)."""
    digest = hashlib.sha256()
    for array in (scene.corners_m, scene.corner_normals, scene.material_index, scene.part_index):
        value = np.ascontiguousarray(array)
        digest.update(str(value.dtype).encode() + str(value.shape).encode())
        digest.update(value.tobytes())
    record = {
        "materials": list(scene.material_names),
        "brdfs": [repr(b) for b in scene.brdfs],
        "parts": list(scene.part_names),
        "articulations": [repr(a) for a in scene.articulations],
        "parameters": sorted((k, float(v)) for k, v in dict(scene.parameters).items()),
    }
    digest.update(json.dumps(record, sort_keys=True).encode())
    return digest.hexdigest()


class ShapeStore:
    """Shape caches on disk (or only in memory when `directory` is None).

    Parameters
    ----------
    directory : path or None
        Where the ``<key>.pkl`` files go (created on first write).
    """

    def __init__(self, directory=None):
        self.directory = None if directory is None else Path(directory)

    def __repr__(self) -> str:
        return f"ShapeStore({str(self.directory) if self.directory else None!r})"

    def key(self, scene, settings: Mapping) -> str:
        """The content key of `scene` built with `settings`."""
        record = {
            "scene": scene_fingerprint(scene),
            "settings": json.loads(json.dumps(dict(settings), sort_keys=True, default=str)),
            "code": code_fingerprint(),
        }
        return hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()[:32]

    def path(self, key: str) -> Path | None:
        return None if self.directory is None else self.directory / f"{key}.pkl"

    def get(self, scene, settings: Mapping, build: Callable):
        """The cache of `scene` with `settings`: from memory, from disk, or ``build()`` (then stored).

        Parameters
        ----------
        scene : Scene
            What the cache is built from (its content is the key).
        settings : mapping
            JSON-friendly build settings (part of the key).
        build : callable
            ``build() -> SceneCache``, called only when no stored cache matches.
        """
        key = self.key(scene, settings)
        remembered = (str(self.directory), key)
        if remembered in _MEMORY:
            _MEMORY.move_to_end(remembered)
            return _MEMORY[remembered]
        path = self.path(key)
        if path is None:
            cache = build()
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            with open(path.with_suffix(".lock"), "a") as lock:
                # One builder per key; other processes wait here and then read its file.
                fcntl.flock(lock, fcntl.LOCK_EX)
                try:
                    cache = _load(path)
                    if cache is None:
                        cache = build()
                        _save(cache, path)
                finally:
                    fcntl.flock(lock, fcntl.LOCK_UN)
        _MEMORY[remembered] = cache
        while len(_MEMORY) > _IN_MEMORY:
            _MEMORY.popitem(last=False)
        return cache


def _load(path: Path):
    """The pickled cache at `path`, or None when there is none or it cannot be read."""
    try:
        with open(path, "rb") as handle:
            return pickle.load(handle)
    except FileNotFoundError:
        return None
    except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ImportError, TypeError, ValueError):
        # A file from an incompatible build, or truncated by a crash before the rename existed:
        # rebuild and replace it.
        return None


def _save(cache, path: Path) -> None:
    handle, partial = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    try:
        with os.fdopen(handle, "wb") as out:
            pickle.dump(cache, out, protocol=pickle.HIGHEST_PROTOCOL)
            out.flush()
            os.fsync(out.fileno())
        os.replace(partial, path)
    except BaseException:
        Path(partial).unlink(missing_ok=True)
        raise
