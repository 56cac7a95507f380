"""``python -m rtloop.cli``: the same as ``rtloop-fit``."""

import sys

from .fit import main

sys.exit(main())
