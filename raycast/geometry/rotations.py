"""Small rotation matrices over arrays of angles, in one layout: (..., 3, 3), angles leading."""

from __future__ import annotations

import numpy as np

__all__ = ["rot_z"]


def rot_z(angle_rad) -> np.ndarray:
    """(..., 3, 3) Rz(angle): rotates vectors counterclockwise about +z by ``angle_rad`` (...).

    Examples
    --------
    >>> rot_z(np.pi / 2).round(12) @ [1.0, 0.0, 0.0]
    array([0., 1., 0.])
    """
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    out = np.zeros(np.shape(angle_rad) + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1], out[..., 2, 2] = c, -s, s, c, 1.0
    return out
