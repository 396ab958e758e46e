"""Reports: self-contained HTML documents with embedded plots.

`build_period_report` (period survey of one object), `build_campaign_report` (its spin-state
fits), `build_ladder_report` (model ladders) and `build_index` (the main job's index page) each
return a `Document`; ``doc.write(path)`` writes it.
"""

from rsodb.report.fit_report import build_campaign_report, load_fits
from rsodb.report.html import Document
from rsodb.report.index_page import build_index
from rsodb.report.ladder_report import build_ladder_report, ladder_section
from rsodb.report.pass_figure import save_pass_plot
from rsodb.report.period_report import build_period_report

__all__ = [
    "build_campaign_report",
    "load_fits",
    "Document",
    "build_index",
    "build_ladder_report",
    "ladder_section",
    "save_pass_plot",
    "build_period_report",
]
