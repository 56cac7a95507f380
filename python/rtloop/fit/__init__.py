"""The fit: rtloop's closed-form method or the paper's two stages, with all the arithmetic in Rust.

``fit()`` checks its inputs, picks the budget and method (:mod:`.protocol`), runs the stages
(:mod:`.stages`), splits the solved products back into scene values (:mod:`.products`) and names what
the photo does not determine (:mod:`.identifiability`). docs/methods.md.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _native
from .._srgb import codes8, decode
from ..errors import RtloopError, RtloopWarning
from ..scene import Scene, load_scene
from .constant import as_environment, compare_constant, declares_ambient
from .bounds import at_bounds, narrowed, restore_bounds
from .camera import Camera, fit_through_camera
from .coat import choose_lobe, with_coat
from .gauge import hold_gauges, release_gauges
from .lights import LightsFit, choose_count, fit_lights
from .framing import fit_reframed, framing_check, mismatch_verdict
from .goodness import clip_level, encoded, goodness, jpeg_blocking, noise_sigma
from .norm import dense_residual, linear_file, norm_verdict, not_linear_verdict, pixel_mask, representable_pixels
from .identifiability import identifiability as _identifiability
from .inputs import objective
from .identifiability import lit_pixel_counts
from .products import constant_term
from .products import product_bounds as _product_bounds
from .products import products as _products
from .protocol import (
    LOSS_SPACES,
    PIXELS_PER_OBJECT,
    PROTOCOLS,
    budget,
    check_arguments,
    choose_method,
    searched_paths,
)
from .options import LightsOptions, check_options
from .reference import check_reference, pin_to_reference
from .result import FitResult, GenerationInfo, StageResult
from .selection import (
    BOUNCE_PASSES,
    EXPLAINED,
    closed_form_loss,
    environment_evidence,
    environment_given,
    explained_ratio,
    highlight_candidates,
    highlight_evidence,
    interreflection_evidence,
    interreflection_given,
    with_highlights,
    with_interreflection,
)
from .stages import Stages, sample_object_pixels

__all__ = ["LOSS_SPACES", "PROTOCOLS", "FitResult", "GenerationInfo", "StageResult", "fit"]

# Kept importable from here, as from the single module this package replaces (tests and benches use them).
_REEXPORTED = (_product_bounds, lit_pixel_counts, sample_object_pixels)


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
    pixel centres); "on" (or True): every search takes it too; "off" (or False): pixel centres only. The
    term tests stay at pixel centres.
    ``lights``: the number of lights to fit (1 to 8), or "auto" to choose it from held-out pixels (one
    light, then one more while it explains pixels the fit did not see: :func:`.lights.choose_count`).
    None (default) or 1 for a one-light scene is the fit above; more lights, or a scene with a ``lights``
    list of several lights or a sphere light, take the lights fit (:mod:`.lights`: matte objects, the
    lights' geometry searched and their products solved) and return a :class:`.lights.LightsFit`.
    ``framing``: whether the photo is framed as the scene's camera frames it (the objects' outlines against
    the fitted render, :mod:`.framing`): "check" (default) says so in ``goodness["framing"]`` and the
    verdict where the residual is at least twice the noise floor; "correct" resamples the photo into the
    scene's framing by the camera correction (roll, zoom, shift) its outlines give and fits again; "off".
    ``vignetting``, ``tone``: the camera between the scene and the file (:mod:`.camera`, docs/camera.md):
    "auto" (default) fits the lens's falloff (cos^4 x (1 + k1 r^2 + k2 r^4)) or a monotone tone curve
    with the light where held-out pixels show it (a tone curve on 8-bit images only), "on", "off";
    ``vignetting=(k1, k2)`` or ``flat_field`` (a linear photo of a flat white target, (H, W[, 3])) give
    the falloff. ``result.model["camera"]`` records the terms and the evidence.
    """
    args = dict(locals())
    t0 = time.perf_counter()
    scene = load_scene(scene)
    options = check_options(scene, args, fit.__kwdefaults__)
    if isinstance(options, LightsOptions):
        return _fit_lights(scene, image, mask, options)
    if options.camera.active:  # the camera's terms: each of their fits through fit() again
        return _through_camera(args, scene, options.camera, t0)
    if options.framing == "correct":  # the framing's correction: each of its fits through fit() again
        return fit_reframed(fit, scene, image, mask, reference, options.reframed(args))
    footprint, space_mode, space, norm_mode, norm = (options.footprint, options.space, options.first_space,
                                                     options.norm, options.first_norm)
    b, env_mode = options.budget_copy(), options.environment
    doubts: list[str] = []
    target, use = objective(scene, image, mask, doubts)
    if reference is not None:
        reference = (check_reference(scene, reference[0], reference[1]), reference[1])
    all_paths = scene.fit_paths
    if not all_paths:
        raise RtloopError("fit: the scene's fit section names no free parameters")
    ident = _identifiability(scene, all_paths)
    # The light's colour and the exposure, where they only rescale the albedos, are held for the closed form.
    given = scene
    if protocol != "paper":
        scene, held = hold_gauges(scene, all_paths, target, use, bounce=interreflection == "on")
    else:
        held = {}
    choose_method(b, scene, scene.fit_paths, population=population, generations=generations, optimizer=optimizer,
                  polish=polish)
    check_arguments(scene, seed=seed, threads=threads, polish=b.polish, pixels_per_object=pixels_per_object,
                    population=b.population)  # the scaled budget too
    settings = {**b.settings(), "clip": clip,
                "masked_pixels": None if use is None else int(scene.width * scene.height - use.size),
                "norm": norm, "space": space, "pixels_per_object": pixels_per_object, "threads": threads,
                "method": b.method, "optimizer": b.optimizer, "polish": b.polish, "environment": env_mode,
                "interreflection": interreflection, "highlights": highlights}
    if b.projection_unavailable is not None:
        settings["projection_unavailable"] = b.projection_unavailable
    # Where the fit takes the pixel footprint: "off", "polish" (the closed-form polish) or "on" (everywhere).
    settings["footprint"] = footprint = ("polish" if b.method == "projected" else "off") if footprint == "auto" \
        else footprint
    # The scene as fitted: with the interreflection term when asked for ("on"), else as given.
    work = with_interreflection(scene) if interreflection == "on" else scene

    def new_stages(norm: str, use: np.ndarray | None, mask: np.ndarray | None) -> Stages:
        return Stages(work, target, use, mask, b, ident, clip=clip, norm=norm, space=space, threads=threads,
                      pixels_per_object=pixels_per_object, rng=np.random.default_rng(seed), callback=callback,
                      footprint=footprint)

    stages = new_stages(norm, use, mask)
    # The photo's 8-bit codes where it has them (a PNG or JPEG as load_image decodes it: the sRGB transfer
    # functions of its values then come from a table of the 256, the same numbers), and its sRGB encoding
    # once, for the JPEG blocking here and the goodness of fit at the end.
    codes = codes8(target)
    encoding = encoded(target, codes)
    sigma, blocking = noise_sigma(target), jpeg_blocking(target, encoding)
    # Where a pixel may be clipped: below 1 by the photo's own noise and JPEG error (goodness.clip_level).
    settings["saturated"] = stages.saturated = clip_level(sigma, blocking) if clip else None
    # A JPEG's colour mixes across silhouettes (its 4:2:0 chroma): those pixels do not inform the products
    # (recorded for a JPEG only: ``settings["solve_margin"]``).
    if _is_jpeg(blocking):
        settings["solve_margin"] = stages.solve_margin = JPEG_CHROMA_MARGIN
    seeds = np.random.SeedSequence(seed).generate_state(4, dtype=np.uint64)
    model: dict[str, Any] = {"terms": ["direct"], "evidence": {}}
    if held:
        model["held"] = held
    if b.method == "projected":
        def select(stages: Stages, model: dict[str, Any], encoding: dict[str, Any] | None = None) -> Scene:
            return _select_terms(scene, work, stages, seeds, model, env_mode=env_mode,
                                 inter_mode=interreflection, highlights=highlights, target=target,
                                 use=stages.use, mask=stages.mask, protocol=protocol, space=space,
                                 population=population, generations=generations, f=f, cr=cr,
                                 optimizer=optimizer, polish=polish, clip=clip, norm=stages.norm,
                                 threads=threads, pixels_per_object=pixels_per_object, seed=seed,
                                 callback=callback, blocking=blocking, space_mode=space_mode, codes=codes,
                                 encoding=encoding)

        current = select(stages, model)
        if norm_mode == "auto" and space == "linear" and model.get("space", {}).get("used") != "srgb":
            if codes is None and not _is_jpeg(blocking) and linear_file(target):
                render = _native.render(current, current.width, current.height, 1, footprint != "off")
                chosen = norm_verdict(dense_residual(render, target, use, None, sigma, [0.0, 0.0, 0.0], clip=clip))
            else:
                chosen = not_linear_verdict()
            if chosen["used"] == "l2":  # refitted in L2 on the pixels that show one object only
                before = scene.width * scene.height if use is None else int(use.size)
                use = representable_pixels(scene, use)
                mask = pixel_mask(use, scene.width, scene.height)
                dense = new_stages("l2", use, mask)
                dense.saturated, dense.solve_margin = stages.saturated, stages.solve_margin
                first_terms, first_encoding = model["terms"], model.get("encoding", {})
                model = {"terms": ["direct"], "evidence": {}, **({"held": held} if held else {})}
                current = select(dense, model, encoding=first_encoding)
                dense.stages[:0] = stages.stages
                dense.evaluations += stages.evaluations
                stages, norm = dense, "l2"
                chosen.update(first_fit_terms=first_terms, outline_pixels_left_out=before - int(use.size))
            model["norm"] = chosen
            settings["norm"] = norm
        if model.get("space", {}).get("used") == "srgb":
            settings["space"] = "srgb"
    else:
        if environment_given(scene):
            model["terms"].append("environment")
        if interreflection_given(work):
            model["terms"].append("interreflection")
        current = stages.two_stage(seeds)
    current, scene = release_gauges(current, given, held), given
    if model.get("encoding", {}).get("suspect"):
        doubts.append(model["encoding"]["doubt"])
    if "interreflection" in model["terms"] and ident.get("degenerate"):
        ident = {**ident, "degenerate": False,
                 "note": "the bounce between the objects is as bright as their albedos themselves, so the photo "
                         "fixes the light's intensity and the albedos, not only their products (weakly where the "
                         "bounce is faint: see the uncertainty)"}
    pinned = None
    if reference is not None:
        current, pinned = pin_to_reference(current, target, reference[0], reference[1])
        ident = {**ident, "degenerate": False, "note": pinned["note"]}
        if "warning" in pinned:
            doubts.append(pinned["warning"])
    values = current.get_params(all_paths)
    result = FitResult(
        scene=current,
        x={n: float(v) for n, v in zip(scene.param_names(), values)},
        stages=stages.stages,
        evaluations=stages.evaluations,
        seconds=time.perf_counter() - t0,
        protocol=protocol,
        seed=seed,
        products=_products(current),
        identifiability=ident,
        settings=settings,
        model=model,
        reference=pinned,
    )
    # The model the fit compared with the photo, for the goodness of fit and the uncertainty's residual, and
    # the pixel-centre render the uncertainty's finite differences start from (the same where the fit took no
    # footprint; else both in one pass, the light a footprint does not change shaded once).
    with_sigma = uncertainty not in (False, "off")
    if footprint == "off":
        as_compared = at_optimum = _native.render(current, current.width, current.height, 1, False)
    elif with_sigma:
        at_optimum, as_compared = _native.render_centre_and_footprint(current)
    else:
        as_compared, at_optimum = _native.render(current, current.width, current.height, 1, True), None
    result.goodness = goodness(current, target, use, clip=clip, render=as_compared, sigma=sigma, blocking=blocking,
                               encoding=encoding, codes=codes)
    result.goodness["framing"] = framing_check(current, target, use, result.goodness["ratio"], framing,
                                               as_compared)
    if result.goodness["framing"]["mismatch"]:
        result.goodness["verdict"] = mismatch_verdict(result.goodness["framing"])
    doubts += at_bounds(current, [p for p in all_paths if p not in held])  # a held gauge was not fitted
    for d in doubts:
        warnings.warn(d, RtloopWarning, stacklevel=2)
    result.warnings = doubts
    if with_sigma:
        from ..uncertainty import estimate_uncertainty

        try:
            result.uncertainty = estimate_uncertainty(result, target, clip=clip, mask=mask, render=at_optimum,
                                                      compared=as_compared)
        except RtloopError as e:
            result.uncertainty = {"method": "gauss-newton", "sigma": {}, "warnings": [str(e)]}
        if uncertainty == "bootstrap":
            from ..uncertainty.bootstrap import block_bootstrap

            try:
                shift = (result.uncertainty.get("robust") or {}).get("footprint_shift")
                result.uncertainty["bootstrap"] = block_bootstrap(result, target, use, seed=seed, threads=threads,
                                                                  shift=shift, callback=callback)
            except RtloopError as e:
                result.uncertainty["bootstrap"] = {"method": "block-bootstrap", "sigma": {}, "warnings": [str(e)]}
    result.seconds = time.perf_counter() - t0
    return result


