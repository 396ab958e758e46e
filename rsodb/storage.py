"""Conversions between Python values and what HDF5 attributes and JSON can hold.

One place for the small conversions every stored record needs: text attributes that h5py may
return as bytes, numpy scalars and arrays that JSON cannot encode, and non-finite floats that
JSON has no literal for.
"""

from __future__ import annotations

from collections.abc import Mapping
import json
import math
from pathlib import PurePath

import numpy as np

__all__ = ["to_json", "attr_text", "attr_plain", "finite_or_none"]


def _encode(value):
    """JSON encoder hook for the non-JSON types stored records carry."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (tuple, set, frozenset)):
        return sorted(value) if isinstance(value, (set, frozenset)) else list(value)
    if isinstance(value, Mapping):
        return dict(value)
    if isinstance(value, PurePath):
        return str(value)
    raise TypeError(f"value {value!r} of type {type(value).__name__} cannot be stored as JSON")


def to_json(value, *, sort_keys: bool = False) -> str:
    """``value`` as JSON text, numpy scalars and arrays, tuples, sets, mappings and paths included.

    Examples
    --------
    >>> to_json({"n": np.int64(3), "x": np.arange(2.0)})
    '{"n": 3, "x": [0.0, 1.0]}'
    """
    return json.dumps(value, default=_encode, ensure_ascii=False, sort_keys=sort_keys)


def attr_text(value) -> str:
    """An HDF5 text attribute or field as ``str`` (h5py gives ``bytes`` for fixed-length strings)."""
    return value.decode("utf-8") if isinstance(value, bytes) else str(value)


def attr_plain(value):
    """An HDF5 attribute as a plain Python value: text, list or scalar."""
    if isinstance(value, bytes):
        return value.decode("utf-8")
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def finite_or_none(value) -> float | None:
    """A float for JSON: NaN and infinities become None."""
    value = float(value)
    return value if math.isfinite(value) else None
