"""Models built by code: TOPEX/Poseidon (with and without louvers), a COSMOS 2502 look-alike and a
generic box with two solar-panel wings.

``MODELS`` maps a model name to its ``build(**parameters) -> Scene``; the paper's own COSMOS
2502 mesh is read from ../shared/data/models with :meth:`raycast.renderer.scene.Scene.from_file`.
"""

from functools import partial

from raycast.models import box_panels, cosmos2502, topex

MODELS = {
    "topex": topex.build,
    "topex_louvered": partial(topex.build, louvers=True),
    "cosmos2502": cosmos2502.build,
    "box_panels": box_panels.build,
}

__all__ = ["MODELS", "topex", "cosmos2502", "box_panels"]
