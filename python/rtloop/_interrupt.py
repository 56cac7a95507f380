"""A Ctrl-C while a console script imports rtloop (its first tenth of a second): one line and exit 130, as
once the script runs, instead of a KeyboardInterrupt traceback."""

from __future__ import annotations

import os
import sys

__all__ = ["SCRIPTS", "interrupted_at_import"]

#: The console scripts of pyproject.toml.
SCRIPTS = ("rtloop-fit", "rtloop-scene", "rtloop-acquire", "rtloop-insert")


def interrupted_at_import() -> None:
    """Called in an ``except KeyboardInterrupt`` around imports: when a console script is starting, say so
    and exit 130; otherwise (a library import) return, and the caller re-raises."""
    script = os.path.basename(sys.argv[0]) if sys.argv else ""
    if script not in SCRIPTS:
        return
    print(f"{script}: interrupted", file=sys.stderr, flush=True)
    raise SystemExit(130) from None
