"""What a fit's residual is made of, per object: fine and zero-mean (texture, noise, JPEG: no shading can
absorb it, and it does not bias the light), or smooth, with structure a shading could absorb (a wrong light,
occluded room light, a lens's falloff, a camera's tone curve). Used by :func:`rtloop.fit.goodness.goodness`
where the residual exceeds the noise floor.

The split: the signed residual's local mean over a STRUCTURE_WINDOW x STRUCTURE_WINDOW box of the object's own
used pixels (a normalised box filter; silhouettes do not mix objects) is its smooth part, the rest its fine
part. White residual keeps about 1/sqrt(n) of its size in the local mean of n pixels; so the smooth part
counts beyond that share of the fine part (``excess``), and is "structured" when that excess exceeds
STRUCTURED_RATIO times the object's noise floor. A structured object's smooth residual is then regressed on
the candidate causes' columns over its pixels (each beside a level and the model itself: the products
absorb those), and the
cause that explains most of it, at least NAMED_SHARE, is named."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from .. import _native
from ..scene import Scene, scene_to_dict

__all__ = ["NAMED_SHARE", "STRUCTURED_RATIO", "STRUCTURE_WINDOW", "residual_structure"]

#: The side, in pixels, of the box whose mean is a pixel's smooth residual.
STRUCTURE_WINDOW = 7
#: An object's smooth residual beyond white residual's share counts as structure the model lacks when it
#: exceeds this many times the object's noise floor (the goodness verdict's own factor).
STRUCTURED_RATIO = 3.0
#: A cause is named when its columns explain at least this share of the smooth residual's sum of squares.
NAMED_SHARE = 0.5
#: ... and at least this much more than any other cause (causes alike on an object, such as a moved light and
#: a lens's falloff on one ball, are not told apart).
NAMED_MARGIN = 0.15
#: The relative step of the light's position (of the distance to the subject) for its columns.
LIGHT_STEP = 0.01

CAUSES = {
    "light": "the light's position or direction (the shading is shaped as a moved light's would be)",
    "occlusion": "room light that the objects occlude (darker under and between them: an environment, not a "
                 "constant ambient)",
    "vignetting": "the lens's falloff towards the corners (vignetting)",
    "tone_curve": "the camera's tone curve (values off in proportion to how bright they are, not as sRGB)",
}


def _box_mean(x: np.ndarray, w: np.ndarray, side: int) -> np.ndarray:
    """Per pixel the mean of ``x`` (H, W, C) over the pixels of weight ``w`` (H, W; 0 or 1) within the
    ``side`` x ``side`` box around it (0 where none): OpenCV's box sums, zero beyond the image."""
    import cv2  # here, not at import: `import rtloop` loads no OpenCV

    def boxsum(a: np.ndarray) -> np.ndarray:
        planes = a.reshape(a.shape[0], a.shape[1], -1)
        # at most CV_CN_MAX (512) channels a call
        out = [cv2.boxFilter(np.ascontiguousarray(planes[..., i:i + 256]), -1, (side, side), normalize=False,
                             borderType=cv2.BORDER_CONSTANT) for i in range(0, planes.shape[2], 256)]
        out = [o.reshape(a.shape[0], a.shape[1], -1) for o in out]
        return np.concatenate(out, axis=2).reshape(a.shape)

    n = boxsum(w.astype(np.float64)[..., None])[..., 0]
    s = boxsum(x * w[..., None])
    return np.where(n[..., None] > 0, s / np.maximum(n, 1.0)[..., None], 0.0)


def _light_columns(d: dict[str, Any]) -> list[np.ndarray]:
    """The render's change per moved light: one render with the light moved by LIGHT_STEP of its distance
    to the subject along each axis (or its direction turned by that many radians about two axes), less the
    render at the fitted light; the direct light alone."""
    light = d.get("light")
    if not isinstance(light, dict):
        return []
    base = {**d, "fit": {}}
    scenes = [Scene(json.dumps(base, allow_nan=False))]
    if "position" in light:
        p = np.asarray(light["position"], float)
        centres = [o["center"] for o in d["objects"] if o.get("shape") == "sphere"]
        ref = np.mean(np.asarray(centres, float), axis=0) if centres else np.zeros(3)
        h = LIGHT_STEP * max(float(np.linalg.norm(p - ref)), 0.1)
        moves = [{**light, "position": (p + h * e).tolist()} for e in np.eye(3)]
    elif "direction" in light:
        v = np.asarray(light["direction"], float)
        v = v / np.linalg.norm(v)
        a = np.eye(3)[int(np.argmin(np.abs(v)))]
        u = np.cross(v, a)
        u /= np.linalg.norm(u)
        w = np.cross(v, u)
        moves = [{**light, "direction": (v + LIGHT_STEP * t).tolist()} for t in (u, w)]
    else:
        return []
    scenes += [Scene(json.dumps({**base, "light": m}, allow_nan=False)) for m in moves]
    images, _ = _native.render_many(scenes)
    ref_img = np.asarray(images[0], np.float64)
    return [np.asarray(im, np.float64) - ref_img for im in images[1:]]


