"""The photo as a fit observes it (:class:`Observation`): the image, its mask and a grey card checked
against the scene, and what the fit reads from the photo once: its 8-bit codes and sRGB encoding, its
noise, its JPEG blocking, the level from which a pixel may be clipped, the margin a JPEG's colour leaves
round the outlines and the objects seen at each pixel."""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _native
from .._srgb import codes8
from ..scene import Scene
from .goodness import clip_level, encoded, jpeg_blocking, noise_sigma
from .inputs import objective
from .jpeg import JPEG_CHROMA_MARGIN, is_jpeg
from .norm import pixel_mask
from .reference import check_reference

__all__ = ["Observation", "observe"]


@dataclass(frozen=True)
class Observation:
    """The photo a fit compares its scene with. ``target``: float32 (H, W, 3) linear radiance; ``use``: the
    used pixels' flat indices (None: all) and ``mask`` the mask they come from (as given, or the pixels a
    refit keeps); ``doubts``: what the image's values make doubtful; ``card``: a grey card ``(bool (H, W),
    reflectance)`` or None. Read from the photo: ``codes``, its 8-bit codes where it has them
    (:func:`rtloop._srgb.codes8`: a PNG or JPEG as load_image decodes it, whose sRGB transfer functions then
    come from a table of the 256, the same numbers), ``encoding`` its sRGB encoding, ``sigma`` its noise per
    channel (:func:`.goodness.noise_sigma`), ``blocking`` its JPEG blocking (:func:`.goodness.jpeg_blocking`),
    ``saturated`` the level from which a pixel may be clipped (below 1 by the photo's own noise and JPEG
    error, :func:`.goodness.clip_level`; None: no clipping, or the core's own level) and ``solve_margin`` the
    pixels round another object's that do not inform the products (a JPEG's 4:2:0 chroma mixes its colour
    across silhouettes: JPEG_CHROMA_MARGIN; else 0)."""

    scene: Scene
    target: np.ndarray
    use: np.ndarray | None
    mask: Any
    doubts: tuple[str, ...]
    card: tuple[np.ndarray, float] | None
    codes: np.ndarray | None
    encoding: np.ndarray
    sigma: np.ndarray
    blocking: dict[str, Any]
    saturated: float | None
    solve_margin: int

    @property
    def jpeg(self) -> bool:
        """Whether the photo is a JPEG by its blocking (:func:`.jpeg.is_jpeg`)."""
        return is_jpeg(self.blocking)

    @property
    def pixels(self) -> int:
        """How many pixels the fit uses."""
        return self.scene.width * self.scene.height if self.use is None else int(self.use.size)

    @functools.cached_property
    def ids(self) -> np.ndarray:
        """The object seen at each pixel centre (-1: the background), once: the fit does not move the
        geometry."""
        return np.asarray(_native.object_ids(self.scene))

    def within(self, pixels: np.ndarray) -> Observation:
        """The photo with only the flat indices ``pixels`` used (its mask theirs)."""
        mask = pixel_mask(pixels, self.scene.width, self.scene.height)
        out = dataclasses.replace(self, use=pixels, mask=mask)
        if "ids" in self.__dict__:
            out.__dict__["ids"] = self.ids
        return out


def observe(scene: Scene, image: Any, mask: Any, reference: tuple[Any, float] | None, *, clip: bool) -> Observation:
    """``image`` (with ``mask`` and a grey card ``reference``, fit()'s arguments) checked against ``scene``
    and read once (:class:`Observation`); ``clip``: fit()'s, whether a pixel may be clipped at all."""
    doubts: list[str] = []
    target, use = objective(scene, image, mask, doubts)
    card = None if reference is None else (check_reference(scene, reference[0], reference[1]), reference[1])
    codes = codes8(target)
    encoding = encoded(target, codes)
    sigma, blocking = noise_sigma(target), jpeg_blocking(target, encoding)
    return Observation(scene=scene, target=target, use=use, mask=mask, doubts=tuple(doubts), card=card,
                       codes=codes, encoding=encoding, sigma=sigma, blocking=blocking,
                       saturated=clip_level(sigma, blocking) if clip else None,
                       solve_margin=JPEG_CHROMA_MARGIN if is_jpeg(blocking) else 0)
