"""Light curves of resident space objects: the archive, spin periods, synthetic light curves and fits.

The front door: what a notebook needs, loaded on first use (so ``rsodb --help`` stays fast).

>>> import rsodb
>>> archive = rsodb.Archive("archive")                                   # doctest: +SKIP
>>> stored = archive.passes(norad=22076)[0]                              # doctest: +SKIP
>>> rsodb.find_period(stored.lightcurve()).best_period_s                 # doctest: +SKIP

Sub-packages by domain: `rsodb.archive` (the HDF5 archive), `rsodb.periods` (period search),
`rsodb.fit` (spin-state fits), `rsodb.campaign` (surveys and fits over many passes),
`rsodb.report` (HTML reports), `rsodb.samples` (generated sample data), `rsodb.cli` (commands).
"""

import lazy_loader

__version__ = "0.1.0"

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submodules=[
        "archive",
        "periods",
        "fit",
        "campaign",
        "report",
        "samples",
        "rendering",
        "pipeline",
        "pool",
        "storage",
        "cli",
    ],
    submod_attrs={
        "archive": ["Archive", "StoredPass"],
        "periods": ["LightCurve", "find_period", "PeriodResult", "PeriodSettings"],
        "fit": ["FitConfig", "FitResult", "fit_pass"],
        "campaign": ["run_campaign", "survey_periods"],
        "rendering": ["load_scene", "render_pass"],
        "pipeline": ["run_pipeline"],
        "archive.eossa": ["write_eossa"],
    },
)