#: A JPEG (its blocking detected and of at least JPEG_SRGB_CODES, :func:`_is_jpeg`) stores colour
#: (chroma) at half the resolution in each direction (4:2:0, the default of libjpeg, Pillow and cameras),
#: and its decoder interpolates each pixel's colour from the neighbouring samples ("fancy upsampling":
#: weights 3/4 and 1/4 of the 2 x 2 samples around it), so a pixel's colour mixes those of the pixels up
#: to 2 away. Within that Chebyshev distance of another object a pixel's colour is part the other's (a
#: red ball's rim takes the grey floor's), which biased each object's colour products toward its
#: neighbours': those pixels still count in the loss, but not in the products' solve
#: (``settings["solve_margin"]``).
JPEG_CHROMA_MARGIN = 2

#: The refit with the terms a photo selected searches near the light found without them (its box shrunk to
#: +-REFIT_FRACTION of each range around it: the terms move the light by centimetres, the box by metres)
#: with a smaller search (population, generations, polish).
REFIT_FRACTION = 0.15
REFIT_BUDGET = (8, 6, 120)
#: The auto terms in the order they are tested and named.
_TERM_ORDER = ("environment", "interreflection", "specular")


def _select_terms(scene: Scene, work: Scene, stages: Stages, seeds: np.ndarray, model: dict[str, Any], *,
                  env_mode: str, inter_mode: str, highlights: str, target: np.ndarray, use: np.ndarray | None,
                  mask: Any, protocol: str, space: str, population: Any, generations: Any, f: Any, cr: Any,
                  optimizer: Any, polish: Any, clip: bool, norm: str, threads: Any, pixels_per_object: int,
                  seed: int, callback: Any, blocking: dict[str, Any], space_mode: str,
                  codes: np.ndarray | None = None, encoding: dict[str, Any] | None = None) -> Scene:
    """The closed-form fit with the image terms the photo needs (:mod:`.selection`): fitted with the terms
    given or forced on; then, unless that fit explains the photo to its quantisation floor, each auto term
    in turn (environment, interreflection, a sphere's lobe) is tested at the light found, on top of those
    already selected (a term not selected is tested again after another is: forward selection), and one
    refit near that light has every selected term; it replaces the first fit only when its loss is lower.
    ``model`` receives the terms and the evidence (each term's last test: ``tested_with`` the terms it was
    tested on top of, ``earlier_gain`` its first test's gain where it was tested again). ``codes``:
    ``target``'s 8-bit codes where it has them (:func:`rtloop._srgb.codes8`). ``encoding``: the encoding
    check of an earlier fit of the same photo (``{}``: it had none), taken instead of checking again."""
    # Ambient light (given or free, no environment) takes the closed form's constant column instead.
    ambient = constant_term(scene) == "ambient"
    env = environment_given(scene) or env_mode == "on" or ambient
    current = stages.projected(int(seeds[0]), environment=env)
    first = stages.stages[-1]
    if env:
        model["terms"].append("ambient" if ambient else "environment")
    if interreflection_given(work):
        model["terms"].append("interreflection")
    kw = {"clip": clip, "norm": norm, "space": space, "threads": threads, "saturated": stages.saturated}

    def refit(box: Scene, refit_space: str) -> Stages | None:
        """The stages of one refit of ``box`` (a box around the light found) in ``refit_space`` with the
        smaller search (REFIT_BUDGET, scaled to the searched parameters as the protocol's own budget is: a
        freed shininess adds one); None where that budget takes the closed form no more."""
        k = max(1.0, len(box.param_names(searched_paths(box.fit_paths))) / PROTOCOLS["rtloop"]["per_dimensions"])
        b2 = budget(protocol, refit_space, round(REFIT_BUDGET[0] * k) if population is None else population,
                    round(REFIT_BUDGET[1] * k) if generations is None else generations, f, cr)
        choose_method(b2, box, box.fit_paths, population=b2.population, generations=b2.generations,
                      optimizer=optimizer, polish=round(REFIT_BUDGET[2] * k * k) if polish is None else polish)
        if b2.method != "projected":
            return None
        more = Stages(box, target, use, mask, b2, _identifiability(box, box.fit_paths), clip=clip, norm=norm,
                      space=refit_space, threads=threads, pixels_per_object=pixels_per_object,
                      rng=np.random.default_rng(seed), callback=callback, footprint=stages.footprint,
                      report_names=stages.all_names)
        more.saturated = stages.saturated
        more.solve_margin = stages.solve_margin
        return more

    # A fit at the photo's noise level needs no more terms: the tests are skipped (one sum, no evaluation).
    # The floor in the fit's own norm and space, and the residual's size against it (alike in every norm).
    floor, ratio = explained_ratio(sum(first.objectives), target, use, codes, norm=norm, space=space)
    model["residual"] = {"loss": float(sum(first.objectives)), "quantisation_floor": floor, "ratio": ratio,
                         "explained_below": EXPLAINED}
    if ratio < EXPLAINED:
        model["skipped"] = (f"the fit's residual is {ratio:.2g}x the size of the photo's 8-bit rounding error "
                            f"(below {EXPLAINED:g}x): the photo needs no more terms")
        return current
    # The tests compare models on every other pixel in each direction: a term that explains 5 % of the loss
    # shows there as well, and the bounce's gathers cost a quarter.
    grid = np.arange(scene.width * scene.height, dtype=np.uint32).reshape(scene.height, scene.width)[::2, ::2]
    sub = grid.ravel() if use is None else np.intersect1d(grid.ravel(), use).astype(np.uint32)
    # An encoding is within [0, 1]: an image beyond it is radiance, not sRGB codes. An image whose every
    # value is an 8-bit code's linear value (a PNG or JPEG as load_image decodes it) was decoded: linear.
    if encoding is not None:  # checked by the first fit (the L1 one the check's gain was measured with)
        if encoding:
            model["encoding"] = encoding
    elif codes is not None:
        model["encoding"] = {"suspect": False, "why": "its values are 8-bit sRGB codes decoded to linear (as "
                                                      "rtloop.load_image reads a PNG or JPEG): not checked"}
    elif space == "linear" and float(target.min()) >= 0.0 and float(target.max()) <= 1.0:
        model["encoding"] = _encoding_check(work, stages, int(seeds[0]), target, sub, ratio, environment=env)
    where, x = first.paths, list(first.x)
    if ambient and declares_ambient(work):  # the declared ambient, or the same light occluded (.constant)
        model["constant"] = ev = compare_constant(work, where, x, target, sub, **kw)
        more = refit(narrowed(as_environment(work).with_params(x, where), where, REFIT_FRACTION), space) \
            if ev["use_environment"] and "refit_blocked" not in ev else None
        if more is not None:
            candidate = more.projected(int(seeds[2]), environment=True, name="light+colour+environment",
                                       from_scene=True)
            stages.stages += more.stages
            stages.evaluations += more.evaluations
            ev["loss_refit"] = float(sum(more.stages[-1].objectives))
            if ev["loss_refit"] < sum(first.objectives):
                work, first, ambient = as_environment(work), more.stages[-1], False
                current, where, x = restore_bounds(candidate, work), first.paths, list(first.x)
                model["terms"][model["terms"].index("ambient")] = "environment"
        ev["used"] = "ambient" if ambient else "environment"
    n_sub = first.pixels // 4
    model_work, model_env, added = work, env, []
    base = float(closed_form_loss(work.with_params(x, where), where, [x], target, sub, environment=env, **kw)[0])
    # Forward selection: each auto term is tested on top of those selected so far, and a term not selected
    # is tested again once another has been added (a missing term's share of the residual shows only when
    # the others' is explained: on lamp-front a dim room's light takes 3.5 % of the loss beside the unexplained
    # bounce and lobe, 5.1 % on top of them), until a round adds nothing (a term is tested at most once per
    # term selected, and once more only if another was selected after it).
    names = highlight_candidates(work) if highlights == "auto" and "light.color" not in model.get("held", {}) else []
    candidates = [t for t, wanted in (
        ("environment", env_mode == "auto" and not env),
        ("interreflection", inter_mode == "auto" and not interreflection_given(work) and len(scene.object_names) > 1
         and not ambient and "light.color" not in model.get("held", {})),
        # (a lobe's highlight has the light's own colour, which a held colour would get wrong)
        ("specular", bool(names)),
    ) if wanted]
    tested_with: dict[str, int] = {}  # a term: how many terms were selected when it was last tested
    while todo := [t for t in candidates if t not in added and tested_with.get(t, -1) < len(added)]:
        for term in todo:
            at = model_work.with_params(x, where)
            tested_with[term] = len(added)
            shininess = None
            if term == "environment":
                ev = environment_evidence(at, where, x, target, sub, base=base, active_pixels=n_sub, **kw)
            elif term == "interreflection":
                ev = interreflection_evidence(at, where, x, target, sub, base=base, environment=model_env,
                                              active_pixels=n_sub, **kw)
            else:
                ev, shininess = highlight_evidence(at, names, where, x, target, sub, base=base,
                                                   environment=model_env, active_pixels=n_sub, **kw)
                if ev["selected"]:  # the coat against Blinn-Phong, by the same evidence (fit/coat.py)
                    choose_lobe(ev, at, names, where, x, target, sub, base=base, environment=model_env,
                                active_pixels=n_sub, **kw)
            earlier = model["evidence"].get(term)
            ev["tested_with"] = [t for t in _TERM_ORDER if t in added]
            if earlier is not None:
                ev["earlier_gain"] = earlier.get("earlier_gain", earlier["gain"])
            model["evidence"][term] = ev
            if not ev["selected"]:
                continue
            base = ev["loss_with"]
            added.append(term)
            if term == "environment":
                model_env = True
            elif term == "interreflection":
                model_work = with_interreflection(model_work)
            else:
                model_work = with_coat(model_work, names, ev["coat"]["roughness"]) if ev.get("lobe") == "coat" \
                    else with_highlights(model_work, names, shininess)
    added.sort(key=_TERM_ORDER.index)
    if not added:
        return _jpeg_refit(current, work, stages, first, model, seeds, blocking=blocking, space=space_mode,
                           env=env, refit=refit)
    # One refit with every selected term, in a box around the light found, with a smaller search.
    box = narrowed(model_work.with_params(x, where), where, REFIT_FRACTION)
    more = refit(box, space)
    if more is None:
        return current
    if (codes := _jpeg_codes(blocking, space_mode)) is not None:
        _stays_linear(model, codes)
    bounce = "interreflection" in added or interreflection_given(work)
    if bounce:
        more.frozen_bounce = BOUNCE_PASSES  # the bounce held, from the light found without it
    # The refit's search starts from the light found (and a lobe's best trial shininess), so that its small
    # population cannot end worse than that; but not with the bounce: there the light found without it is
    # centimetres off, and a start there stops the held passes early (they end once a pass barely moves
    # the light): on rtloop's own bounce renders 0.15-0.41 mm -> 1.0-1.5 mm off (docs/methods.md,
    # "How a photo selects them").
    candidate = more.projected(int(seeds[1]), environment=model_env,
                               name="+".join(["light", "colour", *model["terms"][1:], *added]),
                               from_scene=not bounce)
    stages.stages += more.stages
    stages.evaluations += more.evaluations
    if sum(more.stages[-1].objectives) >= sum(first.objectives):
        model["rejected"] = f"the refit with {', '.join(added)} did not lower the loss"
        return current
    model["terms"] += added
    if "specular" in added:
        model["specular_objects"] = names
        lobe = model["evidence"]["specular"]
        if lobe.get("lobe") == "blinn-phong" and "coat" in lobe and not bounce:
            coated = _coat_after_refit(work, names, candidate, where, float(sum(more.stages[-1].objectives)),
                                       model_env, refit, space, int(seeds[1]), lobe)
            if coated is not None:
                candidate, model_work, extra = coated
                stages.stages += extra.stages
                stages.evaluations += extra.evaluations
    # The user's bounds back (the search box was narrowed), with the freed lobes' bounds kept.
    return restore_bounds(candidate, model_work)


