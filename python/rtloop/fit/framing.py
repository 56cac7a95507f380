"""Whether the photo is framed as the scene's camera frames it: the objects' outlines in the photo against
the fitted scene's render, registered by a small camera correction (roll, zoom and shift of the image about
its centre). A photo cropped, rotated or resized, or a scene whose field of view or pose is off, puts the
balls' outlines where the scene does not; the fit then moves the light to explain the shading around them
(tests/fixtures/photos/direct-side turned 2 deg and cropped to 120x90: 40 cm), and the residual alone says
only "not explained".

The registration is Lucas-Kanade's (Gauss-Newton on the photo's gradient; B. D. Lucas and T. Kanade, IJCAI
1981) of a similarity warp, over the pixels within BAND of an outline (the scene's object boundaries:
geometry, whatever the light), with a gain and offset of the photo's brightness per object (the fitted
shading may be off, not the outlines), Huber weights, then Tukey's (a highlight or a shadow the model
places elsewhere does not pull the outlines). The template is the render the fit compared with the photo.
Its standard error is a sandwich over blocks of pixels (the blur correlates neighbours). A mismatch: the
outlines moved across themselves by MISMATCH_PX or more, by two standard errors. With ``framing="correct"`` the fit resamples
the photo into the scene's framing by that warp and fits again (:func:`fit_reframed`). docs/methods.md,
"The photo's framing"."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _native
from .._opencv import cv2
from .._pixels import edges
from .._srgb import encode
from ..errors import RtloopError
from ..scene import Scene
from .._stats import median

__all__ = ["CHECK_ABOVE", "FRAMING_MODES", "MISMATCH_PX", "check_framing", "fit_reframed", "framing_check",
           "measure", "mismatch_verdict", "reframe", "register_outlines"]

#: The ``framing`` argument's values: "check" (default: measure and say), "correct" (fit a camera
#: correction: the photo resampled into the scene's framing, fitted again), "off".
FRAMING_MODES = ("check", "correct", "off")
#: Outlines displaced across themselves by this much (RMS over their pixels, in the fit's pixels; a motion
#: along an outline, such as a ball turning about its centre, does not move it), less two standard errors,
#: are a mismatch. On the correctly framed test photos (docs/methods.md: the Mitsuba photos with gloss,
#: environment, bounce, lamps and JPEG; the one-photo views with their textured floor; the reference scenes;
#: the pinned synthetic fits, converged or not) that is at most 0.2 px, and 0.46 px where a term the photo
#: needs was switched off; a 2 deg roll of two balls 0.53 px, a 120x90 crop 1.1-1.5 px, a 2 px shift 1.3 px.
MISMATCH_PX = 0.5
#: "check" registers only where the residual is at least this many times the noise floor: outlines off by
#: MISMATCH_PX leave a residual along them that no light explains (2.7-96x on the test photos).
CHECK_ABOVE = 2.0
#: The registration's pixels: within this many pixels (Chebyshev) of an outline.
BAND = 3
#: The photo and the template are blurred by this Gaussian (pixels) before registering: a wider basin.
BLUR_PX = 1.0
#: Huber's threshold (sRGB-encoded luminance, 0-1) for at most HUBER_STEPS steps; then Tukey's biweight
#: at TUKEY_C robust standard deviations of the residual (1.4826 x its median absolute value).
HUBER = 0.02
HUBER_STEPS = 10
TUKEY_C = 4.685
#: At most this many Gauss-Newton steps; each phase (Huber, Tukey) ends once a step moves nothing (roll and
#: zoom at the band's radius, shifts) by SETTLED_PX or more.
STEPS = 40
SETTLED_PX = 1e-3
#: The standard error's blocks: BLOCK x BLOCK pixels (the blur's correlation length is about 3 px).
BLOCK = 4
#: The outlines' normals: the gradient of each object's indicator blurred by this Gaussian (pixels), which
#: reaches the band's pixels.
NORMAL_BLUR_PX = 2.0
#: Fewer outline pixels than this: nothing to register.
MIN_OUTLINE_PIXELS = 12
#: The roll and zoom, where the outlines do not fix them (one ball: a roll about the image's centre moves
#: it as a shift does), are held near 0 by this fraction of the mean curvature of the least squares.
RIDGE = 1e-2
_LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)


def check_framing(framing: Any) -> str:
    """``framing`` as one of :data:`FRAMING_MODES`, else an RtloopError naming the argument."""
    if isinstance(framing, str) and framing in FRAMING_MODES:
        return framing
    raise RtloopError(f"framing: must be 'check', 'correct' or 'off' (got {framing!r})")


def _grey(image: np.ndarray) -> np.ndarray:
    """sRGB-encoded luminance of a linear image clipped to [0, 1], float32: the edges of dark and bright
    objects alike."""
    x = np.clip(np.asarray(image, np.float32), 0, 1)
    return np.ascontiguousarray(encode(x, np.float32) @ _LUMA, dtype=np.float32)


def _centre(h: int, w: int) -> tuple[float, float]:
    return (w - 1) / 2.0, (h - 1) / 2.0


def _warp_coords(p: np.ndarray, x: np.ndarray, y: np.ndarray, c: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Where the similarity ``p`` = (roll rad, log zoom, shift x, shift y) about the centre ``c`` takes the
    template's pixel coordinates (x, y) in the photo."""
    roll, logzoom, tx, ty = (float(v) for v in p)
    s, co, si = math.exp(logzoom), math.cos(roll), math.sin(roll)
    dx, dy = x - c[0], y - c[1]
    return c[0] + s * (co * dx - si * dy) + tx, c[1] + s * (si * dx + co * dy) + ty


