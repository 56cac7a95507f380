"""The camera between the scene and the file: lens vignetting and a tone curve that is not sRGB.

A camera multiplies the scene's radiance by its vignetting V (the natural cos^4 falloff of the angle off
the optical axis, times a lens's radial falloff 1 + k1 r^2 + k2 r^4, r = 1 at the image corner) and
writes it through its tone curve. Both are fitted with the light, not after it: with the light at x, a
matte scene's pixel of object o in channel c is p_oc S_i(x), S the shading of unit albedo and intensity,
so at each candidate light the products and the camera's parameters come from one small least squares
(:class:`Shading`): for the vignetting V_i p_oc S_i (Gauss-Newton on the products and k together); for
the tone curve g(v_i) = p_oc S_i with g a monotone piecewise-linear function of the file's value v
(non-negative ramp weights, a non-negative least squares on the normal equations). Levenberg-Marquardt
steps search the light on that fit's residual; the photo is then corrected
(divided by V, or mapped through g) and fitted as any other near that light (docs/camera.md).

A term is taken only when the photo shows it: from the light the ordinary fit found, each term and the
products alone take a few such steps; each is then fitted on half of the image's 8 x 8 pixel blocks (a
checkerboard) and judged on the other half (and the other way round); a term is selected when its
held-out L1 residual is at least HELD_OUT_GAIN lower than the products' alone. A photo the ordinary fit
explains to its rounding error is not tested, so its fit stays the ordinary one, bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _native
from .._pixels import SATURATED, edges
from .._srgb import codes8, encode
from ..errors import RtloopError
from ..scene import Scene, load_scene
from ..uncertainty.nuisance import Nuisance, profiled_by
from .bounds import narrowed, restore_bounds

MODES = ("auto", "on", "off")
#: ``tone`` takes these and "linear": the image is declared linear radiance (a RAW, a file read with
#: ``response="linear"``): no curve is fitted and its sRGB encoding is not doubted (:mod:`.terms`).
TONE_MODES = (*MODES, "linear")
#: A term is selected when its held-out residual is at least this fraction below the products' alone.
HELD_OUT_GAIN = 0.4
#: The checkerboard's block side (pixels) for the held-out test.
BLOCK = 8
#: The tone curve's knots in the file's value (sRGB-encoded 0..1): g is linear between them.
KNOTS = np.array([0.0, 0.08, 0.16, 0.25, 0.35, 0.45, 0.55, 0.65, 0.75, 0.85, 0.93, 1.0])
#: Levenberg-Marquardt steps of the joint search: in the test, and when a term is taken.
DETECT_STEPS = 2
SEARCH_STEPS = 30
#: The refit of the corrected photo searches +-REFIT_FRACTION of each range around the joint search's light.
REFIT_FRACTION = 0.003
#: The camera terms are tested on every DETECT_STRIDE-th pixel in each direction, and fitted on every
#: SEARCH_STRIDE-th.
DETECT_STRIDE = 4
SEARCH_STRIDE = 2


@dataclass
class Camera:
    """The checked camera options of a fit."""

    vignetting: str = "auto"
    tone: str = "auto"
    given: np.ndarray | None = None  # a given falloff (flat field or k1, k2), (H, W)
    given_from: dict[str, Any] = field(default_factory=dict)

    @property
    def active(self) -> bool:
        return self.given is not None or self.vignetting != "off" or self.tone not in ("off", "linear")


def off_axis(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel: cos^4 of the angle off the optical axis (a pinhole with the scene's vertical field of
    view) and r, the distance from the image centre over the half-diagonal."""
    d = scene.to_dict()
    w, h = scene.width, scene.height
    f = (h / 2) / math.tan(math.radians(float(d["camera"]["vfov_deg"])) / 2)
    x = np.arange(w) + 0.5 - w / 2
    y = np.arange(h) + 0.5 - h / 2
    rr = np.hypot(*np.meshgrid(x, y))
    return (f / np.hypot(f, rr)) ** 4, rr / math.hypot(w / 2, h / 2)


