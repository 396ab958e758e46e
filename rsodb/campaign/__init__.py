"""Work over many passes: the period survey of an archive, spin-state fit campaigns on Dask and model
ladders.

See docs/periods.md (survey), docs/fitting.md (campaigns) and docs/real_passes.md (ladders).
"""

import lazy_loader

# Loaded on first use: the period survey must not import the fitting machinery.
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "fit_campaign": ["CampaignOutcome", "run_campaign", "run_campaigns", "select_passes"],
        "ladder": ["LadderPlan", "LadderResult", "LadderSettings", "Rung", "run_ladder", "score_ladder"],
        "period_survey": ["PeriodSurvey", "load_period_results", "survey_periods"],
    },
)