def _sample(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    mu = np.ascontiguousarray(u, np.float32).reshape(-1, 1)
    mv = np.ascontiguousarray(v, np.float32).reshape(-1, 1)
    return cv2.remap(image, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel().astype(np.float64)


def register_outlines(template: np.ndarray, photo: np.ndarray, band: np.ndarray, labels: np.ndarray,
                      start: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """The similarity ``p`` (roll rad, log zoom, shift x px, shift y px; about the image's centre) that takes
    ``template``'s pixels to the same content in ``photo`` (both grey float32 (H, W)) over the pixels
    ``band`` (bool (H, W)), with a gain and offset of the photo per object (``labels``, int (H, W): which
    object the template shows), and its covariance (4 x 4); None when it does not converge to finite
    values. ``start``: the parameters to start from (default 0)."""
    h, w = template.shape
    t_img = cv2.GaussianBlur(template, (0, 0), BLUR_PX)
    p_img = cv2.GaussianBlur(photo, (0, 0), BLUR_PX)
    gx = cv2.Sobel(p_img, cv2.CV_32F, 1, 0, ksize=3) / np.float32(8)
    gy = cv2.Sobel(p_img, cv2.CV_32F, 0, 1, ksize=3) / np.float32(8)
    ys, xs = np.nonzero(band)
    x, y = xs.astype(np.float64), ys.astype(np.float64)
    c = _centre(h, w)
    t = t_img[ys, xs].astype(np.float64)
    _, group = np.unique(labels[ys, xs], return_inverse=True)
    k = int(group.max()) + 1
    onehot = np.zeros((len(ys), k))
    onehot[np.arange(len(ys)), group] = 1.0
    # The roll and zoom in pixels at the band's RMS distance from the centre, so that one ridge fits all.
    radius = max(float(np.sqrt(np.mean((x - c[0]) ** 2 + (y - c[1]) ** 2))), 1.0)
    scale = np.array([radius, radius, 1.0, 1.0])
    p = np.zeros(4) if start is None else np.asarray(start, np.float64).copy()
    gain, offset = np.ones(k), np.zeros(k)
    tukey, settled = None, False
    for step_no in range(STEPS):
        u, v = _warp_coords(p, x, y, c)
        iv, ix, iy = _sample(p_img, u, v), _sample(gx, u, v), _sample(gy, u, v)
        du, dv = u - c[0] - p[2], v - c[1] - p[3]
        g = gain[group]
        # d(u, v)/d(roll) = (-dv, du), d(u, v)/d(log zoom) = (du, dv), d/d(shift) = identity
        geo = np.stack([g * (iy * du - ix * dv), g * (ix * du + iy * dv), g * ix, g * iy], axis=1) / scale
        jac = np.concatenate([geo, onehot * iv[:, None], onehot], axis=1)
        r = g * iv + offset[group] - t
        a = np.abs(r)
        if tukey is None and (step_no >= HUBER_STEPS or settled):
            tukey = max(TUKEY_C * 1.4826 * float(median(a)), 1e-4)
            settled = False
        if tukey is None:
            wts = np.where(a <= HUBER, 1.0, HUBER / np.maximum(a, 1e-12))
        else:
            wts = np.where(a < tukey, (1 - (a / tukey) ** 2) ** 2, 0.0)
        normal = jac.T @ (jac * wts[:, None])
        normal[:2, :2] += np.eye(2) * RIDGE * float(np.trace(normal[:4, :4])) / 4.0
        normal[4:, 4:] += np.eye(2 * k) * 1e-9 * (1.0 + float(np.trace(normal[4:, 4:])))
        try:
            step = -np.linalg.solve(normal, jac.T @ (wts * r))
        except np.linalg.LinAlgError:
            return None
        if not np.isfinite(step).all():
            return None
        p += step[:4] / scale
        gain += step[4:4 + k]
        offset += step[4 + k:]
        settled = float(np.abs(step[:4]).max()) < SETTLED_PX
        if settled and tukey is not None:
            break
    if not np.isfinite(p).all():
        return None
    # The covariance: a sandwich of the last step's terms summed over blocks of BLOCK x BLOCK pixels.
    blocks = (ys // BLOCK) * ((w + BLOCK - 1) // BLOCK) + xs // BLOCK
    _, bi = np.unique(blocks, return_inverse=True)
    sums = np.zeros((int(bi.max()) + 1, jac.shape[1]))
    np.add.at(sums, bi, jac * (wts * r)[:, None])
    try:
        inv = np.linalg.inv(normal)
    except np.linalg.LinAlgError:
        return None
    cov = (inv @ (sums.T @ sums) @ inv)[:4, :4] / np.outer(scale, scale)
    return (p, cov) if np.isfinite(cov).all() else None


def outline_normals(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the unit normal of the nearest outline (float32 (H, W) x and y; 0 far from any): the
    gradient of a pixel's own object's indicator, blurred by NORMAL_BLUR_PX."""
    nx = np.zeros(ids.shape, np.float32)
    ny = np.zeros(ids.shape, np.float32)
    for k in np.unique(ids):
        own = ids == k
        soft = cv2.GaussianBlur(own.astype(np.float32), (0, 0), NORMAL_BLUR_PX)
        nx[own] = cv2.Sobel(soft, cv2.CV_32F, 1, 0, ksize=3)[own]
        ny[own] = cv2.Sobel(soft, cv2.CV_32F, 0, 1, ksize=3)[own]
    norm = np.hypot(nx, ny)
    ok = norm > 1e-6
    nx[ok] /= norm[ok]
    ny[ok] /= norm[ok]
    nx[~ok] = 0
    ny[~ok] = 0
    return nx, ny


def _outline_stats(p: np.ndarray, cov: np.ndarray, outline: np.ndarray,
                   normals: tuple[np.ndarray, np.ndarray]) -> tuple[float, float, float]:
    """The outlines' displacement across themselves by the warp ``p`` (along their normals: a motion
    along an outline does not move it): RMS and largest over the pixels ``outline`` (exact), and the
    RMS's standard error from ``cov`` (linearised: sqrt(trace(M cov)), M the mean of the displacement's
    Jacobian squared)."""
    ys, xs = np.nonzero(outline)
    c = _centre(*outline.shape)
    x, y = xs.astype(np.float64), ys.astype(np.float64)
    nx, ny = normals[0][ys, xs].astype(np.float64), normals[1][ys, xs].astype(np.float64)
    u, v = _warp_coords(p, x, y, c)
    d = np.abs((u - x) * nx + (v - y) * ny)
    dx, dy = x - c[0], y - c[1]
    # the displacement's Jacobian at p = 0 across the outline: n . (-dy, dx), n . (dx, dy), nx, ny
    jac = np.stack([-dy * nx + dx * ny, dx * nx + dy * ny, nx, ny], 1)
    m = jac.T @ jac / len(x)
    return float(np.sqrt(np.mean(d * d))), float(d.max()), float(np.sqrt(max(float(np.trace(m @ cov)), 0.0)))


def _used(use: np.ndarray | None, h: int, w: int) -> np.ndarray:
    if use is None:
        return np.ones((h, w), bool)
    m = np.zeros(h * w, bool)
    m[np.asarray(use, np.int64)] = True
    return m.reshape(h, w)


def measure(scene: Scene, target: np.ndarray, use: np.ndarray | None, render: np.ndarray,
            start: np.ndarray | None = None) -> tuple[dict[str, Any], np.ndarray | None]:
    """The registration of ``target`` (linear (H, W, 3)) against ``render`` (the fitted ``scene``'s, as the
    fit compared it) over the used pixels (``use``: flat indices, None for all): the report's numbers and the
    warp's parameters (None where nothing could be registered)."""
    h, w = scene.height, scene.width
    used = _used(use, h, w)
    ids = np.asarray(_native.object_ids(scene, w, h))
    rim = edges(ids)
    outline = rim & used
    n = int(outline.sum())
    out: dict[str, Any] = {"checked": False, "mismatch": False, "outline_pixels": n, "flag_above_px": MISMATCH_PX}
    if n < MIN_OUTLINE_PIXELS:
        out["why"] = f"fewer than {MIN_OUTLINE_PIXELS} outline pixels in the used pixels: nothing to register"
        return out, None
    near = cv2.dilate(rim.astype(np.uint8), np.ones((2 * BAND + 1, 2 * BAND + 1), np.uint8)) > 0
    normals = outline_normals(ids)
    fitted = register_outlines(_grey(render), _grey(target), near & used, ids, start)
    if fitted is None:
        out["why"] = "the registration did not converge"
        return out, None
    p, cov = fitted
    rms, largest, se = _outline_stats(p, cov, outline, normals)
    out.update(checked=True, mismatch=bool(rms - 2.0 * se >= MISMATCH_PX), outline_rms_px=round(rms, 3),
               outline_rms_se_px=round(se, 3), outline_max_px=round(largest, 3),
               roll_deg=round(math.degrees(float(p[0])), 3), zoom_percent=round(100.0 * math.expm1(float(p[1])), 3),
               shift_px=[round(float(p[2]), 3), round(float(p[3]), 3)], centre_px=list(_centre(h, w)))
    return out, p


def framing_check(scene: Scene, target: np.ndarray, use: np.ndarray | None, ratio: float | None, mode: str,
                  render: np.ndarray) -> dict[str, Any]:
    """``goodness["framing"]``: whether the photo's framing matches the scene's camera (:func:`measure`,
    ``render`` the fitted scene's render the fit compared), registered where the residual is at least
    CHECK_ABOVE times the noise floor; ``mode`` "off": not checked."""
    if mode == "off":
        return {"checked": False, "mismatch": False, "why": "framing='off'"}
    if ratio is None or not ratio >= CHECK_ABOVE:
        return {"checked": False, "mismatch": False,
                "why": f"the residual is within {CHECK_ABOVE:g}x the noise floor: outlines in place"}
    out, _ = measure(scene, target, use, render)
    return out


def mismatch_verdict(framing: dict[str, Any]) -> str:
    """The verdict of a fit whose photo is framed otherwise than the scene's camera."""
    sx, sy = framing["shift_px"]
    return (f"the photo's framing does not match the scene's camera: the objects' outlines lie "
            f"{framing['outline_rms_px']:.1f} px (RMS) from where the scene puts them (the photo turned "
            f"{framing['roll_deg']:+.1f} deg, zoomed {framing['zoom_percent']:+.1f} %, shifted ({sx:+.1f}, {sy:+.1f}) "
            "px): was it cropped, rotated or resized, or are the scene's camera (field of view, pose) or objects "
            "off? The fitted light is not to be trusted; framing='correct' (rtloop-fit --framing correct) "
            "resamples the photo into the scene's framing and fits again")


#: "correct" registers and refits up to this many times (each registration starts from the one before),
#: until a registration moves the outlines by less than CORRECT_SETTLED_PX from the one before. With one ball
#: the roll shows only in the shading around it, which the light also moves: several rounds.
CORRECT_ROUNDS = 6
CORRECT_SETTLED_PX = 0.05


def reframe(image: np.ndarray, p: np.ndarray, mask: np.ndarray | None,
            extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``image`` (H, W, 3) resampled into the scene's framing by the warp ``p`` (bilinear), the mask of
    the pixels that fall inside the photo (and inside ``mask``, resampled nearest) and ``extra`` (a bool
    (H, W) image such as a grey card's, resampled nearest)."""
    h, w = image.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w]
    u, v = _warp_coords(p, xs.astype(np.float64), ys.astype(np.float64), _centre(h, w))
    mu, mv = u.astype(np.float32), v.astype(np.float32)
    out = cv2.remap(np.ascontiguousarray(image, np.float32), mu, mv, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
    if mask is not None:
        inside &= cv2.remap(np.asarray(mask, np.uint8), mu, mv, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT) > 0
    moved = None if extra is None else cv2.remap(np.asarray(extra, np.uint8), mu, mv, cv2.INTER_NEAREST,
                                                 borderMode=cv2.BORDER_CONSTANT) > 0
    return np.ascontiguousarray(out, np.float32), inside, moved


def _between(p: np.ndarray, q: np.ndarray, outline: np.ndarray) -> float:
    """The RMS distance between where the warps ``p`` and ``q`` take the pixels ``outline``."""
    ys, xs = np.nonzero(outline)
    c = _centre(*outline.shape)
    a, b = _warp_coords(p, xs.astype(np.float64), ys.astype(np.float64), c)
    e, f = _warp_coords(q, xs.astype(np.float64), ys.astype(np.float64), c)
    return float(np.sqrt(np.mean((a - e) ** 2 + (b - f) ** 2)))


def _compared(result: Any) -> np.ndarray:
    """The render a fit compared with the photo (with the pixel footprint where it took it)."""
    s = result.scene
    settings = result.settings
    return _native.render(s, s.width, s.height, 1, settings.get("footprint", "off") != "off",
                          outlines=bool(settings.get("silhouettes", False)))


def fit_reframed(fit: Callable[..., Any], scene: Any, image: np.ndarray, mask: Any, reference: Any,
                 options: dict[str, Any]) -> Any:
    """``fit(..., framing="correct")``: the fit as given; where its outlines are off (:func:`measure`), the
    photo resampled into the scene's framing by the registered correction and fitted again, CORRECT_ROUNDS
    times, each registration against the photo as given starting from the last. ``goodness["framing"]``
    holds the check after, ``as_given`` the check before and the ``correction`` applied;
    ``result.reframed`` the photo and mask fitted."""
    quick = {**options, "uncertainty": False}
    first = fit(scene, image, mask=mask, reference=reference, framing="off", **quick)
    target = np.ascontiguousarray(image, np.float32)
    use = None if mask is None else np.flatnonzero(np.asarray(mask).astype(bool).ravel())
    check, p = measure(first.scene, target, use, _compared(first))
    if p is None or not check["mismatch"]:
        result = first if options.get("uncertainty", True) in (False, "off") else \
            fit(scene, image, mask=mask, reference=reference, framing="off", **options)
        result.goodness["framing"] = {**check, "corrected": False}
        return result
    card = None if reference is None else np.asarray(reference[0], bool)
    outline = edges(np.asarray(_native.object_ids(first.scene, first.scene.width, first.scene.height)))
    rounds = 1
    for rounds in range(1, CORRECT_ROUNDS):
        moved, inside, card_moved = reframe(target, p, mask, card)
        mid = fit(scene, moved, mask=inside, reference=None if reference is None else (card_moved, reference[1]),
                  framing="off", **quick)
        _, again = measure(mid.scene, target, use, _compared(mid), start=p)
        if again is None:
            break
        moved_by = _between(p, again, outline)
        p = again
        if moved_by < CORRECT_SETTLED_PX:
            break
    moved, inside, card_moved = reframe(target, p, mask, card)
    result = fit(scene, moved, mask=inside, reference=None if reference is None else (card_moved, reference[1]),
                 framing="off", **options)
    after, _ = measure(result.scene, moved, np.flatnonzero(inside.ravel()), _compared(result))
    result.goodness["framing"] = {
        **after, "corrected": True, "as_given": check,
        "correction": {"roll_deg": round(math.degrees(float(p[0])), 3),
                       "zoom_percent": round(100.0 * math.expm1(float(p[1])), 3),
                       "shift_px": [round(float(p[2]), 3), round(float(p[3]), 3)],
                       "pixels_left_out": int((~inside).sum()), "rounds": rounds},
    }
    result.reframed = (moved, inside)
    return result