def falloff(cos4: np.ndarray, r: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """V = cos^4 x (1 + k1 r^2 + k2 r^4)."""
    return cos4 * (1 + k1 * r**2 + k2 * r**4)


def check_camera(scene: Scene, vignetting: Any, tone: Any, flat_field: Any) -> Camera:
    """The camera options checked (an RtloopError naming the argument otherwise)."""
    cam = Camera()
    if isinstance(vignetting, str):
        if vignetting not in MODES:
            raise RtloopError(f"vignetting: must be 'auto', 'on', 'off' or (k1, k2) (got {vignetting!r})")
        cam.vignetting = vignetting
    else:
        try:
            k = [float(v) for v in vignetting]
        except (TypeError, ValueError):
            k = []
        if len(k) != 2 or not all(math.isfinite(v) for v in k):
            raise RtloopError(f"vignetting: must be 'auto', 'on', 'off' or (k1, k2) (got {vignetting!r})")
        cos4, r = off_axis(scene)
        v = falloff(cos4, r, *k)
        if not (np.isfinite(v).all() and (v > 0).all()):
            raise RtloopError(f"vignetting: (k1, k2) = ({k[0]:g}, {k[1]:g}) makes the falloff 0 or negative "
                              "inside the image (1 + k1 r^2 + k2 r^4 must stay positive for r in [0, 1])")
        cam.vignetting, cam.given, cam.given_from = "given", v, {"k1": k[0], "k2": k[1], "source": "given"}
    if not (isinstance(tone, str) and tone in TONE_MODES):
        raise RtloopError(f"tone: must be 'auto', 'on', 'off' or 'linear' (got {tone!r})")
    cam.tone = tone
    if flat_field is not None:
        if cam.given is not None:
            raise RtloopError("flat_field: give either a flat field or vignetting=(k1, k2), not both")
        cam.given, cam.given_from = flat_field_falloff(scene, flat_field), {"source": "flat field"}
        cam.vignetting = "given"
    return cam


def flat_field_falloff(scene: Scene, flat: Any) -> np.ndarray:
    """The falloff a photo of a flat white target shows: its channel mean over its brightest 1 %."""
    f = np.asarray(flat)
    if f.dtype.kind != "f" or f.ndim not in (2, 3):
        raise RtloopError(f"flat_field: must be a float array of linear values (got dtype {f.dtype})")
    if f.ndim == 3 and f.shape[2] == 3:
        f = f.mean(axis=2)
    if f.shape != (scene.height, scene.width):
        raise RtloopError(f"flat_field: shape {np.asarray(flat).shape} does not match the scene's "
                          f"({scene.height}, {scene.width}[, 3])")
    if not np.isfinite(f).all() or not (f > 0).all():
        raise RtloopError("flat_field: every value must be finite and above 0 (a photo of a flat white target)")
    if (f >= SATURATED).mean() > 0.01:
        raise RtloopError(f"flat_field: {(f >= SATURATED).mean():.0%} of its pixels are saturated: expose the "
                          "flat white target darker")
    top = float(np.quantile(f, 0.99))
    return np.minimum(f / top, 1.0)


class Shading:
    """A matte scene's shading S(x) of unit albedo and intensity at the pixels that inform the camera
    terms (one object in the pixel and its 4-neighbours, unsaturated), and the small solves on it."""

    def __init__(self, fitted: Scene, target: np.ndarray, use: np.ndarray | None, environment: bool = False,
                 stride: int = 2):
        d = fitted.to_dict()
        d["fit"] = {"light.position": d["fit"]["light.position"]}
        d["light"].update(intensity=1.0, color=[1.0, 1.0, 1.0])
        d["exposure"] = 1.0
        d.pop("interreflection", None)
        d.pop("environment", None)
        for o in d["objects"]:
            o["material"]["albedo"] = [1.0, 1.0, 1.0]
        self.scene = load_scene(d)
        ids = _native.object_ids(self.scene, self.scene.width, self.scene.height)
        self.env = None
        ok = (ids >= 0) & ~edges(ids) & (target.max(axis=2) < SATURATED)
        keep = np.zeros_like(ok)
        keep[::stride, ::stride] = True
        ok &= keep
        if use is not None:
            keep = np.zeros(ok.size, bool)
            keep[use] = True
            ok &= keep.reshape(ok.shape)
        self.ok = ok
        self.idx = np.flatnonzero(ok).astype(np.uint32)  # the pixels the terms read, rendered alone
        self.t = target[ok].astype(np.float64)  # (n, 3)
        self.group = (ids[ok][:, None] * 3 + np.arange(3)).ravel()  # object x channel per value
        self.groups = len(d["objects"]) * 3
        cos4, r = off_axis(fitted)
        self.c4, self.r2 = np.repeat(cos4[ok], 3), np.repeat(r[ok], 3) ** 2
        self._cache: dict[int, Any] = {}
        self._positive: dict[int, np.ndarray] = {}  # the tone's last positive variables, per pixel selection
        self._k = np.zeros(2)
        cb = ((np.indices(ok.shape) // BLOCK).sum(axis=0) % 2).astype(bool)[ok]
        self.halves = (np.repeat(cb, 3), np.repeat(~cb, 3))
        self.v = encode(np.clip(self.t, 0, 1)).astype(np.float64).ravel()
        lo, hi = KNOTS[:-1], KNOTS[1:]
        self.ramps = np.clip((self.v[:, None] - lo) / (hi - lo), 0.0, 1.0)
        if environment:  # the environment's column: its view factor (the light off, a white environment)
            d.update(environment=[1.0, 1.0, 1.0])
            d["light"]["intensity"] = 0.0
            e = load_scene(d)
            self.env = np.asarray(_native.render_pixels(e, self.idx), np.float64).ravel()

    def shading(self, position: Any) -> np.ndarray:
        s = self.scene.with_params([float(p) for p in position], ["light.position"])
        return np.asarray(_native.render_pixels(s, self.idx, True), np.float64).ravel()

    def _model(self, y: np.ndarray, s: np.ndarray, sel: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
        """The least-squares products (and environment products) per object and channel fitted to ``y``
        on ``sel``: the model's values p S (+ e E) at every pixel, each column times ``scale``."""
        g, cols = self.group[sel], [s] if self.env is None else [s, self.env]
        if scale is not None:
            cols = [c * scale for c in cols]
        ys = y[sel]
        if len(cols) == 1:
            num = np.bincount(g, ys * cols[0][sel], self.groups)
            den = np.bincount(g, cols[0][sel] ** 2, self.groups)
            p = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0).clip(0.0)
            return p[self.group] * cols[0]
        a, b = cols[0][sel], cols[1][sel]
        aa, ab, bb = (np.bincount(g, u * v, self.groups) for u, v in ((a, a), (a, b), (b, b)))
        ay, by = np.bincount(g, a * ys, self.groups), np.bincount(g, b * ys, self.groups)
        det = aa * bb - ab * ab
        good = det > 1e-12 * np.maximum(aa * bb, 1e-300)
        det = np.where(good, det, 1.0)
        p = np.where(good, (bb * ay - ab * by) / det, np.where(aa > 0, ay / np.where(aa > 0, aa, 1.0), 0.0))
        e = np.where(good, (aa * by - ab * ay) / det, 0.0)
        return p[self.group] * cols[0] + e[self.group] * cols[1]

    def base(self, s: np.ndarray, sel: np.ndarray) -> np.ndarray:
        """The products alone: the model's values at every pixel, fitted on ``sel``."""
        return self._model(self.t.ravel(), s, sel)

    def vignetting(self, s: np.ndarray, sel: np.ndarray, rounds: int = 8,
                   falling: bool = False) -> tuple[np.ndarray, tuple[float, float]]:
        """Products x V by Gauss-Newton on the products and (k1, k2) together (the model is bilinear: an
        alternation converges in hundreds of rounds), the products' normal equations eliminated per
        object and channel (Schur complement); with ``falling`` (the reported falloff) k1 > 0 is refitted
        with k1 = 0. The model's values and (k1, k2)."""
        # from the last call's k (the searches' neighbouring lights): a step or two instead of several
        k = self._lens_steps(s, sel, self._k, 2, rounds)
        if falling and k[0] > 0:  # a lens darkens away from its axis: 1 + k1 r^2 + k2 r^4 falls from r = 0
            k = self._lens_steps(s, sel, np.array([0.0, min(k[1], 0.0)]), 1, rounds)
        self._k = k if np.isfinite(k).all() else np.zeros(2)
        v = self.c4 * (1 + k[0] * self.r2 + k[1] * self.r2 * self.r2)
        return self._model(self.t.ravel(), s, sel, v), (float(k[0]), float(k[1]))

    def _lens_steps(self, s: np.ndarray, sel: np.ndarray, k: np.ndarray, free: int, rounds: int) -> np.ndarray:
        """Gauss-Newton steps on (products, k): ``free`` 2 frees k1 and k2, 1 only k2 (k1 held)."""
        y, g, m = self.t.ravel()[sel], self.group[sel], self.groups
        q = self.r2[sel]
        base = [c[sel] * self.c4[sel] for c in ([s] if self.env is None else [s, self.env])]
        powers = [q, q * q][2 - free:]
        n = len(base)
        p = None
        for _ in range(rounds):
            lens = 1 + k[0] * q + k[1] * q * q
            jp = [c * lens for c in base]  # d model / d products
            if p is None:  # the products at k = start, by least squares
                app = np.stack([np.stack([np.bincount(g, a * b, m) for b in jp], -1) for a in jp], -2)
                bp = np.stack([np.bincount(g, a * y, m) for a in jp], -1)
                p = _solve_groups(app, bp)
            unlensed = sum(p[g, i] * base[i] for i in range(n))
            res = y - unlensed * lens
            jk = [unlensed * w for w in powers]
            app = np.stack([np.stack([np.bincount(g, a * b, m) for b in jp], -1) for a in jp], -2)  # (m, n, n)
            apk = np.stack([np.stack([np.bincount(g, a * b, m) for b in jk], -1) for a in jp], -2)  # (m, n, f)
            akk = np.array([[float((a * b).sum()) for b in jk] for a in jk])
            bp = np.stack([np.bincount(g, a * res, m) for a in jp], -1)
            bk = np.array([float((a * res).sum()) for a in jk])
            inv_app_apk = _solve_groups(app, apk)
            inv_app_bp = _solve_groups(app, bp)
            schur = akk - np.einsum("gnf,gne->fe", apk, inv_app_apk)
            rhs = bk - np.einsum("gnf,gn->f", apk, inv_app_bp)
            try:
                dk = np.linalg.solve(schur + 1e-12 * np.trace(schur) * np.eye(free), rhs)
            except np.linalg.LinAlgError:
                break
            p = p + inv_app_bp - np.einsum("gnf,f->gn", inv_app_apk, dk)
            k = k + (dk if free == 2 else np.array([0.0, dk[0]]))
            if np.max(np.abs(dk)) < 1e-7:
                break
        return k

    def tone(self, s: np.ndarray, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """g(v) = p S (+ e E): the ramp weights w >= 0 and the products >= 0 by a non-negative least
        squares on the normal equations, g's mean over the pixels held at the sRGB decoding's (the scale).
        Returns (g(v), the model, w)."""
        key = id(sel)
        if key not in self._cache:
            b = self.ramps[sel]
            self._cache[key] = (sel, np.einsum("ij,ik->jk", b, b), b.mean(axis=0), float(self.t.ravel()[sel].mean()))
        _, m_bb, b_mean, mean_t = self._cache[key]
        k, m = m_bb.shape[0], self.groups
        cols = [np.where(sel, c, 0.0) for c in ([s] if self.env is None else [s, self.env])]
        grouped = [-np.stack([np.bincount(self.group, self.ramps[:, j] * c, m) for j in range(k)]) for c in cols]
        blocks = [[m_bb] + grouped]
        for i, c in enumerate(cols):
            blocks.append([grouped[i].T] + [np.diag(np.bincount(self.group, c * d, m)) for d in cols])
        normal = np.block(blocks)
        n = normal.shape[0]
        normal += 1e-12 * np.trace(normal) / n * np.eye(n)
        u = np.linalg.cholesky(normal).T
        scale = math.sqrt(float(np.trace(normal))) * 10
        row = np.concatenate([b_mean, np.zeros(n - k)]) * scale
        x = nnls(np.vstack([u, row]), np.concatenate([np.zeros(n), [mean_t * scale]]), start=self._positive.get(key))
        self._positive[key] = x > 0
        w = x[:k]
        model = sum(x[k + i * m: k + (i + 1) * m][self.group] * c for i, c in
                    enumerate([s] if self.env is None else [s, self.env]))
        return self.ramps @ w, model, w


def _l1(a: np.ndarray, b: np.ndarray, sel: np.ndarray) -> float:
    return float(np.abs(a[sel] - b[sel]).sum())


def nnls(a: np.ndarray, b: np.ndarray, iterations: int = 0, start: np.ndarray | None = None) -> np.ndarray:
    """min |a x - b| subject to x >= 0 (Lawson and Hanson's active set, for the few tens of unknowns here).
    ``start``: the variables likely positive (a neighbouring problem's), tried first: the search then
    takes a step or two instead of one per variable, and ends at the same solution (the least squares on
    the final positive set, which the optimality test fixes)."""
    n = a.shape[1]
    x, passive = np.zeros(n), np.zeros(n, bool)
    if start is not None:
        passive = start.copy()
        while passive.any():  # the start's positive solution, variables dropped until there is one
            z = np.zeros(n)
            z[passive] = np.linalg.lstsq(a[:, passive], b, rcond=None)[0]
            if (z[passive] > 0).all():
                x = z
                break
            passive &= z > 0
    for _ in range(iterations or 3 * n):
        w = a.T @ (b - a @ x)
        if passive.all() or w[~passive].max() <= 1e-12 * max(1.0, float(np.abs(w).max())):
            break
        passive[np.flatnonzero(~passive)[np.argmax(w[~passive])]] = True
        while True:
            z = np.zeros(n)
            z[passive] = np.linalg.lstsq(a[:, passive], b, rcond=None)[0]
            if (z[passive] > 0).all():
                x = z
                break
            neg = passive & (z <= 0)
            alpha = float(np.min(x[neg] / (x[neg] - z[neg])))
            x = x + alpha * (z - x)
            passive &= x > 1e-15
            x[~passive] = 0.0
    return x


def _solve_groups(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per object and channel: a (m, n, n) x = b (m, n[, f]) for n = 1 or 2, in closed form (LAPACK's call
    costs more than these solves); a group without pixels, or a singular one, gets 0."""
    rhs = b if b.ndim == 3 else b[..., None]
    if a.shape[-1] == 1:
        d = a[:, 0, 0]
        good = d > 0
        out = np.where(good[:, None, None], rhs / np.where(good, d, 1.0)[:, None, None], 0.0)
    else:
        p, q, r, t = a[:, 0, 0], a[:, 0, 1], a[:, 1, 0], a[:, 1, 1]
        det = p * t - q * r
        good = np.abs(det) > 1e-12 * np.maximum(p * t, 1e-300)
        det = np.where(good, det, 1.0)
        x0 = (t[:, None] * rhs[:, 0] - q[:, None] * rhs[:, 1]) / det[:, None]
        x1 = (p[:, None] * rhs[:, 1] - r[:, None] * rhs[:, 0]) / det[:, None]
        out = np.where(good[:, None, None], np.stack([x0, x1], axis=1), 0.0)
    return out if b.ndim == 3 else out[..., 0]


def residual(sh: Shading, term: str, s: np.ndarray, sel: np.ndarray) -> np.ndarray:
    """The joint fit's residual at a shading ``s`` (fitted on ``sel``)."""
    if term == "vignetting":
        return sh.vignetting(s, sel)[0] - sh.t.ravel()
    if term == "tone":
        g, ps, _ = sh.tone(s, sel)
        return ps - g
    return sh.base(s, sel) - sh.t.ravel()


def search(sh: Shading, term: str, start: Any, bounds: list[tuple[float, float]], iterations: int,
           shading: dict[tuple[float, ...], np.ndarray] | None = None,
           slopes: list[np.ndarray] | None = None) -> tuple[np.ndarray, int]:
    """Levenberg-Marquardt over the light's position on the joint fit's squared residual (the camera's
    parameters and the products solved at each light: variable projection; the Jacobian by forward
    differences of 1e-4 of each range), from ``start``, ``iterations`` steps at most. ``shading``: renders
    shared between the terms' searches; ``slopes``: the shading's derivatives along each coordinate at
    ``start``, the first step's differences taken on them and the later steps' Jacobian Broyden-updated
    (the test's cheap steps: a render per trial only). Returns the light and the renders taken."""
    lo, hi = np.array(bounds, float).T
    h = 1e-4 * (hi - lo)
    cache = {} if shading is None else shading
    every = np.ones(sh.t.size, bool)
    renders = 0

    def shade(x: np.ndarray) -> np.ndarray:
        nonlocal renders
        key = tuple(np.round(x, 12))
        if key not in cache:
            cache[key] = sh.shading(x)
            renders += 1
        return cache[key]

    x = np.clip(np.asarray(start, float), lo, hi)
    r = residual(sh, term, shade(x), every)
    loss, lam = float((r * r).sum()), 1e-3
    j = None
    for _ in range(iterations):
        if slopes is not None:
            if j is None:  # later steps: Broyden-updated at the last accepted step (below), no renders
                j = np.stack([(residual(sh, term, shade(x) + h[i] * slopes[i], every) - r) / h[i]
                              for i in range(3)], axis=1)
        else:
            cols = []
            for i in range(3):
                step = x.copy()
                step[i] += h[i] if x[i] + h[i] <= hi[i] else -h[i]
                cols.append((residual(sh, term, shade(step), every) - r) / (step[i] - x[i]))
            j = np.stack(cols, axis=1)
        jtj, jtr = np.einsum("ij,ik->jk", j, j), np.einsum("ij,i->j", j, r)
        moved = False
        for _ in range(6):
            try:
                delta = -np.linalg.solve(jtj + lam * np.diag(np.diag(jtj) + 1e-30), jtr)
            except np.linalg.LinAlgError:
                break
            trial = np.clip(x + delta, lo, hi)
            rt = residual(sh, term, shade(trial), every)
            lt = float((rt * rt).sum())
            if lt < loss:
                if slopes is not None:  # Broyden's update of the Jacobian along the step taken
                    d = trial - x
                    j = j + np.outer(rt - r - np.einsum("ij,j->i", j, d), d) / max(float((d * d).sum()), 1e-300)
                x, r, loss, lam, moved = trial, rt, lt, lam / 10, True
                break
            lam *= 10
        if not moved or np.all(np.abs(delta) < h):
            break
    return x, renders


def evidence(sh: Shading, position: Any, terms: list[str], bounds: list[tuple[float, float]]) -> dict[str, Any]:
    """Each term's light after DETECT_STEPS joint steps from the ordinary fit's; there, the term fitted on
    one half of the blocks and judged on the other (both ways), against the products alone after as many
    steps."""
    shared: dict[tuple[float, ...], np.ndarray] = {}
    lo, hi = np.array(bounds, float).T
    x0 = np.clip(np.asarray(position, float), lo, hi)
    s0 = shared[tuple(np.round(x0, 12))] = sh.shading(x0)
    slopes = []
    for i, h in enumerate(1e-4 * (hi - lo)):
        step = x0.copy()
        step[i] += h if x0[i] + h <= hi[i] else -h
        shared[tuple(np.round(step, 12))] = si = sh.shading(step)
        slopes.append((si - s0) / (step[i] - x0[i]))

    def held_out(term: str) -> tuple[float, np.ndarray]:
        # the same steps for the products alone: a term is not credited with what a better light gives
        # the tone curve's light can be a metre off: one more step, each with differences of its own (a
        # Broyden update of the first step's Jacobian stops short)
        x, _ = search(sh, term, x0, bounds, DETECT_STEPS + (term == "tone"), shared,
                      slopes=None if term == "tone" else slopes)
        s = shared.get(tuple(np.round(x, 12)))
        s = sh.shading(x) if s is None else s
        return sum(float(np.abs(residual(sh, term, s, a))[b].sum()) for a, b in (sh.halves, sh.halves[::-1])), x

    base, _ = held_out("base")
    out = {}
    for t in terms:
        held, x = held_out(t)
        gain = 1.0 - held / base if base > 0 else 0.0
        out[t] = {"held_out_l1": held, "held_out_l1_without": base, "gain": round(gain, 4),
                  "selected": bool(gain >= HELD_OUT_GAIN), "light": [float(v) for v in x],
                  "rule": f"selected when the held-out L1 residual falls by at least {HELD_OUT_GAIN:.0%} "
                          f"(fitted on half of the {BLOCK} x {BLOCK} px blocks, judged on the other half)"}
    return out


def corrected(target: np.ndarray, term: str, fitted: Any, scene: Scene) -> tuple[np.ndarray, dict[str, Any]]:
    """The photo with the camera's term undone, and the term's record."""
    if term == "vignetting":
        cos4, r = off_axis(scene)
        v = falloff(cos4, r, *fitted)  # 1 on the optical axis: the products are the scene's
        out = np.where(target >= SATURATED, target, target / v[..., None])
        return out.astype(np.float32), {"k1": fitted[0], "k2": fitted[1], "corner": float(v.min())}
    w = np.asarray(fitted)
    lo, hi = KNOTS[:-1], KNOTS[1:]
    top = float(w.sum())
    if top <= 0:
        raise RtloopError("tone: the fitted curve is flat")
    v = encode(np.clip(target, 0, 1)).astype(np.float64)
    g = np.clip((v[..., None] - lo) / (hi - lo), 0, 1) @ (w / top)
    curve = np.cumsum(np.concatenate([[0.0], w / top]))
    return g.astype(np.float32), {"knots": KNOTS.round(3).tolist(), "linear_at_knots": curve.round(5).tolist()}


def tone_nuisance(target: np.ndarray, w: Any) -> Nuisance:
    """The fitted tone curve's parameters as nuisance parameters of the corrected photo's fit: the curve
    g(v) = sum_j w'_j ramp_j(v), w' = w / sum(w) (g(1) = 1, the gauge :func:`corrected` fixes: the curve and
    the colours share one scale), so the corrected photo moves along ramp_j - ramp_ref per free weight
    (``ref`` the largest). Weights the non-negative fit left at 0 are on their bound and held, as that
    fit's active set holds them. ``target``: the photo as the file gave it (linear, (H, W, 3))."""
    wn = np.asarray(w, float) / float(np.sum(w))
    free = np.flatnonzero(wn > 0)
    ref = int(free[np.argmax(wn[free])])
    others = free[free != ref]
    v = encode(np.clip(np.asarray(target), 0, 1)).reshape(-1, 3)
    lo, hi = KNOTS[:-1], KNOTS[1:]

    def columns(idx: np.ndarray) -> np.ndarray:
        vv = v[idx].astype(np.float64).ravel()[:, None]
        ramps = np.clip((vv - lo[np.r_[others, ref]]) / (hi - lo)[np.r_[others, ref]], 0.0, 1.0)
        return ramps[:, :-1] - ramps[:, -1:]

    return Nuisance("the fitted tone curve's weights between its knots", tuple(
        f"camera.tone.w{j}" for j in others), columns)


def applicable(fitted: Scene) -> str | None:
    """Why the camera terms are not tested on this fit (None: they are): a matte scene, one point light
    whose position the fit frees, no ambient light."""
    d = fitted.to_dict()
    if "light.position" not in fitted.fit_paths or d["light"].get("type", "point") != "point":
        return "the camera terms are tested for a free point light's position only"
    if any(o["material"].get("specular", 0.0) > 0 for o in d["objects"]):
        return "the camera terms are tested on matte scenes only"
    if any(float(a) > 0 for a in d.get("ambient", [0, 0, 0])):
        return "the camera terms are tested without ambient light only"
    return None


def fit_through_camera(fit_once: Callable[..., Any], scene: Scene, image: np.ndarray, use: np.ndarray | None,
                       cam: Camera) -> Any:
    """``fit_once(image)`` (the ordinary fit), and where the photo shows vignetting or a tone curve (or
    the user gives a falloff) the fit of the photo with the camera undone (``result.model["camera"]``)."""
    target = np.ascontiguousarray(image, dtype=np.float32)
    if cam.given is not None:
        out = np.where(target >= SATURATED, target, target / cam.given[..., None]).astype(np.float32)
        result = fit_once(out)
        result.model["camera"] = {"terms": ["vignetting"], "vignetting": cam.given_from}
        return result
    first = fit_once(target)
    why = applicable(first.scene) if first.settings.get("method") == "projected" else \
        "the two-stage method selects no term (as it selects no image term)"
    if why is None and "skipped" in first.model and "on" not in (cam.vignetting, cam.tone):
        why = "the fit explains the photo to its rounding error (model.residual): nothing more is tested"
    if why is not None:
        first.model["camera"] = {"terms": [], "not_tested": why}
        return first
    terms = [t for t, mode in (("vignetting", cam.vignetting), ("tone", cam.tone)) if mode not in ("off", "linear")]
    if "tone" in terms and cam.tone == "auto" and codes8(target) is None:
        terms.remove("tone")  # linear data (RAW, 16-bit, float) stays linear
    env = "environment" in first.model.get("terms", []) or "environment" in first.scene.to_dict()
    sh = Shading(first.scene, target, use, environment=env, stride=DETECT_STRIDE)
    if not terms or sh.t.shape[0] < 4 * BLOCK * BLOCK:
        first.model["camera"] = {"terms": []}
        return first
    position = first.scene.get_params(["light.position"])
    bounds = first.scene.bounds(["light.position"])
    try:
        ev = evidence(sh, position, terms, bounds)
    except (np.linalg.LinAlgError, ValueError) as e:  # a degenerate photo (no shading to speak of)
        first.model["camera"] = {"terms": [], "not_tested": f"the camera terms' solve failed: {e}"}
        return first
    chosen = [t for t in terms if ev[t]["selected"] or dict(vignetting=cam.vignetting, tone=cam.tone)[t] == "on"]
    record: dict[str, Any] = {"terms": [], "evidence": ev}
    if not chosen:
        first.model["camera"] = record
        return first
    term = max(chosen, key=lambda t: ev[t]["gain"])  # one camera term per photo
    sh = Shading(first.scene, target, use, environment=env, stride=SEARCH_STRIDE)
    light, renders = search(sh, term, ev[term]["light"], bounds, SEARCH_STEPS)
    every = np.ones(sh.t.size, bool)
    s = sh.shading(light)
    fitted = sh.vignetting(s, every, falling=True)[1] if term == "vignetting" else sh.tone(s, every)[2]
    out, params = corrected(target, term, fitted, first.scene)
    # The photo with the camera undone, fitted in a box of +-REFIT_FRACTION of each range around the joint
    # search's light (the ordinary search would trade the light against what the correction left).
    near = narrowed(scene.with_params([float(v) for v in light], ["light.position"]), ["light.position"],
                    REFIT_FRACTION)
    # A tone curve's own uncertainty is carried into the bars: its parameters are profiled out of them
    # (rtloop.uncertainty.nuisance; vignetting's two are left to the corrected photo's bars).
    with profiled_by(tone_nuisance(target, fitted) if term == "tone" else None):
        result = fit_once(out, near)
    result.scene = restore_bounds(result.scene, scene)
    record.update(terms=[term], **{term: params}, search={"light": [float(v) for v in light],
                                                           "renders": renders})
    result.model["camera"] = record
    if term == "tone":  # the curve shares one scale with the colours: their level is not determined
        from ..uncertainty.bars import tone_curve_products

        tone_curve_products((result.uncertainty or {}).get("bars"))
    return result
