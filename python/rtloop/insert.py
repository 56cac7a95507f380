"""Virtual object insertion (differential rendering, after Debevec 1998): the fitted scene rendered with
and without added objects, composited into the photo: their render where they are seen, elsewhere the
photo plus the difference they make (shadows, bounce light)."""

from __future__ import annotations

import json
import os
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._files import MAX_TEXT_BYTES, read_regular
from .errors import RtloopError, RtloopWarning

__all__ = ["MAX_INSERT_PIXELS", "Insertion", "insert", "load_objects"]

#: The largest photo an insertion renders (README: "Input limits"): it takes some 115 bytes a pixel (the
#: two renders, their samples and the composite), 2.8 GB at this cap.
MAX_INSERT_PIXELS = 24_000_000


@dataclass(frozen=True)
class Insertion:
    """One insertion's images, all (H, W, ...) float32 at the photo's size: linear RGB except ``matte``
    (H, W) in [0, 1], the fraction of each pixel the added objects cover."""

    photo: np.ndarray
    composite: np.ndarray
    matte: np.ndarray
    with_objects: np.ndarray
    without: np.ndarray


def load_objects(source: Any) -> list[dict[str, Any]]:
    """Added objects in the scene format: a list, ``{"objects": [...]}``, or a JSON file holding either.

    A mesh's relative ``file`` is read from the JSON file's folder (from the current directory for a list
    or dict)."""
    where = "objects"
    folder = None
    if isinstance(source, (str, os.PathLike)):
        folder = Path(source).parent
        where = str(source)
        if not os.path.lexists(source):
            raise RtloopError(f"{where}: objects file not found")
        try:
            source = json.loads(read_regular(source, limit=MAX_TEXT_BYTES, what="objects file").decode("utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as e:
            raise RtloopError(f"{where}: cannot read the objects ({e})") from None
    if isinstance(source, dict):
        if "objects" not in source:
            raise RtloopError(f"{where}: expected a list of objects or {{\"objects\": [...]}}")
        source = source["objects"]
    if not isinstance(source, list) or not source or not all(isinstance(o, dict) for o in source):
        raise RtloopError(f"{where}: expected a non-empty list of objects (each a JSON object)")
    if folder is not None:
        source = [
            {**o, "file": str(folder / o["file"])} if o.get("shape") == "mesh" and isinstance(o.get("file"), str) else o
            for o in source
        ]
    return source


def _warn_enclosing(scene: dict[str, Any], added: list[dict[str, Any]], where: str) -> None:
    """An RtloopWarning for an added sphere that encloses the camera: the render sees only its inside (black
    where it also encloses the light, which then lights nothing outside it; any of a ``lights`` list)."""
    camera = np.asarray(scene["camera"]["position"], dtype=np.float64)
    lights = scene.get("lights") or [scene.get("light") or {}]
    for k, o in enumerate(added):
        if o.get("shape", "sphere") != "sphere":
            continue
        centre, radius = np.asarray(o["center"], dtype=np.float64), float(o["radius"])
        if np.linalg.norm(camera - centre) < radius:
            inside = any("position" in light and np.linalg.norm(np.asarray(light["position"]) - centre) < radius
                         for light in lights)
            what = "the camera and the light" if inside else "the camera"
            warnings.warn(f"{where}: objects[{k}] ({o.get('name', 'unnamed')}): the sphere encloses {what}: the "
                          "composite shows only its inside", RtloopWarning, stacklevel=3)


def insert(result: Any, photo: Any, objects: Any, *, spp: int = 16, response: str = "srgb",
           adaptive: bool = True, progress: Callable[[int, int], object] | None = None) -> Insertion:
    """Insert ``objects`` into ``photo`` under the light fitted in ``result`` (every light of a ``lights``
    list: each casts its shadow, a sphere's or rectangle's soft).

    Args:
        result: The fitted scene: a result.json path (rtloop-fit's), a scene dict or a Scene.
        photo: The photo: a file path (loaded with ``response``) or a linear (H, W, 3) array. Renders are
            made at its size, keeping the scene's field of view (its aspect ratio must be the scene's).
        objects: What to add (see :func:`load_objects`); scene-format objects, validated with the scene.
        spp: Samples per pixel (a stratified grid when square) where a pixel is supersampled; the matte
            counts the same samples.
        adaptive: Supersample only the pixels where a neighbour sees another object, the other side of a
            shadow edge or of a crease, or another colour, in either render (one sample elsewhere); False
            supersamples every pixel (each render then is ``render(scene, W, H, spp)``).
        progress: Called as ``progress(tiles_done, tiles_total)`` while rendering, at most every 0.1 s.
    """
    from . import _native, scene_to_dict
    from .scene import load_scene

    base = load_scene(result)
    base_dict = scene_to_dict(base)
    added = load_objects(objects)
    if isinstance(photo, (str, os.PathLike)):
        from .acquisition.response import load_photo

        image = load_photo(photo, None, response=response)  # as rtloop-fit reads it: oriented, RAW too
    else:
        image = np.asarray(photo, dtype=np.float32)
        if image.ndim != 3 or image.shape[2] != 3 or not np.isfinite(image).all():
            raise RtloopError(f"photo: expected a finite (H, W, 3) linear image, got shape {image.shape}")
    height, width = image.shape[:2]
    if width * height > MAX_INSERT_PIXELS:
        raise RtloopError(f"{photo if isinstance(photo, (str, os.PathLike)) else 'photo'}: {width}x{height} = "
                          f"{width * height / 1e6:.1f} megapixels, more than the {MAX_INSERT_PIXELS / 1e6:.0f} an "
                          "insertion renders; downscale the photo first")
    if abs(width / height - base_dict["image"]["width"] / base_dict["image"]["height"]) > 0.01 * width / height:
        raise RtloopError(f"photo: {width}x{height} does not have the scene's aspect ratio "
                          f"({base_dict['image']['width']}x{base_dict['image']['height']})")
    if not (isinstance(spp, int) and 1 <= spp <= 4096):
        raise RtloopError(f"spp: must be an integer 1..4096 (got {spp!r})")
    n_old = len(base_dict["objects"])
    where = os.fspath(objects) if isinstance(objects, (str, os.PathLike)) else "added objects"
    try:
        scene_with = load_scene({**base_dict, "objects": base_dict["objects"] + added})
    except RtloopError as e:  # named by their place in the objects given, not in the combined scene
        renamed = re.sub(r"^objects\[(\d+)\]", lambda m: f"objects[{int(m[1]) - n_old}]", str(e))
        raise RtloopError(f"{where}: {renamed}") from None
    _warn_enclosing(base_dict, added, where)
    (without, with_objects), matte, _ = _native.render_layers(
        [base, scene_with], width, height, spp, bool(adaptive), n_old, progress)
    composite = _native.composite(np.ascontiguousarray(image), with_objects, without, matte)
    return Insertion(image, composite, matte, with_objects, without)
