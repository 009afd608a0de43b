"""Fuzz tests: registers the hypothesis profiles (``tests/profiles.py``) and
makes ``ci`` the default unless ``--hypothesis-profile`` chose one."""

from hypothesis import settings

import tests.profiles  # noqa: F401  (registers the profiles)

if settings.get_current_profile_name() == "default":
    settings.load_profile("ci")
