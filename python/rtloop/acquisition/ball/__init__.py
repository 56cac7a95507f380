"""The ball: its outline in the photo (a cone of grazing rays, not a circle) and its centre in 3-D.

:func:`locate_ball` (``rtloop-scene``) searches the floor position of a resting ball of known radius
whose predicted outline lies on colour edges and whose inside is shaded like a sphere (not its shadow);
:func:`find_ball` fits a free cone without a pose;
:func:`place_sphere` turns an outline into the centre. Modules: ``cone``, ``edges``, ``search``,
``placement``, ``shading``.
"""

from __future__ import annotations

from .cone import BallSilhouette, silhouette_polyline
from .placement import SpherePlacement, locate_ball, place_sphere
from .search import find_ball

__all__ = [
    "BallSilhouette",
    "SpherePlacement",
    "find_ball",
    "locate_ball",
    "place_sphere",
    "silhouette_polyline",
]
