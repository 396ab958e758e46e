"""Work over many passes: the period survey of an archive, spin-state fit campaigns on Dask and model
ladders.

See docs/periods.md (survey), docs/fitting.md (campaigns) and docs/real_passes.md (ladders).
"""

from rsodb.campaign.fit_campaign import CampaignOutcome, run_campaign, run_campaigns, select_passes
from rsodb.campaign.ladder import LadderPlan, LadderResult, LadderSettings, Rung, run_ladder, score_ladder
from rsodb.campaign.period_survey import PeriodSurvey, load_period_results, survey_periods

__all__ = [
    "CampaignOutcome",
    "run_campaign",
    "run_campaigns",
    "select_passes",
    "LadderPlan",
    "LadderResult",
    "LadderSettings",
    "Rung",
    "run_ladder",
    "score_ladder",
    "PeriodSurvey",
    "load_period_results",
    "survey_periods",
]
