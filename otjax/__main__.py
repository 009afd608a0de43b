"""``python -m otjax``: the same as the ``otjax`` command."""

import sys

from otjax.cli import entry

sys.exit(entry())
