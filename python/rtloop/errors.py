"""rtloop's exceptions.

Every error rtloop raises on bad input derives from :class:`RtloopError`, so a caller (or the
``rtloop-fit`` CLI) can catch one type and print one line. Messages name the offending field,
e.g. ``objects[1].normal: zero-length normal``.
"""

from ._native import RtloopError, SceneError


class AcquisitionError(RtloopError):
    """An objective image could not be read or does not fit the scene (file, format, size)."""


class SceneTypeError(SceneError, TypeError):
    """A scene given as something that is not a scene: neither a path, a dict, JSON text nor a Scene
    (also a TypeError, as Python expects of a wrong argument type)."""


class RtloopWarning(UserWarning):
    """An input rtloop accepts but doubts (an image that looks sRGB-encoded or 0..255, fitted values at their
    bounds); the same text is in the fit's ``warnings`` (``fit_report.warnings``)."""


__all__ = ["AcquisitionError", "RtloopError", "RtloopWarning", "SceneError", "SceneTypeError"]
