"""Which image terms a fit uses, decided from the photo (docs/methods.md, "Image terms").

The default fit starts from the model every photo needs (direct light) and adds a term only where the photo
shows it: nested models compared at the fitted light, by the Bayesian information criterion of the fit's
own loss and by the size of the improvement. The terms: the occluded environment (a room's light from
every direction, darkened under and between the objects: ``render::environment``), one diffuse bounce
between the objects (``render::bounce``), and a sphere's specular lobe. A photo the base model explains
to its quantisation floor pays one sum; otherwise a few closed-form evaluations decide.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _native
from .._srgb import decode, encode, per_code
from ..errors import RtloopError
from ..scene import Scene, scene_to_dict
from .heldout import HeldOut, held_out_evidence, held_out_loss
from .spec import closed_form_spec

__all__ = [
    "BOUNCE_PASSES",
    "ENVIRONMENT_MODES",
    "EXPLAINED",
    "HIGHLIGHT_MODES",
    "MIN_GAIN",
    "SHININESS_BEYOND",
    "SHININESS_TRIALS",
    "check_environment",
    "check_highlights",
    "check_interreflection",
    "closed_form_loss",
    "environment_evidence",
    "environment_given",
    "explained_ratio",
    "highlight_candidates",
    "highlight_evidence",
    "interreflection_evidence",
    "interreflection_given",
    "quantisation_floor",
    "with_highlights",
    "with_interreflection",
]

#: ``fit(environment=...)``: "auto" (default) adds the term when the photo shows it, "on" always fits
#: it, "off" never (today's model).
ENVIRONMENT_MODES = ("auto", "on", "off")

#: ``fit(highlights=...)``: "auto" (default) frees a sphere's specular lobe when the photo shows a highlight
#: the diffuse model cannot explain; "off" never.
HIGHLIGHT_MODES = ("auto", "off")

#: Blinn-Phong exponents tried at the found light to see whether a lobe explains the photo (from a broad
#: sheen to a tight highlight, a factor of about 3 apart); the refit then searches the shininess.
SHININESS_TRIALS = (10.0, 30.0, 100.0, 300.0, 1000.0)
#: Tried too, in turn, while the tightest exponent tried so far is the best: a polished ball's highlight is
#: tighter than SHININESS_TRIALS reach, and a lobe too broad for it pulls the light towards the highlight's
#: centre of mass.
SHININESS_BEYOND = (3000.0, 10000.0)
#: The bounds a freed lobe gets: specular in [0, 1]; shininess within a factor SHININESS_SPAN of the best
#: trial (the trials' spacing: the refit searches between the neighbouring trials), inside SHININESS_RANGE,
#: whose top is twice the tightest of SHININESS_TRIALS unless one of SHININESS_BEYOND was the best.
SPECULAR_RANGE = (0.0, 1.0)
SHININESS_RANGE = (1.0, 2000.0)
SHININESS_SPAN = 3.2

#: A fit whose residual is within this many times the size of the photo's 8-bit rounding error
#: (:func:`explained_ratio`, in the fit's own norm and space) explains the photo: the terms are not tested
#: (with L1 a clean photo of what the base model has leaves 1.9-2.7x, from the pixel footprint at edges;
#: every test photo with an environment, a bounce or gloss 3.7x and more).
EXPLAINED = 3.0

#: The least relative reduction of the loss at the fitted light for "auto" to add a term. The information
#: criterion alone accepts any term that explains a few pixels better (a photo has ~10^4 of them, so
#: ln n per parameter is cheap), including a column that only soaks up some other mismatch; a term must also
#: explain a visible part of the residual.
MIN_GAIN = 0.05


def quantisation_floor(target: np.ndarray, pixels: np.ndarray | None, codes: np.ndarray | None = None, *,
                       norm: str = "l1", space: str = "linear") -> float:
    """The loss an exact model would leave on the photo from 8-bit sRGB quantisation alone, in the fit's
    ``norm`` and ``space``: per pixel and channel the expected penalty of an error uniform over the pixel's
    code step (L1: a quarter of the step, L2: a twelfth of its square, Huber between the two), the step
    in linear units (``space="linear"``) or 1/255 (``"srgb"``, the loss on the encodings), summed over
    ``pixels`` (all when None). ``codes``: ``target``'s 8-bit codes (:func:`rtloop._srgb.codes8`) where it
    has them (each pixel's step looked up: the same numbers)."""
    if norm == "l1" and space == "linear":
        return float(np.sum(_quarter_steps(target, pixels, codes)))
    return _floor(_half_steps(target, pixels, codes, space), 1.0, norm)


def explained_ratio(loss: float, target: np.ndarray, pixels: np.ndarray | None, codes: np.ndarray | None = None,
                    *, norm: str = "l1", space: str = "linear") -> tuple[float, float]:
    """(floor, ratio): :func:`quantisation_floor` in the fit's ``norm`` and ``space``, and how many times
    the size of the quantisation error the residual behind ``loss`` (the fit's loss on ``pixels``, in that
    norm and space) is: the factor the error would have to grow by to leave ``loss`` (L1: loss / floor;
    L2: its square root; Huber: solved). A ratio compares alike in every norm: a residual twice the
    quantisation's size is 2, where L2's loss / floor would be 4 (and that of a JPEG's sRGB-space fit is
    measured on its encodings, where the error is)."""
    if norm == "l1" and space == "linear":
        floor = quantisation_floor(target, pixels, codes)
        return floor, (loss / floor if floor > 0 else float("inf"))
    half = _half_steps(target, pixels, codes, space)
    floor = _floor(half, 1.0, norm)
    if not floor > 0:
        return floor, float("inf")
    if norm == "l1":
        return floor, loss / floor
    if norm == "l2":
        return floor, math.sqrt(loss / floor)
    # Huber: the floor grows with the scale k (as k^2, then k): bracket it by doubling, then bisect.
    values, counts = np.unique(half, return_counts=True)
    lo, hi = 0.0, 1.0
    while _floor(values, hi, norm, counts) < loss and hi < 1e12:
        lo, hi = hi, 2.0 * hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _floor(values, mid, norm, counts) < loss else (lo, mid)
    return floor, hi


def _huber_width(norm: str) -> float | None:
    """H of a "huber" or "huber:H" norm (the core's default 0.02), else None."""
    if norm == "huber":
        return 0.02
    if norm.startswith("huber:"):
        return float(norm.split(":", 1)[1])
    return None


def _floor(half: np.ndarray, k: float, norm: str, counts: np.ndarray | None = None) -> float:
    """Σ E[penalty(q)] over the pixels' channels for q uniform on ±k·``half`` (each value ``counts``
    times; once when None), in ``norm``."""
    a = k * np.asarray(half, np.float64)
    h = _huber_width(norm)
    if norm == "l1":
        e = 0.5 * a
    elif norm == "l2":
        e = a * a / 3.0
    elif h is not None:
        # penalty 0.5 q^2 / H within H, |q| - H/2 beyond (the core's Huber)
        inside = a * a / (6.0 * h)
        safe = np.maximum(a, 1e-300)
        beyond = (h * h / 6.0 + 0.5 * (a * a - h * h) - 0.5 * h * (a - h)) / safe
        e = np.where(a <= h, inside, beyond)
    else:
        raise RtloopError(f"norm: unknown norm {norm!r} (known: l1, l2, huber, huber:H)")
    return float(np.sum(e if counts is None else e * counts))


def _quarter_steps(target: np.ndarray, pixels: np.ndarray | None, codes: np.ndarray | None) -> np.ndarray:
    """A quarter of each used pixel's channel's code step in linear units (:func:`_quarter_step`)."""
    if codes is not None:
        c = np.asarray(codes).reshape(-1, 3)
        return per_code(_quarter_step_at, c if pixels is None else c[pixels])
    x = np.clip(np.asarray(target, np.float64).reshape(-1, 3), 0.0, 1.0)
    return _quarter_step(x if pixels is None else x[pixels])


def _half_steps(target: np.ndarray, pixels: np.ndarray | None, codes: np.ndarray | None, space: str) -> np.ndarray:
    """Half of each used pixel's channel's code step: in linear units, or on the encodings (``"srgb"``:
    1/510, one-sided at 0 and 1, as the linear step is)."""
    if space == "srgb":
        if codes is not None:
            c = np.asarray(codes).reshape(-1, 3)
            e = (c if pixels is None else c[pixels]).astype(np.float64) / 255.0
        else:
            x = np.clip(np.asarray(target, np.float64).reshape(-1, 3), 0.0, 1.0)
            e = encode(x if pixels is None else x[pixels]).astype(np.float64)
        half = 0.5 / 255
        return 0.5 * (np.minimum(e + half, 1.0) - np.maximum(e - half, 0.0))
    return 2.0 * _quarter_steps(target, pixels, codes)


def _quarter_step(x: np.ndarray) -> np.ndarray:
    """A quarter of the 8-bit code step in linear units at the linear values ``x`` (float64, in [0, 1])."""
    e = encode(x)
    half = 0.5 / 255  # half a code step, either side of the value's code
    step = decode(np.minimum(e + half, 1.0)) - decode(np.maximum(e - half, 0.0))
    return 0.25 * step


def _quarter_step_at(x: np.ndarray) -> np.ndarray:
    """:func:`_quarter_step` at the values ``x`` (any dtype) in float64, clipped to [0, 1]."""
    return _quarter_step(np.clip(np.asarray(x, np.float64), 0.0, 1.0))


def check_environment(mode: Any) -> str:
    """``mode`` if it is one of ENVIRONMENT_MODES, else an RtloopError naming the argument."""
    if mode not in ENVIRONMENT_MODES:
        raise RtloopError(f"environment: must be one of {', '.join(ENVIRONMENT_MODES)} (got {mode!r})")
    return str(mode)


def check_highlights(mode: Any) -> str:
    """``mode`` if it is one of HIGHLIGHT_MODES, else an RtloopError naming the argument."""
    if mode not in HIGHLIGHT_MODES:
        raise RtloopError(f"highlights: must be one of {', '.join(HIGHLIGHT_MODES)} (got {mode!r})")
    return str(mode)


def highlight_candidates(scene: Scene) -> list[str]:
    """The spheres whose lobe the fit may free: matte in the scene (specular 0), specular not in the fit
    section, albedo free (the lobe's product then joins the closed form)."""
    paths = scene.fit_paths
    if "light.position" not in paths and "light.direction" not in paths:
        return []
    return [o["name"] for o in scene_to_dict(scene)["objects"]
            if o["shape"] == "sphere" and o["material"]["specular"] == 0 and "coat" not in o["material"]
            and f"objects.{o['name']}.specular" not in paths and f"objects.{o['name']}.shininess" not in paths
            and f"objects.{o['name']}.albedo" in paths]


def with_highlights(scene: Scene, names: list[str], shininess: float) -> Scene:
    """``scene`` with the specular and shininess of ``names`` freed (SPECULAR_RANGE; the shininess within
    SHININESS_SPAN of ``shininess``, inside SHININESS_RANGE unless ``shininess`` is beyond SHININESS_TRIALS),
    the shininess at ``shininess``."""
    lo = max(SHININESS_RANGE[0], shininess / SHININESS_SPAN)
    hi = shininess * SHININESS_SPAN if shininess > SHININESS_TRIALS[-1] else min(SHININESS_RANGE[1],
                                                                                shininess * SHININESS_SPAN)
    changes: dict[str, tuple[Any, Any]] = {}
    for n in names:
        changes[f"objects.{n}.specular"] = SPECULAR_RANGE
        changes[f"objects.{n}.shininess"] = (lo, hi)
    out = scene.with_bounds(changes)
    return out.with_params([shininess] * len(names), [f"objects.{n}.shininess" for n in names])


def highlight_evidence(scene: Scene, names: list[str], paths: list[str], x: list[float], target: np.ndarray,
                       pixels: np.ndarray | None, *, base: float, environment: bool, clip: bool, norm: str,
                       space: str, threads: int | None, active_pixels: int,
                       saturated: float | None = None) -> tuple[dict[str, Any], float]:
    """Whether a specular lobe on the spheres ``names`` explains the photo better at the light ``x`` found
    without it: the closed-form loss without, and with the lobe at each of SHININESS_TRIALS (its strength
    solved in closed form); the best trial, the gain, the change in BIC (k = 2 per sphere: strength and
    shininess) and the verdict (as :func:`environment_evidence`, in-sample only). Returns the evidence and
    the shininess."""
    glossy = with_highlights(scene, names, SHININESS_TRIALS[0])
    gpaths = paths + [f"objects.{n}.shininess" for n in names]

    def losses(trials: tuple[float, ...]) -> list[float]:
        rows = [list(x) + [s] * len(names) for s in trials]
        # With a bounce, the trials share one: held where the first is (the light does not move between
        # them, and a lobe's shininess shapes no diffuse bounce), so each costs a direct candidate's solve
        # instead of the bounce's fixed point.
        return [float(v) for v in closed_form_loss(
            glossy, gpaths, rows, target, pixels, environment=environment, clip=clip, norm=norm, space=space,
            threads=threads, saturated=saturated, frozen_bounce=interreflection_given(glossy))]

    tried, with_lobe = list(SHININESS_TRIALS), losses(SHININESS_TRIALS)
    for beyond in SHININESS_BEYOND:
        if int(np.argmin(with_lobe)) != len(tried) - 1:
            break
        tried.append(beyond)
        with_lobe += losses((beyond,))
    k = int(np.argmin(with_lobe))
    ev = _verdict(base, with_lobe[k], active_pixels, 2 * len(names), norm, nested=True)
    # not judged on held-out pixels: a highlight is local (a tight lobe lights a few blocks), and products
    # fitted on the other blocks do not predict it (docs/methods.md, "Held-out pixels")
    ev["selected_in_sample"] = ev["selected"]
    ev["held_out"] = {"skipped": "not measured: a highlight is local, so a lobe is judged in-sample" if ev["selected"]
                      else "not measured: the in-sample rule rejects the term"}
    ev["shininess_tried"] = tried
    ev["loss_per_shininess"] = with_lobe
    return ev, tried[k]


def check_interreflection(mode: Any) -> str:
    """``mode`` if it is one of ENVIRONMENT_MODES (auto, on, off), else an RtloopError naming the argument."""
    if mode not in ENVIRONMENT_MODES:
        raise RtloopError(f"interreflection: must be one of {', '.join(ENVIRONMENT_MODES)} (got {mode!r})")
    return str(mode)


#: The refit with the bounce ranks lights with the bounce held at a reference light (``_native.optimize``'s
#: ``frozen_bounce``: a candidate then costs a direct one's factors and one solve, not the bounce's fixed
#: point): first at the light found without the bounce (a search whose polish takes half the budget where
#: passes follow), then, for each further pass, at the light the previous pass found (a Nelder-Mead polish
#: from it, with half the polish budget, in a tenth of the box around it), at most this many passes: a
#: third pass only while the second moved the light by more than a thousandth of the box (the held
#: bounce's fixed point; a light the fit without the terms put 20 cm off moves 5 cm in the second pass and
#: 2 cm in the third); the last pass's result carries the full bounce's products, gauge and loss at its
#: light. A fourth pass would search a thousandth of the refit's box (+-2.4 mm on a lamp photo), less than
#: the polish's own scatter on a noisy photo (the passes' moves near the fixed point, 2-5 mm): over the 25
#: bounce, lamp and environment photos (11 committed, 14 held out) allowing it gave a mean light error of
#: 8.78 mm against 8.76 without (median 6.08 against 5.64 mm, mean worst product 1.95 against 1.97 %), for
#: 108 more evaluations on each of the three photos that took it (+13 % of those fits' evaluations).
BOUNCE_PASSES = 3


def interreflection_given(scene: Scene) -> bool:
    """Whether the scene itself models one bounce (``"interreflection": true``)."""
    return bool(scene_to_dict(scene).get("interreflection", False))


def with_interreflection(scene: Scene) -> Scene:
    """``scene`` with one diffuse bounce between its objects."""
    return Scene(json.dumps({**scene_to_dict(scene), "interreflection": True}, allow_nan=False))


def interreflection_evidence(scene: Scene, paths: list[str], x: list[float], target: np.ndarray,
                             pixels: np.ndarray | None, *, base: float, environment: bool, clip: bool, norm: str,
                             space: str, threads: int | None, active_pixels: int,
                             saturated: float | None = None, held: HeldOut | None = None) -> dict[str, Any]:
    """Whether one bounce between the objects explains the photo better at the light ``x`` found without
    it: the closed-form loss without (``base``) and with it (its one extra unknown is the gauge, 1 /
    intensity: k = 1), as :func:`environment_evidence`. Not selected on a scene with a coated object (the
    bounce's closed form does not model the coat)."""
    if any("coat" in o["material"] for o in scene_to_dict(scene)["objects"]):
        return {"loss_without": base, "loss_with": base, "gain": 0.0, "delta_bic": None, "selected": False,
                "rule": "not tested: the bounce does not model a coated object", "nested": False,
                "loss_with_nested": base, "raised": False}
    kw = {"environment": environment, "clip": clip, "norm": norm, "space": space, "threads": threads,
          "saturated": saturated}
    bounced = with_interreflection(scene)
    l1 = closed_form_loss(bounced, paths, [x], target, pixels, **kw)[0]
    ev = _verdict(base, l1, active_pixels, 1, norm, nested=False)
    return _judge_held_out(ev, held, lambda folds: held_out_loss(bounced, paths, x, target, pixels, folds, **kw))


def environment_given(scene: Scene) -> bool:
    """Whether the scene itself has the term: ``environment`` free in its fit section, or a value given."""
    return "environment" in scene.fit_paths or any(v != 0 for v in scene_to_dict(scene).get("environment", [0, 0, 0]))


def environment_evidence(scene: Scene, paths: list[str], x: list[float], target: np.ndarray,
                         pixels: np.ndarray | None, *, base: float, clip: bool, norm: str, space: str,
                         threads: int | None, active_pixels: int, saturated: float | None = None,
                         held: HeldOut | None = None) -> dict[str, Any]:
    """Whether the occluded environment explains the photo better at the light ``x`` (of ``paths``) found
    without it: the closed-form loss without (``base``, :func:`closed_form_loss`) and with each object's
    environment column, the relative gain,
    the change in BIC (for the L1 and Huber norms, a Laplace likelihood: 2 n ln(L0/L1); for L2, Gaussian:
    n ln(L0/L1); minus k ln n for the k = 3 x objects added products), and the verdict. ``held``: the
    folds and the held-out loss without the term (:mod:`.heldout`), to compare with the term's (None: not
    compared)."""
    kw = {"clip": clip, "norm": norm, "space": space, "threads": threads, "saturated": saturated}
    l1 = closed_form_loss(scene, paths, [x], target, pixels, environment=True, **kw)[0]
    ev = _verdict(base, l1, active_pixels, 3 * len(scene.object_names), norm, nested=True)
    return _judge_held_out(ev, held, lambda folds: held_out_loss(scene, paths, x, target, pixels, folds,
                                                                 environment=True, **kw))


def closed_form_loss(scene: Scene, paths: list[str], rows: list[list[float]], target: np.ndarray,
                     pixels: np.ndarray | None, *, environment: bool, clip: bool, norm: str, space: str,
                     threads: int | None, saturated: float | None = None, frozen_bounce: bool = False
                     ) -> np.ndarray:
    """The closed-form (least-squares products) loss of ``scene`` at each row of values of ``paths``, with
    or without the environment column: the measure every test of a term compares (its spec:
    :func:`.spec.closed_form_spec`). ``saturated``: where clipping may start (None: SATURATED).
    ``frozen_bounce``: with interreflection, the bounce solved once at the scene's own values and held for
    every row."""
    spec = closed_form_spec(scene, paths, pixels, environment=environment, clip=clip, norm=norm, space=space,
                            saturated=saturated, frozen_bounce=frozen_bounce)
    v = _native.evaluate(scene, target, np.asarray(rows, dtype=np.float64), spec, threads=threads)
    return v[:, 0]


#: Why a term's closed-form loss can exceed the loss without it (``evidence[term]["why_raised"]``).
WHY_RAISED = {
    True: ("the closed form solves the products by least squares and the loss is the fit's {norm}: a term's column "
           "lowers the squared residual, not always the {norm} loss (a residual with large one-signed regions, "
           "such as a light the model lacks, pulls least-squares products away from the {norm} optimum); the "
           "term's own products at 0 give the loss without it, so its best loss is at most that "
           "(``loss_with_nested``)"),
    False: ("the bounce is not nested in the direct model: its strength is the albedos' over the light's "
            "intensity, which the intensity's bounds (or a known intensity) keep from 0, so it cannot be "
            "switched off by its products"),
}


def _judge_held_out(ev: dict[str, Any], held: HeldOut | None,
                    with_term: Callable[[np.ndarray], float]) -> dict[str, Any]:
    """``ev`` (:func:`_verdict`'s) with the held-out comparison (:mod:`.heldout`) where ``held`` is given:
    measured only where the in-sample rule selects the term (``with_term(folds)``: the held-out loss with it),
    and the term then selected only where the held-out loss falls by HELD_OUT_GAIN too
    (``selected_in_sample`` keeps the in-sample verdict)."""
    if held is None:
        return ev
    ev["selected_in_sample"] = ev["selected"]
    if not ev["selected"]:
        ev["held_out"] = {"skipped": "not measured: the in-sample rule rejects the term"}
        return ev
    ev["held_out"] = held_out_evidence(held.without(), with_term(held.folds))
    ev["selected"] = ev["held_out"]["passes"]
    return ev


def _verdict(l0: float, l1: float, active_pixels: int, k: int, norm: str, *, nested: bool) -> dict[str, Any]:
    """The evidence for a term that takes the loss from ``l0`` to ``l1`` with ``k`` more parameters.
    ``nested``: the model without the term is the model with it at 0 (the environment, a lobe: their
    products' bounds hold 0), so the term's best loss is at most ``l0`` (``loss_with_nested``); the
    selection is unchanged by it (a term must lower the closed form's own loss)."""
    n = 3 * max(int(active_pixels), 1)
    gain = (l0 - l1) / l0 if l0 > 0 else 0.0
    per = n if norm == "l2" else 2 * n
    if l0 > 0 and l1 > 0:
        dbic = per * math.log(l0 / l1) - k * math.log(n)
    else:
        dbic = math.inf if l0 > l1 else -k * math.log(n)
    selected = bool(gain >= MIN_GAIN and dbic > 0)
    out = {
        "loss_without": l0,
        "loss_with": l1,
        "gain": gain,
        "delta_bic": dbic if math.isfinite(dbic) else None,
        "selected": selected,
        "rule": f"added when the loss falls by at least {MIN_GAIN:.0%} and the BIC falls",
        "nested": nested,
        "loss_with_nested": min(l0, l1) if nested else l1,
        "raised": bool(l1 > l0),
    }
    if l1 > l0:
        out["why_raised"] = WHY_RAISED[nested].format(norm=norm.upper())
    return out
