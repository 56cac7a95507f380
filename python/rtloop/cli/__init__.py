"""The command lines: ``rtloop-fit`` (:mod:`.fit`), ``rtloop-acquire`` (:mod:`.acquire`) and
``rtloop-scene`` (:mod:`.scene`), with their shared argument types in :mod:`.args`."""

from __future__ import annotations

from .._interrupt import interrupted_at_import

try:
    from .fit import main
except KeyboardInterrupt:
    interrupted_at_import()  # a console script starting: one line, exit 130
    raise

__all__ = ["main"]
