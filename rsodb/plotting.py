"""matplotlib, loaded only when a plot is drawn: it costs about a second of start-up, which
commands that draw nothing should not pay."""

from __future__ import annotations

__all__ = ["pyplot", "file_pyplot", "axes_or_new", "magnitude_label"]

_NOTEBOOK_BACKENDS = ("agg", "module://matplotlib_inline.backend_inline")


def pyplot():
    """matplotlib's pyplot, with whatever backend the session chose."""
    # Deferred: matplotlib is heavy and most calls of the library draw nothing.
    import matplotlib.pyplot as plt

    return plt


def file_pyplot():
    """pyplot for figures that go to files: the Agg backend, unless a notebook draws inline."""
    # Deferred: matplotlib is heavy and most calls of the library draw nothing.
    import matplotlib

    if matplotlib.get_backend().lower() not in _NOTEBOOK_BACKENDS:
        matplotlib.use("Agg")
    return pyplot()


def axes_or_new(ax, figsize=(8, 3.5)):
    """``ax`` itself, or the axes of a new figure of ``figsize`` inches."""
    return ax if ax is not None else pyplot().figure(figsize=figsize).add_subplot()


def magnitude_label(band: str = "", convention: str = "", detrended: bool = False) -> str:
    """The axis label of magnitudes: their band and range reduction, from a pass's `band` and
    `mag_convention`.

    >>> magnitude_label("V", "standard magnitude reduced to 1000 km range: ...")
    'V magnitude (reduced to 1000 km)'
    >>> magnitude_label("", "", detrended=True)
    'magnitude - trend'
    """
    label = f"{band} magnitude".strip()
    if "reduced to 1000 km" in (convention or ""):
        label += " (reduced to 1000 km)"
    return f"{label} - trend" if detrended else label
