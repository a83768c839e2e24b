"""Shared pytest configuration: hypothesis profiles and the tests/ helper modules on sys.path.

pytest runs in importlib mode (pyproject.toml), so the checkout's ``avp/`` is never put on
sys.path ahead of the installed package; only this directory is added, for ``scenarios`` and
``oracles``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from hypothesis import HealthCheck, settings

sys.path.insert(0, str(Path(__file__).parent))

settings.register_profile(
    "ci", derandomize=True, deadline=None, max_examples=60,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("dev", deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow])
# HYPOTHESIS_PROFILE=stress: a long local run before a release (not in CI)
settings.register_profile("stress", deadline=None, max_examples=1000, suppress_health_check=list(HealthCheck))
settings.load_profile("ci" if os.environ.get("CI") else os.environ.get("HYPOTHESIS_PROFILE", "dev"))