def _coat_after_refit(work: Scene, names: list[str], fitted: Scene, where: list[str], fitted_loss: float,
                      env: bool, refit: Callable[[Scene, str], Stages | None], space: str, seed: int,
                      lobe: dict[str, Any]) -> tuple[Scene, Scene, Stages] | None:
    """The coat tried again after Blinn-Phong's refit. The lobes were compared at the light found without
    any (:func:`.coat.choose_lobe`), which a highlight pulls towards itself: there Blinn-Phong's broader
    lobe can absorb the misplaced light and win, and its refit then ends degrees off on a coated ball
    (Mitsuba's roughplastic balls of studies/results/linear_photos.md: 0.8-3.3 deg with Blinn-Phong,
    0.02-0.07 deg with the coat given). So the fit is made once more with the coat (the roughness its
    evidence found), in the refit's box around the light Blinn-Phong's refit found, and the coat is kept
    when its loss is lower. ``fitted`` is the Blinn-Phong refit's scene, ``fitted_loss`` its loss, ``where``
    the paths of the light and colours. Returns (scene, its model, the refit's stages), or None where
    Blinn-Phong stays; the record goes in ``lobe["after_refit"]``. Not with the bounce (the coat's closed
    form does not model it)."""
    x = list(fitted.get_params(where))
    roughness = lobe["coat"]["roughness"]
    record: dict[str, Any] = {"roughness": roughness}
    lobe["after_refit"] = record
    model_work = with_coat(work, names, roughness)
    more = refit(narrowed(model_work.with_params(x, where), where, REFIT_FRACTION), space)
    if more is None:
        return None
    candidate = more.projected(seed, environment=env, name="light+colour+coat (after the lobe's refit)",
                               from_scene=True)
    record["loss_refit_coat"] = float(sum(more.stages[-1].objectives))
    record["loss_refit_blinn_phong"] = fitted_loss
    if record["loss_refit_coat"] >= record["loss_refit_blinn_phong"]:
        record["kept"] = "blinn-phong"
        return None
    record["kept"] = "coat"
    lobe.update(lobe="coat", roughness=roughness)
    return candidate, model_work, more


