"""From files to a fit: the one path ``rtloop-fit`` and every job of ``rtloop-fit --batch`` take. The scene,
the photo, the mask (the one given, else the one the scene names) and the grey card (the one the scene names,
unless another or none is given) are read with the same options by :func:`load_inputs`, and :func:`fit_inputs`
calls :func:`rtloop.fit` with them."""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RtloopError, RtloopWarning

__all__ = ["SCENE_CARD", "Inputs", "fit_inputs", "load_inputs", "scene_card", "scene_mask"]

#: ``grey_card`` of :func:`load_inputs`: the card the scene names (``meta.acquisition.grey_card``), if any.
SCENE_CARD = "scene"


@dataclass
class Inputs:
    """What a fit reads from files: the scene, the photo (linear, at the scene's size), the mask and grey
    card (None where none), the mask's path and the warnings reading them gave."""

    scene: Any
    image: np.ndarray
    mask: np.ndarray | None = None
    mask_path: str | None = None
    reference: tuple[np.ndarray, float] | None = None
    warnings: list[str] = field(default_factory=list)
    response: str = "srgb"
    #: The field of view's uncertainty rtloop-scene recorded (``meta.acquisition.field_of_view``, checked:
    #: :mod:`rtloop.uncertainty.field_of_view`), None where the scene has none.
    field_of_view: dict[str, Any] | None = None


def _acquisition(scene_path: str | os.PathLike[str]) -> dict[str, Any]:
    """The scene file's ``meta.acquisition`` (rtloop-scene's record), {} where it has none."""
    try:
        meta = json.loads(Path(scene_path).read_text(encoding="utf-8")).get("meta") or {}
        acq = meta.get("acquisition") or {}
    except (OSError, ValueError, AttributeError, RecursionError):
        return {}  # load_scene has read it already: not a JSON object we can look into
    return acq if isinstance(acq, dict) else {}


def scene_mask(scene_path: str | os.PathLike[str]) -> Path | None:
    """The mask a scene names (``meta.acquisition.mask``, written by rtloop-scene), relative to the scene's
    folder; None when it names none."""
    name = _acquisition(scene_path).get("mask")
    if not isinstance(name, str):
        return None
    path = Path(scene_path).parent / name
    if not path.is_file():
        raise RtloopError(f"{scene_path}: meta.acquisition.mask names {name}, but {path} is not a file; "
                          "put it back, or pass --mask")
    return path


def scene_card(scene_path: str | os.PathLike[str]) -> tuple[Path, float] | None:
    """The grey card a scene names (``meta.acquisition.grey_card``: ``mask``, a PNG white inside the card,
    relative to the scene's folder, and ``reflectance``), written by rtloop-scene --grey-card-reflectance."""
    card = _acquisition(scene_path).get("grey_card") or {}
    if not isinstance(card, dict) or not isinstance(card.get("mask"), str):
        return None
    name, reflectance = card["mask"], card.get("reflectance")
    if not isinstance(reflectance, (int, float)) or isinstance(reflectance, bool):
        raise RtloopError(f"{scene_path}: meta.acquisition.grey_card.reflectance must be a number (e.g. 0.18)")
    path = Path(scene_path).parent / name
    if not path.is_file():
        raise RtloopError(f"{scene_path}: meta.acquisition.grey_card.mask names {name}, but {path} is not a file")
    return path, float(reflectance)


def referenced(scene_path: str | os.PathLike[str], mask: str | None, grey_card: Any = SCENE_CARD
               ) -> tuple[str | None, tuple[str, float] | None]:
    """The mask and grey card (path, reflectance) a fit of this scene reads: the given ones, else the
    scene's (:func:`scene_mask`, :func:`scene_card`)."""
    mask_path = mask if mask is not None else scene_mask(scene_path)
    card = scene_card(scene_path) if grey_card == SCENE_CARD else grey_card
    return (None if mask_path is None else str(mask_path),
            None if card is None else (str(card[0]), float(card[1])))


def load_inputs(scene_path: str | os.PathLike[str], photo_path: str | os.PathLike[str], *,
                mask: str | None = None, response: str = "srgb", crop: bool = False,
                grey_card: Any = SCENE_CARD) -> Inputs:
    """Read a fit's files: the scene, the photo (``response``, ``crop`` as :func:`rtloop.load_image`), the
    mask (``mask``, else the one the scene names) and the grey card (``grey_card``: :data:`SCENE_CARD` for the
    scene's, None for none, or ``(path, reflectance)``). Warnings are collected, not shown."""
    import rtloop

    scene = rtloop.load_scene(scene_path)
    mask_path, card = referenced(scene_path, mask, grey_card)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        image = rtloop.load_image(photo_path, scene, response=response, crop=crop)
        pixels = None if mask_path is None else rtloop.load_mask(mask_path, scene, crop=crop)
        reference = None if card is None else (rtloop.load_mask(card[0], scene, crop=crop), card[1])
    return Inputs(scene, image, pixels, mask_path, reference, [str(w.message) for w in caught], response,
                  scene_field_of_view(scene_path, scene))


def scene_field_of_view(scene_path: str | os.PathLike[str], scene: Any) -> dict[str, Any] | None:
    """The field of view's uncertainty the scene records (``meta.acquisition.field_of_view``, written by
    rtloop-scene for a photo without EXIF), checked; None where it records none."""
    from ..uncertainty.field_of_view import check_field_of_view

    spheres = {o.get("name") for o in scene.to_dict().get("objects", []) if o.get("shape") == "sphere"}
    return check_field_of_view(_acquisition(scene_path).get("field_of_view"), spheres,
                               f"{scene_path}: meta.acquisition.field_of_view")


def fit_inputs(inputs: Inputs, *, seed: int = 0, threads: int | None = None, callback: Any = None,
               **options: Any) -> Any:
    """:func:`rtloop.fit` on what :func:`load_inputs` read (``options`` as its keyword arguments); its
    warnings are in the result's ``warnings``, not shown. A photo read as linear (``response="linear"``)
    stays linear: ``tone="linear"`` (no curve tested, no doubt of an sRGB encoding) unless ``tone`` says
    otherwise."""
    import rtloop

    if inputs.response == "linear" and options.get("tone", "auto") == "auto":
        options = {**options, "tone": "linear"}

    flat = options.get("flat_field")
    if isinstance(flat, (tuple, list)):  # (path, response): the photo of a flat white target
        options["flat_field"] = rtloop.load_image(flat[0], inputs.scene, response=flat[1])
    def run(scene: Any, **more: Any) -> Any:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RtloopWarning)
            return rtloop.fit(scene, inputs.image, seed=seed, threads=threads, mask=inputs.mask,
                              reference=inputs.reference, **{**options, **more})

    result = run(inputs.scene, callback=callback)
    if inputs.field_of_view is not None and getattr(result, "uncertainty", None):
        from ..uncertainty.field_of_view import carry_field_of_view

        carry_field_of_view(result, inputs.field_of_view,
                            lambda d: run(rtloop.load_scene(d), uncertainty=False), inputs.scene.to_dict())
    return result