def _occlusion_column(d: dict[str, Any]) -> np.ndarray:
    """Per pixel its sky view factor (the unit environment's render with every albedo 1): where a constant
    room light is occluded."""
    from .products import unit_environment

    return np.asarray(unit_environment(d), np.float64)[..., None].repeat(3, axis=2)


def residual_structure(scene: Any, target: np.ndarray, model: np.ndarray, keep: np.ndarray, floor: np.ndarray,
                       ids: np.ndarray, names: list[str], causes: bool = True) -> dict[str, Any]:
    """Per object of ``names`` (index k, -1 the background), the split of its residual ``model - target``
    (both (H, W, 3)) over the used pixels ``keep`` (flat bool) into a fine and a smooth part, their sums of
    absolute values (``fine``, ``smooth``), its noise floor's (``floor``), the smooth part beyond white residual's share of the fine
    (``excess``) over the object's noise floor (``floor``: per used pixel and channel, as ``keep`` selects;
    ``structured_ratio``), whether that is structure (``structured``), and for a structured object the share
    of its smooth residual each cause explains (``causes``) and the one named (``cause``, None where none
    reaches NAMED_SHARE: ``why`` then; not with ``causes`` False: the split alone). ``ids``: the object index
    per pixel (flat)."""
    h, w = target.shape[:2]
    r = (np.asarray(model, np.float64) - np.asarray(target, np.float64)).reshape(h, w, 3)
    kept = keep.reshape(h, w)
    ids2 = ids.reshape(h, w)
    floor_img = np.zeros((h * w, 3))
    floor_img[keep] = floor
    floor_img = floor_img.reshape(h, w, 3)
    n_eff = float(STRUCTURE_WINDOW * STRUCTURE_WINDOW)
    out: dict[str, Any] = {}
    smooth_of: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for k, name in [*enumerate(names), (-1, "background")]:
        sel = kept & (ids2 == k)
        if not sel.any():
            continue
        lp = _box_mean(r, sel, STRUCTURE_WINDOW)
        smooth = float(np.abs(lp[sel]).sum())
        fine = float(np.abs(r[sel] - lp[sel]).sum())
        # Of white residual, the local mean keeps about 1/sqrt(n) of its size (n the box's pixels: fewer at
        # an outline, so this is a lower bound of white residual's share and errs towards "structured").
        excess = max(smooth - fine / math.sqrt(n_eff - 1.0), 0.0)
        fl = float(floor_img[sel].sum())
        ratio = excess / fl if fl > 0 else (math.inf if excess > 0 else 0.0)
        entry: dict[str, Any] = {"fine": fine, "smooth": smooth, "excess": excess, "floor": fl,
                                 "structured_ratio": ratio if math.isfinite(ratio) else None,
                                 "structured": bool(ratio >= STRUCTURED_RATIO)}
        out[name] = entry
        if entry["structured"] and k >= 0 and causes:
            smooth_of[k] = (sel, lp)
    if smooth_of:
        d = scene_to_dict(scene) if not isinstance(scene, dict) else scene
        m3 = np.asarray(model, np.float64).reshape(h, w, 3)
        columns = _cause_columns(d, m3, ids2)
        # every image a regression needs, the model's first, as one stack: one box mean per object
        stack = np.concatenate([m3, *(c for cols in columns.values() for c in cols)], axis=2)
        for k, (sel_full, lp_full) in smooth_of.items():
            box = _around(sel_full, STRUCTURE_WINDOW // 2)  # the object's pixels and the window's reach
            sel = sel_full[box]
            means = _box_mean(stack[box], sel, STRUCTURE_WINDOW)[sel]  # (n, 3 x images)
            out[names[k]].update(_attribute(lp_full[box][sel].ravel(), means, columns))
    return out


def _around(sel: np.ndarray, margin: int) -> tuple[slice, slice]:
    """The rows and columns of the bounding box of ``sel`` (H, W bool), ``margin`` pixels wider (a box mean
    over it is the full image's there: the pixels beyond hold none of the object's)."""
    rows, cols = np.flatnonzero(sel.any(axis=1)), np.flatnonzero(sel.any(axis=0))
    return (slice(max(int(rows[0]) - margin, 0), int(rows[-1]) + margin + 1),
            slice(max(int(cols[0]) - margin, 0), int(cols[-1]) + margin + 1))


def _attribute(y: np.ndarray, means: np.ndarray, columns: dict[str, list[np.ndarray]]) -> dict[str, Any]:
    """The share of the smooth residual ``y`` (flat, pixel-major over the channels) each cause explains
    beyond the baseline every cause has (per channel a level and the model's own scale: the products absorb
    both), from the box means ``means`` (n, 3 x images: the model's, then each cause's columns in order); the
    cause named, or None and why. Least squares by the normal equations of the unit-norm columns, their sums
    by einsum (a few columns: a solve of the tall matrix, or a threaded BLAS call beside the renderer's
    threads, costs 10-100x more)."""
    n = means.shape[0]
    base = []
    for c in range(3):  # a level per channel
        e = np.zeros((n, 3))
        e[:, c] = 1.0
        base.append(e.ravel())
    for c in range(3):  # the model's own scale per channel
        e = np.zeros((n, 3))
        e[:, c] = means[:, c]
        base.append(e.ravel())
    vecs = base + [means[:, 3 * i:3 * i + 3].ravel() for i in range(1, means.shape[1] // 3)]
    vecs = [v / nv if (nv := math.sqrt(float(np.einsum("i,i->", v, v)))) > 0 else v for v in vecs]
    size = len(vecs)
    gram = np.empty((size, size))
    for i in range(size):
        for j in range(i, size):
            gram[i, j] = gram[j, i] = float(np.einsum("i,i->", vecs[i], vecs[j]))
    b = np.array([float(np.einsum("i,i->", v, y)) for v in vecs])
    yy = float(np.einsum("i,i->", y, y))

    def left(idx: list[int]) -> float:
        g, bb = gram[np.ix_(idx, idx)], b[idx]
        coef = np.linalg.lstsq(g, bb, rcond=1e-12)[0]
        return max(yy - 2.0 * float(coef @ bb) + float(coef @ g @ coef), 0.0)

    baseline = left(list(range(6)))
    shares: dict[str, float] = {}
    at = 6
    for cause, cols in columns.items():
        idx = list(range(6)) + list(range(at, at + len(cols)))
        at += len(cols)
        if baseline > 0:
            shares[cause] = max(0.0, 1.0 - left(idx) / baseline)
    out: dict[str, Any] = {"causes": shares}
    best = max(shares, key=shares.get) if shares else None
    runner = max((v for c, v in shares.items() if c != best), default=0.0)
    if best is not None and shares[best] >= NAMED_SHARE and shares[best] - runner >= NAMED_MARGIN:
        out["cause"] = best
    else:
        out["cause"] = None
        out["why"] = ("smooth residual that no single named cause explains (a light, room light, a lens or a "
                      "camera curve the scene leaves out, or several)")
    return out


def _cause_columns(d: dict[str, Any], model: np.ndarray, ids: np.ndarray) -> dict[str, list[np.ndarray]]:
    """The candidate causes' columns (H, W, 3) each: the light's moves, the occluded room light, the
    lens's radial falloff and a tone curve's change (a power of the model's values). ``ids``: the object
    index per pixel (H, W)."""
    h, w = model.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    rr = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    m = np.clip(model, 1e-6, 1.0)
    cols: dict[str, list[np.ndarray]] = {}
    light = _light_columns(d)
    if light:
        cols["light"] = light
    albedo = np.ones((h, w, 3))
    for k, o in enumerate(d["objects"]):
        albedo[ids == k] = np.asarray(o["material"]["albedo"], float)
    cols["occlusion"] = [_occlusion_column(d) * albedo]
    cols["vignetting"] = [model * rr[..., None], model * (rr * rr)[..., None]]
    cols["tone_curve"] = [m * np.log(m), m * np.log(m) ** 2]
    return cols
