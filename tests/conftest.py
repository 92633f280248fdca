"""Test-wide settings.

Hypothesis draws the same examples on every run (``derandomize``), so that
``make test`` on a clean clone gives the same verdict each time. To explore
fresh examples, as one should after changing the core, run with
``HYPOTHESIS_PROFILE=explore``; pin what it finds with ``@example``.
"""

import os

from hypothesis import settings

settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))
