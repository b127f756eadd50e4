"""The planner tests' small search budgets."""
from dataclasses import replace

import pytest


@pytest.fixture
def small(settings):
    """The paper's settings (``settings``) with a small search: 2048 candidates, 64 after the first hit,
    batches of 64, 8 start postures."""
    return replace(settings, motion=replace(settings.motion, max_candidates=2048, extra_after_hit=64, batch=64,
                                            posture_pool=8))
