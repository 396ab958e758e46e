"""matplotlib, loaded only when a plot is drawn: it costs about a second of start-up, which
commands that draw nothing should not pay."""

from __future__ import annotations

__all__ = ["pyplot", "file_pyplot", "axes_or_new"]

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
