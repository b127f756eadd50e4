"""Self-contained HTML reports per trial and per campaign, with their figures.
"""
from .campaign_page import write_campaign_report
from .pages import write_trial_report

__all__ = ["write_campaign_report", "write_trial_report"]
