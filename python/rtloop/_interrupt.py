"""A Ctrl-C while a console script imports rtloop (its first tenth of a second): one line and exit 130, as
once the script runs, instead of a KeyboardInterrupt traceback."""

from __future__ import annotations

import os
import sys

__all__ = ["SCRIPTS", "importing", "interrupted_at_import"]

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


class _Importing:
    """``with importing:`` around a console script module's imports: a Ctrl-C in them goes to
    :func:`interrupted_at_import` (one line and exit 130 when a script is starting), else propagates."""

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: object) -> bool:
        if kind is not None and issubclass(kind, KeyboardInterrupt):
            interrupted_at_import()
        return False


importing = _Importing()
