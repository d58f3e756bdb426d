"""Monte-Carlo campaigns: many seeded draws of a scenario or a campaign file, run locally or on a Dask
cluster (:mod:`.runner`: planning, running, outputs, the ``campaign`` command; :mod:`.cluster`: the
local cluster and the scheduler connection)."""
from __future__ import annotations

from .runner import (CampaignConfig, CampaignFile, RunSpec, Variation, is_campaign_file, load_campaign_file,
                     plan_campaign, plan_campaign_file, run_campaign, run_one)

__all__ = ["CampaignConfig", "CampaignFile", "RunSpec", "Variation", "is_campaign_file", "load_campaign_file",
           "plan_campaign", "plan_campaign_file", "run_campaign", "run_one"]
