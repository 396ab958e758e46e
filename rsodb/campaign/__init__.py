"""Work over many passes: the period survey of an archive and spin-state fit campaigns on Dask.

See docs/periods.md (survey) and docs/fitting.md (campaigns).
"""

from rsodb.campaign.fit_campaign import CampaignOutcome, run_campaign, run_campaigns, select_passes
from rsodb.campaign.period_survey import PeriodSurvey, load_period_results, survey_periods

__all__ = [
    "CampaignOutcome",
    "run_campaign",
    "run_campaigns",
    "select_passes",
    "PeriodSurvey",
    "load_period_results",
    "survey_periods",
]
