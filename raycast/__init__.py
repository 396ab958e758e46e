"""The physical scene: orbit and observer geometry, attitude, shapes, BRDFs and the renderer.

raycast never imports rsodb.
"""
from raycast.site import Site

__all__ = ["Site"]