#: A photo whose JPEG blocks err by at least this many 8-bit codes (RMS, channel mean;
#: :func:`.goodness.jpeg_blocking`) has errors of constant size in code values, several times the 8-bit
#: quantisation's own (0.29 codes RMS): the default loss space compares it there.
JPEG_SRGB_CODES = 1.0


def _jpeg_refit(current: Scene, work: Scene, stages: Stages, first: StageResult, model: dict[str, Any],
                seeds: np.ndarray, *, blocking: dict[str, Any], space: str, env: bool,
                refit: Callable[[Scene, str], Stages | None]) -> Scene:
    """For ``space="auto"``: a JPEG (blocking of at least JPEG_SRGB_CODES) that the base model explains (no
    term selected or given) refitted in the sRGB space, near the light found (as the terms' refit). JPEG
    quantises the DCT of the sRGB-encoded values, so its errors are alike in code values and in linear
    radiance grow with the brightness: the sRGB loss weighs each pixel by what the file knows about it.
    On the JPEG-40 variants of the 11 direct Mitsuba photos the median light error falls 24.5 -> 11.7 mm
    (docs/accuracy.md, "Noisy and JPEG photos"). Where the model lacks something the photo shows (a desk
    lamp's soft shadow, a coat), the sRGB loss weighs up the dark pixels where that shows most (lamp-desk:
    10 -> 30 mm), so a photo with extra terms stays linear. ``model["space"]`` records the choice."""
    codes = _jpeg_codes(blocking, space)
    if codes is None:
        return current
    if len(model["terms"]) > 1 or env:
        _stays_linear(model, codes)
        return current
    box = narrowed(work.with_params(list(first.x), first.paths), first.paths, REFIT_FRACTION)
    more = refit(box, "srgb")
    if more is None:
        return current
    candidate = more.projected(int(seeds[1]), name="light+colour (srgb)", from_scene=True)
    stages.stages += more.stages
    stages.evaluations += more.evaluations
    model["space"] = {"used": "srgb", "jpeg_error_codes": codes,
                      "why": (f"a JPEG (its blocks err by {codes:.2g} codes RMS) that direct light explains: "
                              "refitted in the sRGB space, where its errors are alike")}
    return restore_bounds(candidate, work)


