"""Large photos: the ball is searched for in a copy at most :data:`WORK_SIDE` pixels on its longer side, and
the outline it finds is then refined on the photo itself.

The search's steps are sized in pixels (the outline score samples at most 15 offsets across its tolerance,
a quarter of the ball's radius in the coarse stage; the Hough circles' blur grows with the image), so a
ball hundreds of pixels across, as an 11 MP photo shows it, slips between the samples: searched at their
own size, scenes rendered at 4032 x 3024 give no ball, or one off by 5 % of its distance, where at 640 x 480
they give one within 0.1 %. The copy is the photo resized by the same factor on both axes up to rounding
(``cv2.resize`` with INTER_AREA: the centre pixel maps onto the centre pixel), seen by the same camera with
its focal length scaled (:meth:`PinholeCamera.resized`); the outline's cone (its axis and angle) and the
sphere's centre in the world do not depend on the image's size.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from .._common import AcquisitionError
from .cone import BallSilhouette

#: The longest side (pixels) the ball is searched for at; a larger photo is searched at this size. A ball a
#: metre across filling a third of a 4032 x 3024 photo (807 px radius) is found at 1600 and not at 2048.
WORK_SIDE = 1600


def working_size(width: int, height: int) -> tuple[int, int] | None:
    """The size of the search's copy of a ``width`` x ``height`` photo, or None where the photo is small
    enough to search as it is."""
    side = max(width, height)
    if side <= WORK_SIDE:
        return None
    k = WORK_SIDE / side
    return max(8, round(width * k)), max(8, round(height * k))


class Working:
    """The map between a photo (``full``: width, height) and its search copy (``small``)."""

    def __init__(self, full: tuple[int, int], small: tuple[int, int]):
        self.full, self.small = full, small
        self.sx, self.sy = full[0] / small[0], full[1] / small[1]

    def image(self, image: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(cv2.resize(image, self.small, interpolation=cv2.INTER_AREA), np.float32)

    def to_small(self, pts: np.ndarray) -> np.ndarray:
        pts = np.asarray(pts, dtype=float).reshape(-1, 2)
        return np.column_stack([(pts[:, 0] + 0.5) / self.sx - 0.5, (pts[:, 1] + 0.5) / self.sy - 0.5])

    def to_full(self, pts: np.ndarray) -> np.ndarray:
        pts = np.asarray(pts, dtype=float).reshape(-1, 2)
        return np.column_stack([(pts[:, 0] + 0.5) * self.sx - 0.5, (pts[:, 1] + 0.5) * self.sy - 0.5])

    def hint(self, hint: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        """A hint (x, y, radius in the photo's pixels, already checked against it) in the copy's pixels."""
        if hint is None:
            return None
        x, y = self.to_small(np.array([hint[0], hint[1]]))[0]
        return float(x), float(y), max(3.0, float(hint[2]) * 2 / (self.sx + self.sy))

    def mask(self, mask: Any, where: str) -> np.ndarray | None:
        """The user's ball mask (the photo's size, checked) at the copy's size."""
        if mask is None:
            return None
        m = np.asarray(mask)
        w, h = self.full
        if m.shape[:2] != (h, w):
            raise AcquisitionError(
                f"{where}: the ball mask is {m.shape[1]}x{m.shape[0]} but the photo is {w}x{h}; draw the "
                "mask on the photo itself (same size)"
            )
        m8 = (m.reshape(h, w, -1).max(axis=2) > 0).astype(np.uint8) * 255
        return cv2.resize(m8, self.small, interpolation=cv2.INTER_AREA) >= 128

    def polygon(self, poly: np.ndarray | None) -> np.ndarray | None:
        return None if poly is None else self.to_small(poly)

    def silhouette(self, sil: BallSilhouette, focal_px: float) -> BallSilhouette:
        """An outline found in the copy, on the photo (the same cone; its points and RMS in the photo's
        pixels)."""
        return BallSilhouette(
            sil.axis, sil.alpha, float(focal_px), self.full[0], self.full[1], self.to_full(sil.edge_points),
            sil.rms_px * math.sqrt(self.sx * self.sy), sil.coverage, sil.source, dict(sil.extra),
        )
