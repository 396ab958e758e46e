"""Models built by code: TOPEX/Poseidon (with and without louvers) and a COSMOS 2502 look-alike.

``MODELS`` maps a model name to its ``build(**parameters) -> Scene``; the paper's own COSMOS
2502 mesh is read from ../shared/data/models with :meth:`raycast.renderer.scene.Scene.from_file`.
"""

from functools import partial

from raycast.models import cosmos2502, topex

MODELS = {"topex": topex.build, "topex_louvered": partial(topex.build, louvers=True), "cosmos2502": cosmos2502.build}

__all__ = ["MODELS", "topex", "cosmos2502"]
