"""The errors a user's files raise: a wrong configuration, or wrong data."""
from __future__ import annotations


class ConfigError(ValueError):
    """A configuration or campaign file is wrong; the message names file and key."""
