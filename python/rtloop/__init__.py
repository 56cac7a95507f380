"""rtloop: recover a scene's light and colours from one photo by rendering in the loop.

A hand-built scene (camera, spheres, planes, one point light) plus a photo go in; a differential-evolution
search over the scene's free parameters, driven by rtloop's own ray tracer, brings back the light's
position and intensity and the objects' colours. See docs/scene-format.md for the scene format.

    scene = rtloop.load_scene("examples/yellow-ball/scene_input.json")
    photo = rtloop.load_image("examples/yellow-ball/objective.png", scene)
    result = rtloop.fit(scene, photo, seed=1)
    result.scene          # the fitted scene
"""

from ._interrupt import importing as _importing

with _importing:  # a Ctrl-C while a console script starts: one line, exit 130
    import numpy as _np

    from . import _native
    from ._native import Scene, __version__
    from ._srgb import srgb_to_linear
    from .acquisition.objective import load_image, load_mask
    from .errors import AcquisitionError, RtloopError, RtloopWarning, SceneError, SceneTypeError
    from .fit import FitResult, StageResult, fit
    from .fit.protocol import whole as _whole
    from .insert import Insertion, insert
    from .report import report
    from .scene import load_scene, save_scene, scene_to_dict
    from .uncertainty import estimate_uncertainty

__all__ = [
    "AcquisitionError",
    "FitResult",
    "Insertion",
    "JobResult",
    "MAX_SPP",
    "RtloopError",
    "RtloopWarning",
    "Scene",
    "SceneError",
    "SceneTypeError",
    "StageResult",
    "__version__",
    "estimate_uncertainty",
    "fit",
    "fit_many",
    "insert",
    "load_image",
    "load_mask",
    "load_scene",
    "object_ids",
    "render",
    "report",
    "save_image",
    "save_scene",
    "scene_to_dict",
    "srgb_to_linear",
]

#: Names loaded on first use (rtloop.batch brings a process pool and hashing that one fit does not need).
_LAZY = {"JobResult": "batch", "fit_many": "batch"}


def __getattr__(name: str) -> object:
    if name in _LAZY:
        from importlib import import_module

        value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'rtloop' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The public API (``__all__``): not the modules and helpers the package is built from."""
    return sorted(__all__)


def render(scene: object, width: int | None = None, height: int | None = None, spp: int = 1, *,
           footprint: bool | str = False) -> _np.ndarray:
    """Render ``scene`` (a Scene, dict or path) to a float32 (H, W, 3) linear-RGB array.

    ``width``/``height`` default to the scene's image size and keep the field of view; ``spp`` > 1
    supersamples each pixel (stratified grid when it is a square number) and averages in linear light.
    ``footprint`` (one sample per pixel) integrates sphere shadow edges and terminators over each pixel
    in closed form: the image ``fit(..., footprint=True)`` compares with a photo; "silhouette" besides
    averages each pixel that straddles an object's outline over 16 sub-pixel rays (the model a fit whose
    ``settings["silhouettes"]`` is True compared). Values are radiance times exposure, not clipped.
    """
    scene = load_scene(scene)
    width, height = _size(width, height)
    spp = _whole("spp", spp, 1, MAX_SPP)
    if not (isinstance(footprint, bool) or (isinstance(footprint, str) and footprint == "silhouette")):
        raise RtloopError(f"footprint: must be True, False or 'silhouette' (got {footprint!r})")
    if footprint and spp != 1:
        raise RtloopError(f"footprint: takes one sample per pixel (got spp={spp})")
    return _native.render(scene, width, height, spp, bool(footprint), outlines=footprint == "silhouette")


def object_ids(scene: object, width: int | None = None, height: int | None = None) -> _np.ndarray:
    """Which object each pixel centre shows: int32 (H, W) index into ``objects``, -1 for background."""
    scene = load_scene(scene)
    return _native.object_ids(scene, *_size(width, height))


#: Most samples per pixel render() takes (docs/scene-format.md: "Input limits"); the size is 1..16384 as in a
#: scene.
MAX_SPP = 4096


def _size(width: object, height: object) -> tuple[int | None, int | None]:
    """An optional (width, height), each None or 1..16384 pixels as a scene's image."""
    return tuple(None if v is None else _whole(n, v, 1, 16384)  # type: ignore[return-value]
                 for n, v in (("width", width), ("height", height)))


def save_image(path: object, image_linear: _np.ndarray) -> None:
    """Write a linear (H, W, 3) image as 8-bit sRGB PNG or BMP (by extension), atomically."""
    arr = _np.ascontiguousarray(image_linear, dtype=_np.float32)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise RtloopError(f"image_linear: expected an (H, W, 3) image, got shape {arr.shape}")
    _native.save_image(str(path), arr)
