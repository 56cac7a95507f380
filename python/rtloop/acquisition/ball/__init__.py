"""The ball: its silhouette in the photo and its place in 3-D.

A sphere's outline in a pinhole image is not a circle but an ellipse (stretched away from the image
centre). What is exact is the *cone* of rays that graze the sphere: every silhouette ray ``d`` makes
the same angle ``alpha`` with the direction ``u`` to the sphere's centre, ``sin(alpha) = r / D`` at
distance ``D``. So the silhouette has three degrees of freedom, like a circle, and this module fits
that cone rather than a circle.

* :func:`locate_ball` (what ``rtloop-scene`` uses) knows the posed camera, the floor and the radius.
  A ball resting on the floor has only two unknowns, its centre's ``x`` and ``z``, and its outline
  (size included) follows from them exactly. Hough circles (on brightness and on colour saturation),
  or the user's hint ``(x, y, r)``, or a user-drawn mask, only seed a search over the floor position
  that scores each predicted outline by how well it lies on colour edges running along it. This
  tells the ball from its own shadow (a crisp ellipse too, but not the outline of a resting ball of
  that radius), from shading just inside the ball, and from textured surroundings. The best outline
  then gets sub-pixel edge points across it (the strongest colour step on each ray from its centre)
  and the centre is fitted to them by least squares (``place_sphere``'s model). With
  ``resting=False`` a last fit frees the centre's height (distance then comes from the apparent size
  alone, less precisely), which also tells how far the ball is from resting on the floor.
* :func:`find_ball` needs no pose: it fits the free cone ``(u, alpha)`` (3 unknowns) by RANSAC to
  edge points along rays from each Hough candidate, keeping the best-supported one. It cannot tell
  a ball from its shadow by size, so prefer ``locate_ball`` when the camera is posed.
* :func:`place_sphere` turns an outline into the sphere's centre in the world (resting on the floor,
  or free), fitting the centre to the outline's edge rays by least squares.

Modules: ``cone`` (the cone and its outline), ``edges`` (edge points, robust fits, outline scores),
``search`` (find_ball, the seeds), ``placement`` (place_sphere, locate_ball).

Edge points near a dark side of the ball against its own shadow cannot be seen and are left out:
the visible part of the outline (at least about a third of it) is enough.
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
