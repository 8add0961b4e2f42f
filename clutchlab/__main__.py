"""``python -m clutchlab``: the ``clutchlab`` command line."""

import sys

from .cli import main

sys.exit(main())
