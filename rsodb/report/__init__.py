"""Reports: self-contained HTML documents with embedded plots.

`REPORT_KINDS` maps a report kind to the module that builds it. Each module exposes
``DESCRIPTION`` (one line), ``EXAMPLE`` (usage text), ``add_arguments(parser)`` (its command-line
options) and ``build_from_args(args) -> rsodb.report.html.Document``; ``rsodb report KIND``
lists the kinds from this table, so adding a kind is one line here plus its module.
"""
from __future__ import annotations

import importlib

__all__ = ["REPORT_KINDS", "report_module"]

# Kind -> module (imported only when that kind is used).
REPORT_KINDS = {
    "periods": "rsodb.report.periods",
    "campaign": "rsodb.report.campaign",
}


def report_module(kind: str):
    """The module that builds reports of `kind`."""
    if kind not in REPORT_KINDS:
        raise ValueError(f"unknown report kind {kind!r}; known kinds: {', '.join(REPORT_KINDS)}")
    return importlib.import_module(REPORT_KINDS[kind])
