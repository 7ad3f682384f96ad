"""``python -m wholebody`` = the ``wholebody`` command."""

import sys

from .cli import main

sys.exit(main())