def _is_jpeg(blocking: dict[str, Any]) -> bool:
    """Whether the photo is a JPEG by its blocking (:func:`.goodness.jpeg_blocking`): detected, and of at
    least JPEG_SRGB_CODES RMS (a PNG can show a significant but smaller grid: direct-back-left's 0.57
    codes)."""
    codes = float(np.mean(blocking.get("error_codes", [0.0, 0.0, 0.0])))
    return bool(blocking.get("detected")) and codes >= JPEG_SRGB_CODES


def _jpeg_codes(blocking: dict[str, Any], space: str) -> float | None:
    """The JPEG's RMS error in codes (channel mean) where ``space="auto"`` would compare it in sRGB (a
    JPEG blocking of at least JPEG_SRGB_CODES), else None."""
    codes = float(np.mean(blocking.get("error_codes", [0.0, 0.0, 0.0])))
    return codes if space == "auto" and _is_jpeg(blocking) else None


def _stays_linear(model: dict[str, Any], codes: float) -> None:
    model["space"] = {"used": "linear", "jpeg_error_codes": codes,
                      "why": "a JPEG, but the model needs more than direct light: the linear loss, as the sRGB "
                             "one would weigh up the dark pixels where the model's approximations err"}


#: An image whose sRGB decoding the base model explains at least this many times better (each loss against
#: its own quantisation floor) is doubted as sRGB-encoded. On the Mitsuba test photos the decoded encodings
#: fit 1.8-15x better, and decoding a linear photo makes the fit 1.1-5.8x worse, never better.
ENCODED_GAIN = 1.5


