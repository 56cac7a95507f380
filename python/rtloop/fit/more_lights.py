"""The default fit's number of lights: one light, and more only where the photo asks for them.

``fit(scene, image)`` without ``lights`` fits one light (the ordinary fit). Where that fit does not explain
the photo (its goodness ratio at or above EXPLAINED_RATIO, with a smooth residual on some object: a
cheap test, the verdict the fit computes anyway: :func:`gate`), the lights fit tries a further light on half
the pixels and keeps it only where the other half say so (:func:`.lights.held_out_counts`, ``"auto"``'s
rule, up to AUTO_LIMIT lights), against the one light through a camera's curve and field as well. A kept
light makes the result a :class:`.lights.LightsFit`; otherwise the one-light result is returned
unchanged, with the test and its evidence in ``result.model["lights"]``.
docs/methods.md, "Several lights".
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _native
from .._srgb import codes8, decode, encode
from ..errors import RtloopError
from ..scene import Scene, load_scene, scene_to_dict
from .camera import KNOTS, nnls
from .framing import measure
from .goodness import EXPLAINED_RATIO
from .inputs import objective
from .lights import AUTO_GAIN, AUTO_LIMIT, LightsFit, attach_errors, held_out_counts
from .options import not_with_lights
from .result import FitResult

__all__ = ["MIN_ANGLE_DEG", "MIN_SHARE", "distinct", "gate", "more_lights"]

#: A further light the default fit adds must carry this share of the objects' diffuse light at least (its
#: products over all the lights' products): a light that lights no matte surface (its diffuse products 0,
#: a lobe's only) stands in for a mismatch of the highlight, not for a lamp.
MIN_SHARE = 0.02
#: ... and stand this many degrees from every other light at least, seen from the subject (the spheres'
#: mean centre; the scene's origin without one). Two lights a few degrees apart shade every surface alike
#: but at the terminator: the pair stands in for one light's shape (a size, or a falloff the matte model
#: lacks: on the DiLiGenT ball such pairs 1.7-7.4 degrees apart were kept by the held-out error alone;
#: the key and fill of tests/fixtures/lights stand 80 degrees apart).
MIN_ANGLE_DEG = 20.0


def gate(result: FitResult) -> dict[str, Any]:
    """The test on the one-light fit: ``fires`` where its residual is at least EXPLAINED_RATIO times the
    photo's noise floor and some object's excess is smooth (``structured``: the objects whose residual
    :mod:`.goodness` does not call texture or noise). ``framing_mismatch``: the framing check found the
    outlines off (``goodness["framing"]``), which a lamp the one light lacks can do too (its light on the
    far side of a ball moves the outline's edges): a further light found is then kept only where the
    outlines register against its render (:func:`more_lights`)."""
    g = result.goodness or {}
    ratio = g.get("ratio")
    structured = sorted(name for name, what in (g.get("explained") or {}).items() if what != "texture/noise")
    framing = bool((g.get("framing") or {}).get("mismatch"))
    fires = ratio is not None and ratio >= EXPLAINED_RATIO and bool(structured)
    return {"ratio": ratio, "explained_below": EXPLAINED_RATIO, "structured": structured,
            **({"framing_mismatch": True} if framing else {}), "fires": bool(fires)}


def _not_tried(result: FitResult, args: dict[str, Any], defaults: dict[str, Any]) -> str | None:
    """Why the lights fit cannot take this call (an argument it does not take given, a photo the one-light
    fit resampled into the scene's framing) or should not (the image's values doubted: ``image:``
    warnings), or None."""
    name = not_with_lights(args, defaults)
    if name is not None:
        return f"{name} given, which the lights fit does not take"
    if args["uncertainty"] == "bootstrap":
        return "uncertainty 'bootstrap' asked, which the lights fit does not take"
    if result.reframed is not None:
        return "the one-light fit resampled the photo into the scene's framing; the lights fit does not"
    doubted = [w for w in result.warnings if w.startswith("image:")]
    if doubted:  # e.g. an sRGB encoding passed as linear: its residual is the encoding's, not a lamp's
        return f"the image itself is doubted ({doubted[0].split(':', 2)[1].strip()}): no further light is tried"
    return None


def _trial_scene(scene: Scene, result: FitResult) -> Scene:
    """The scene the further lights are tried in: as given, but with the lobes the one-light fit found (their
    specular and shininess held: the lights fit solves a lobe's product, not its shininess)."""
    d = scene_to_dict(scene)
    fitted = {o["name"]: o["material"] for o in result.scene.to_dict()["objects"]}
    for o in d["objects"]:
        m = fitted.get(o["name"], {})
        if float(m.get("specular", 0.0)) > 0:
            o["material"].update(specular=float(m["specular"]), shininess=float(m["shininess"]))
    d["fit"] = {p: v for p, v in d["fit"].items() if not p.endswith((".specular", ".shininess"))}
    return load_scene(d)


def _held_out_error(result: FitResult, target: np.ndarray) -> Callable[[np.ndarray, np.ndarray],
                                                                          dict[str, float]]:
    """The one-light fit's squared errors on the held-out pixels (flat indices), its render clipped at 1 as
    the fit compares it: every term it selected (room light, a bounce, a lobe) counts, which the lights fit
    lacks. Three times: as rendered (``given_fit``); through the monotone curve per channel that maps the
    render to the photo best on the training pixels (``given_fit_tone``, :func:`monotone_error`); and times
    the smooth field over the image that does (``given_fit_field``, :func:`field_error`). What the camera
    does that the model lacks (its curve, a falloff or an exposure gradient across the frame) leaves a
    smooth residual that a further light can soak up; the one light's shading explains it through a curve
    or a field, where a further lamp's shading, from another direction and varying with the surfaces'
    normals and shadows, it cannot."""
    s = result.scene
    render = np.minimum(np.asarray(_native.render(s, s.width, s.height, 1), np.float64), 1.0).reshape(-1, 3)
    photo = target.reshape(-1, 3).astype(np.float64)

    def error(held: np.ndarray, train: np.ndarray) -> dict[str, float]:
        return {"given_fit": float(((render[held] - photo[held]) ** 2).sum()),
                "given_fit_tone": monotone_error(render, photo, train, held),
                "given_fit_field": field_error(render, photo, train, held, s.width, s.height)}
    return error


def field_error(render: np.ndarray, photo: np.ndarray, train: np.ndarray, held: np.ndarray, width: int,
                height: int) -> float:
    """The squared error on ``held`` of the photo (N, 3) against the render times a quadratic field over the
    image per channel, 1, u, v, u^2, uv, v^2 in the image's coordinates (u, v in [-1, 1]), its six weights
    the least squares on ``train``."""
    def basis(pixels: np.ndarray, c: int) -> np.ndarray:
        u = 2.0 * (pixels % width + 0.5) / width - 1.0
        v = 2.0 * (pixels // width + 0.5) / height - 1.0
        return render[pixels, c][:, None] * np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=1)

    total = 0.0
    for c in range(3):
        w = np.linalg.lstsq(basis(train, c), photo[train, c], rcond=None)[0]
        total += float(((basis(held, c) @ w - photo[held, c]) ** 2).sum())
    return total


def _floor(result: FitResult, target: np.ndarray) -> Callable[[np.ndarray], float]:
    """The squared error a perfect model leaves on given pixels: per pixel and channel the photo's noise
    variance (the goodness's ``noise_sigma``) and, for 8-bit codes, the rounding's (the code step there
    squared over 12)."""
    sigma2 = np.square(np.asarray((result.goodness or {}).get("noise_sigma") or [0.0, 0.0, 0.0], np.float64))
    codes = codes8(target)
    if codes is None:
        rounding = np.zeros((target.shape[0] * target.shape[1], 3))
    else:
        c = codes.reshape(-1, 3).astype(np.float64)
        step = decode(np.minimum(c + 0.5, 255.0) / 255.0) - decode(np.maximum(c - 0.5, 0.0) / 255.0)
        rounding = step * step / 12.0

    def floor(pixels: np.ndarray) -> float:
        return float((rounding[pixels] + sigma2).sum())
    return floor


def monotone_error(render: np.ndarray, photo: np.ndarray, train: np.ndarray, held: np.ndarray) -> float:
    """The squared error on ``held`` of the photo (N, 3) against g_c(render) per channel c, g_c the
    non-decreasing piecewise-linear curve of the render's sRGB encoding (knots :data:`.camera.KNOTS`, a
    non-negative offset and slopes: non-negative least squares) fitted on ``train``."""
    def basis(v: np.ndarray) -> np.ndarray:
        lo, hi = KNOTS[:-1], KNOTS[1:]
        return np.hstack([np.ones((v.size, 1)), np.clip(v[:, None] - lo, 0.0, hi - lo)])

    code = encode(np.clip(render, 0.0, 1.0))
    total = 0.0
    for c in range(3):
        w = nnls(basis(code[train, c]), photo[train, c])
        total += float(((basis(code[held, c]) @ w - photo[held, c]) ** 2).sum())
    return total


def distinct(found: LightsFit, have: int) -> dict[str, Any]:
    """The default fit's further rule for ``found``'s lights past the first ``have``: each carries MIN_SHARE
    of the light and stands MIN_ANGLE_DEG from every other light (seen from the subject)."""
    d = found.scene.to_dict()
    centres = [o["center"] for o in d["objects"] if o.get("shape") == "sphere"]
    centre = np.mean(np.asarray(centres, float), axis=0) if centres else np.zeros(3)

    def towards(light: dict[str, Any]) -> np.ndarray:
        v = np.asarray(light["position"], float) - centre if "position" in light else \
            -np.asarray(light["direction"], float)
        return v / max(float(np.linalg.norm(v)), 1e-300)

    ways = [towards(light) for light in found.lights]
    angle = min(float(np.degrees(np.arccos(np.clip(ways[i] @ ways[j], -1.0, 1.0))))
                for i in range(have, len(ways)) for j in range(len(ways)) if j != i)
    share = min(float(light["share"]) for light in found.lights[have:])
    passes = share >= MIN_SHARE and angle >= MIN_ANGLE_DEG
    return {"least_share": share, "least_angle_deg": angle, "passes": passes}


#: The one-light baselines a further light must beat (:func:`_held_out_error` and the lights fit's own).
BASELINES = {"lights_fit": "the lights fit's one light", "given_fit": "the one-light fit as it is",
             "given_fit_tone": "the one-light fit through a tone curve",
             "given_fit_field": "the one-light fit times a smooth field over the image"}


def _baseline(evidence: list[dict[str, Any]]) -> str:
    """Which one-light baseline a further light had to beat: the best on the held-out pixels of those in
    ``evidence``'s first entry (the one-light counts), named."""
    first = evidence[0] if evidence else {}
    scores = {k: float(first[k]) for k in BASELINES if k in first}
    if not scores:
        return "the one-light fit"
    return BASELINES[min(scores, key=scores.__getitem__)]


def more_lights(result: FitResult, scene: Scene, image: np.ndarray, mask: Any, args: dict[str, Any],
                defaults: dict[str, Any], t0: float) -> FitResult | LightsFit:
    """The default fit's answer: ``result`` (the one-light fit) unchanged where :func:`gate` does not fire;
    else further lights tried, and the lights fit returned where held-out pixels keep one (``args``:
    fit()'s arguments, ``defaults`` its defaults; ``t0``: when the fit began). A further light must beat
    the best of the lights fit's one light and the one-light fit as it is, through a curve and times a
    field (:func:`_held_out_error`), scored on the held-out pixels (it saw them; its terms included); where
    the framing check found the outlines off, they must register against the lights' render too."""
    test = gate(result)
    if not test["fires"]:
        return result
    why = _not_tried(result, args, defaults)
    found, evidence = None, []
    if why is None:
        try:
            trial = _trial_scene(scene, result)
            target, use = objective(scene, image, mask, [])
            found, evidence, pixels = held_out_counts(trial, target, seed=args["seed"], limit=AUTO_LIMIT, mask=use,
                                                      first=_held_out_error(result, target), check=distinct,
                                                      floor=_floor(result, target), threads=args["threads"])
        except RtloopError as e:  # a scene the lights fit does not take (a coat, a directional light, ...)
            why = str(e)
    record = {**test, "tried": why is None, "limit": AUTO_LIMIT, "gain": AUTO_GAIN, "min_share": MIN_SHARE,
              "min_angle_deg": MIN_ANGLE_DEG}
    if found is None:
        record.update(kept=1, evidence=evidence, why=why or (
            f"no further light lowered the held-out error of {_baseline(evidence)} by {AUTO_GAIN:.0%}, "
            f"carrying {MIN_SHARE:.0%} of the light {MIN_ANGLE_DEG:g} degrees from the others: the one-light "
            "fit is kept"))
        result.model["lights"] = record
        result.seconds = time.perf_counter() - t0
        return result
    if test.get("framing_mismatch"):  # the outlines were off against the one light's render: and now?
        s = found.scene
        again, _ = measure(s, target, use, np.asarray(_native.render(s, s.width, s.height, 1), np.float32))
        record["framing_with_lights"] = again
        if again["mismatch"]:
            record.update(kept=1, evidence=evidence, why=(
                f"{len(found.lights)} lights were kept by the held-out pixels, but the objects' outlines lie "
                f"{again['outline_rms_px']:.1f} px (RMS) off against their render too: the residual is the "
                "framing's, not a lamp's; the one-light fit is kept"))
            result.model["lights"] = record
            result.seconds = time.perf_counter() - t0
            return result
    attach_errors(trial, found, target, pixels, args["seed"])
    found.gate = {**record, "kept": len(found.lights)}
    found.seconds = time.perf_counter() - t0
    return found
