"""The command lines: ``rtloop-fit`` (:mod:`.fit`), ``rtloop-acquire`` (:mod:`.acquire`) and
``rtloop-scene`` (:mod:`.scene`), with their shared argument types in :mod:`.args`."""

from __future__ import annotations

from .._interrupt import importing

with importing:  # a Ctrl-C while a console script starts: one line, exit 130
    from .fit import main

__all__ = ["main"]
