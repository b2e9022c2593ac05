"""Settings of the property tests, one place for all packages.

``make test`` draws the same examples on every machine (the ``repeatable``
profile, loaded in ``tests/conftest.py``), so CI gives the developer's
answer. ``HYPOTHESIS_PROFILE=explore pytest tests/`` draws new random
examples, ten times as many, to look for failures; add each one it finds to
its test as an ``@example`` before fixing it.
"""

from __future__ import annotations

from hypothesis import HealthCheck, settings


def property_settings(examples: int) -> settings:
    """``examples`` per test (ten times that under the ``explore`` profile), no deadline."""
    scale = 10 if settings._current_profile == "explore" else 1
    return settings(
        max_examples=examples * scale,
        deadline=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture],
    )
