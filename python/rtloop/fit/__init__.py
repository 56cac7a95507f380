"""The fit: rtloop's closed-form method or the paper's two stages, with all the arithmetic in Rust.

``fit()`` checks its arguments once (:mod:`.options`), observes the photo (:mod:`.observation`), plans the
budget and method (:mod:`.plan`, :mod:`.protocol`), runs the stages (:mod:`.method`, :mod:`.stages`) with
the image terms the photo selects (:mod:`.terms`) and the refits (:mod:`.refit`), splits the solved products
back into scene values (:mod:`.products`), names what the photo does not determine
(:mod:`.identifiability`) and judges the result (:mod:`.analysis`). docs/methods.md.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..scene import Scene, load_scene
from .analysis import analyse, fit_result
from .camera import Camera, fit_through_camera
from .framing import fit_reframed
from .identifiability import lit_pixel_counts
from .inputs import objective
from .jpeg import JPEG_CHROMA_MARGIN
from .lights import LightsFit, choose_count, fit_lights
from .method import run_method
from .more_lights import more_lights
from .observation import observe
from .options import LightsOptions, check_options
from .plan import plan_fit
from .products import product_bounds as _product_bounds
from .protocol import LOSS_SPACES, PIXELS_PER_OBJECT, PROTOCOLS
from .result import FitResult, GenerationInfo, StageResult
from .stages import sample_object_pixels

__all__ = ["LOSS_SPACES", "PROTOCOLS", "FitResult", "GenerationInfo", "StageResult", "fit"]

# Kept importable from here, as from the single module this package replaces (tests and benches use them).
_REEXPORTED = (_product_bounds, lit_pixel_counts, sample_object_pixels, JPEG_CHROMA_MARGIN)


def fit(
    scene: Any,
    image: np.ndarray,
    *,
    protocol: str = "rtloop",
    seed: int = 0,
    population: int | None = None,
    generations: int | tuple[int, int] | None = None,
    f: float | None = None,
    cr: float | None = None,
    threads: int | None = None,
    clip: bool = True,
    pixels_per_object: int = PIXELS_PER_OBJECT,
    callback: Callable[[GenerationInfo], Any] | None = None,
    optimizer: str | None = None,
    polish: int | None = None,
    uncertainty: bool | str = True,
    mask: np.ndarray | None = None,
    norm: str = "auto",
    space: str = "auto",
    environment: str = "auto",
    interreflection: str = "auto",
    highlights: str = "auto",
    reference: tuple[np.ndarray, float] | None = None,
    footprint: str | bool = "auto",
    lights: int | str | None = None,
    framing: str = "check",
    vignetting: Any = "auto",
    tone: str = "auto",
    flat_field: np.ndarray | None = None,
) -> FitResult | LightsFit:
    """Fit the scene's free parameters (its ``fit`` section) to ``image``.

    ``image`` is the objective in linear RGB, float (H, W, 3) at the scene's size (see :func:`load_image`).
    ``protocol``: ``"rtloop"`` (default) or ``"paper"`` (population 60, 200 + 200 generations, F 0.6,
    CR 0.8); ``population``, ``generations`` (one number for both stages or a pair), ``f`` and ``cr``
    override it. ``seed`` makes the result reproducible on any number of ``threads``. ``clip`` compares
    min(render, 1) with the objective, as an 8/16-bit photo saturates. ``callback(GenerationInfo)`` runs
    after every generation; returning False stops the current stage. ``uncertainty`` adds per-parameter
    1-sigma estimates (Gauss-Newton at the optimum, scaled by the residual, and the block sandwich) to the
    result: ``True`` or ``"default"`` (a few ms), ``"bootstrap"`` also the spatial block bootstrap (tens of
    closed-form refits on resampled image blocks, seeded by ``seed``; ``result.uncertainty["bootstrap"]``,
    see :mod:`rtloop.uncertainty.bootstrap`; ``callback`` runs after each of their generations too, its stage
    ``"bootstrap R/N"``), ``False`` or ``"off"`` none. ``optimizer``
    ("de" or "lshade") and ``polish`` (Nelder-Mead evaluations) override the protocol's search for the
    closed-form method. ``mask`` (bool (H, W), True = use) leaves out pixels the scene does not model
    (another object, a reflection, the photographer's shadow): they count in no loss and no solve.
    ``norm`` penalises each pixel's difference: "auto" (default: L1, refitted in L2 on the pixels that show
    one object where the photo is a linear camera file, a linear 16-bit or 8-bit PNG or TIFF or a developed
    RAW, and the L1 fit's residual is dense against its own errors: :mod:`rtloop.fit.norm`,
    ``result.model["norm"]``), "l1" (the paper's), "l2" (maximum likelihood for Gaussian noise), "huber" or
    "huber:H" (quadratic within H, default 0.02, linear beyond). ``space`` is
    where it is taken: "linear" (radiance) or "srgb" (the sRGB encodings of the clipped render
    and of the image, as an 8-bit file stores them: a shadow's error counts as the file resolves it); the
    closed-form products stay least squares in linear space, the reported ones minimise the sRGB loss.
    "auto" (default): linear, except that a JPEG (its blocking measured in the image) that direct light
    alone explains is refitted in sRGB near the light found, where its errors are alike
    (``result.model["space"]`` says why; ``settings["space"]`` is the space used). On a noisy or JPEG
    image, pixels within three of its errors below 1 count as possibly clipped (``settings["saturated"]``).
    On a JPEG (its blocking of at least one code RMS) the pixels within JPEG_CHROMA_MARGIN (2) of another
    object, whose colour its 4:2:0 chroma mixes with that object's, do not inform the colour products
    (``settings["solve_margin"]``); they still count in the loss.
    ``environment``: the occluded environment term (a room's light from every direction, darkened under
    and between the objects): "auto" (default) adds it when the photo shows it (``result.model`` says
    why), "on" always fits it, "off" never; a scene that gives ``environment`` or frees it always has it.
    The closed-form method solves it (one product per object and channel); elsewhere it is the scene's.
    ``interreflection``: one diffuse bounce between the objects (the floor lighting a ball's underside, a
    red ball tinting the floor): "auto" (default) adds it when the photo shows it, "on", "off"; the bounce
    depends on the albedos themselves, so with it the fit also estimates the light's intensity.
    ``highlights``: "auto" (default) frees a lobe on every sphere the scene gives as matte when the photo
    shows a highlight the diffuse model cannot explain: Blinn-Phong (specular, shininess) or, where it explains
    it better, a clear coat (``material.coat``, its roughness chosen; ``result.model`` says why); "off" never.
    ``reference``: ``(card, reflectance)``, a surface of known reflectance lying on a plane of the scene
    (a grey card; ``card`` bool (H, W), True on it, and left out of the fit by ``mask``): the fitted scene is
    rescaled to absolute albedos and the light's intensity in W/sr (:mod:`rtloop.fit.reference`), recorded
    in ``result.reference``.
    ``footprint``: compare the photo with pixels integrated over their area where a sphere's shadow edge
    or terminator crosses them, as a camera integrates them (``render(..., footprint=True)`` renders that
    model), instead of pixel centres. "auto" (default): the closed-form method's search finds the basin at
    pixel centres and its polish, products and loss take the footprint (the two-stage fallback stays at
    pixel centres); where the photo shows it needs them (the outline gate, :mod:`.outlines`), the pixels on
    an object's outline are then averaged over 16 sub-pixel rays and the light polished again
    (``result.model["outlines"]`` records the evidence, ``result.settings["silhouettes"]`` whether they were
    taken). "silhouette": as "auto" with the outlines always averaged. "on" (or True): every search takes
    the footprint too; "off" (or False): pixel centres only. The term tests stay at pixel centres.
    ``lights``: the number of lights to fit (1 to 8), or "auto" to choose it from held-out pixels (one
    light, then one more while it explains pixels the fit did not see: :func:`.lights.choose_count`).
    1 for a one-light scene is the fit above. None (default) is that fit too, and where it does not
    explain the photo (its goodness of fit) further lights are tried and kept only where held-out pixels
    ask for them (:mod:`.more_lights`): a kept light returns the lights fit, a refused one the fit above
    with ``model["lights"]`` saying what was tried. More lights, or a scene with a ``lights``
    list of several lights or a sphere light, take the lights fit (:mod:`.lights`: matte objects, the
    lights' geometry searched and their products solved) and return a :class:`.lights.LightsFit`.
    ``framing``: whether the photo is framed as the scene's camera frames it (the objects' outlines against
    the fitted render, :mod:`.framing`): "check" (default) says so in ``goodness["framing"]`` and the
    verdict where the residual is at least twice the noise floor; "correct" resamples the photo into the
    scene's framing by the camera correction (roll, zoom, shift) its outlines give and fits again; "off".
    ``vignetting``, ``tone``: the camera between the scene and the file (:mod:`.camera`, docs/camera.md):
    "auto" (default) fits the lens's falloff (cos^4 x (1 + k1 r^2 + k2 r^4)) or a monotone tone curve
    with the light where held-out pixels show it (a tone curve on 8-bit images only), "on", "off";
    ``tone="linear"`` declares the image linear radiance (a RAW, a file read with ``response="linear"``,
    as rtloop-fit does): no curve, and no doubt that it may be sRGB-encoded; ``vignetting=(k1, k2)`` or ``flat_field`` (a linear photo of a flat white target, (H, W[, 3])) give
    the falloff. ``result.model["camera"]`` records the terms and the evidence.
    """
    args, t0 = dict(locals()), time.perf_counter()
    scene = load_scene(scene)
    options = check_options(scene, args, fit.__kwdefaults__)
    if isinstance(options, LightsOptions):
        return _fit_lights(scene, image, mask, options)
    if options.camera.active:  # the camera's terms: each of their fits through fit() again
        result = _through_camera(args, scene, options.camera, t0)
    elif options.framing == "correct":  # the framing's correction: each of its fits through fit() again
        result = fit_reframed(fit, scene, image, mask, reference, {**options.reframed(args), "lights": 1})
    else:
        photo = observe(scene, image, mask, reference, clip=clip)
        plan = plan_fit(scene, options, photo)
        fitted = run_method(options, photo, plan)
        result, doubts = fit_result(fitted, options, photo, plan, t0)
        analyse(result, options, fitted.photo, plan, doubts)
        result.seconds = time.perf_counter() - t0
    if lights is None:  # the default: a further light only where the photo asks for it
        return more_lights(result, scene, image, mask, args, fit.__kwdefaults__, t0)
    return result


def _through_camera(args: dict[str, Any], scene: Scene, camera: Camera, t0: float) -> FitResult:
    """``fit()`` (``args``: its arguments) through the camera's terms (:func:`.camera.fit_through_camera`):
    each fit with them off (an image declared linear stays declared)."""
    tone = "linear" if camera.tone == "linear" else "off"

    def once(img: np.ndarray, near: Scene | None = None) -> FitResult:
        return fit(**{**args, "image": img, "vignetting": "off", "tone": tone, "flat_field": None, "lights": 1,
                      **({"scene": near} if near is not None else {})})

    result = fit_through_camera(once, scene, *objective(scene, args["image"], args["mask"], []), camera)
    result.seconds = time.perf_counter() - t0
    return result


def _fit_lights(scene: Scene, image: Any, mask: Any, options: LightsOptions) -> LightsFit:
    """``fit()`` for several lights or a sphere light (:mod:`.lights`)."""
    target, use = objective(scene, image, mask, [])
    budget = {"population": options.population, "generations": options.generations, "threads": options.threads}
    if options.lights == "auto":
        return choose_count(scene, target, seed=options.seed, mask=use, **budget)
    return fit_lights(scene, target, options.lights, seed=options.seed, mask=use, **budget)