def _encoding_check(work: Scene, stages: Stages, seed: int, target: np.ndarray, sub: np.ndarray,
                    ratio: float, environment: bool = False) -> dict[str, Any]:
    """Whether ``target`` looks sRGB-encoded rather than linear: the base model fitted once more, on every
    other pixel in each direction, to the target decoded from sRGB; the two residuals against the rounding
    error (:func:`.selection.explained_ratio`; ``ratio``: the fit as given). Run only for photos in [0, 1]
    that the first fit does not explain and whose values are not decoded 8-bit codes; ``environment``: the
    base model has the environment's (or ambient light's) column."""
    decoded = np.ascontiguousarray(decode(target), dtype=np.float32)
    check = Stages(work, decoded, sub, None, stages.budget, stages.ident, clip=stages.clip, norm=stages.norm,
                   space="linear", threads=stages.threads, pixels_per_object=stages.pixels_per_object,
                   rng=np.random.default_rng(seed), callback=None, footprint=stages.footprint)
    check.saturated = None if stages.saturated is None else float(decode(np.float64(stages.saturated)))
    check.projected(seed, environment=environment)
    _, decoded_ratio = explained_ratio(sum(check.stages[-1].objectives), decoded, sub, norm=stages.norm)
    out: dict[str, Any] = {"ratio_as_given": ratio, "ratio_decoded": decoded_ratio,
                           "suspect": bool(decoded_ratio * ENCODED_GAIN <= ratio),
                           "rule": f"doubted when the sRGB-decoded image fits at least {ENCODED_GAIN:g}x better"}
    if out["suspect"]:
        out["doubt"] = (f"image: it looks sRGB-encoded, not linear (decoded from sRGB, the fit's residual is "
                        f"{decoded_ratio:.2g}x the rounding error against {ratio:.2g}x as given): pass linear "
                        "radiance, e.g. rtloop.load_image(path, scene) for a file, or rtloop.srgb_to_linear(array)")
    return out


def _through_camera(args: dict[str, Any], scene: Scene, camera: Camera, t0: float) -> FitResult:
    """``fit()`` (``args``: its arguments) through the camera's terms (:func:`.camera.fit_through_camera`):
    each fit with them off."""
    def once(img: np.ndarray, near: Scene | None = None) -> FitResult:
        return fit(**{**args, "image": img, "vignetting": "off", "tone": "off", "flat_field": None,
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
