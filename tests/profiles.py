"""Hypothesis profiles of the property and fuzz tests.

``ci`` (the default): the example counts written next to each test, sized
for the two-core CI. ``thorough``: the larger counts given for it. Select it
with ``--hypothesis-profile=thorough`` on a run whose paths include
``tests/fuzz`` (its conftest registers the profiles before hypothesis's
pytest plugin reads the option), e.g.
``pytest tests/fuzz tests/curves/test_plan.py --hypothesis-profile=thorough``.
"""

from hypothesis import HealthCheck, settings

# No deadline: a first example may compile kernels (seconds), later ones take milliseconds.
settings.register_profile("ci", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("thorough", parent=settings.get_profile("ci"))


def examples(ci: int, thorough: int) -> int:
    """``max_examples`` of a test under the active profile."""
    return thorough if settings.get_current_profile_name() == "thorough" else ci
