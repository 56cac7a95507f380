"""How sure are we: per-parameter uncertainty of a fit from the Gauss-Newton approximation at the optimum.

    result = rtloop.fit(scene, photo, seed=1)
    u = estimate_uncertainty(result, photo)
    u["sigma"]["light.position.x"]      # one standard deviation, metres
    u["sigma"]["products.ball.r"]       # exposure x intensity x colour x albedo of the ball, red
    u["sigma"]["products.ball.specular"]  # intensity x specular of a glossy ball
    u["sigma"]["objects.ball.shininess"]  # its Blinn-Phong exponent, when free
    u["sigma"]["light.direction.u"]     # a directional light: radians (see "Directional light")

Residuals are r(θ) = min(render(θ), 1) - image over every used pixel and channel. Near the optimum
r(θ) ≈ r(θ̂) + J (θ - θ̂), and if the image is the model plus independent noise of one variance σ², the
least-squares estimate has covariance σ² (JᵀJ)⁻¹; σ² is estimated from the residuals as
s² = |r|² / (N - P) (P the rank of J). J is taken by central finite differences of rtloop's own renderer,
with steps of 1e-3 of each parameter's scale (its bound range; 1 rad for a direction angle): the renderer
works in float32, and smaller steps let its rounding through (the intensity-albedo degeneracy then no
longer looks singular). The image is linear in an albedo (a product), so an albedo's column is its exact
derivative instead, exposure x (ambient + light x the unit-light render) on the object's pixels: no
render, and none of the float32 rounding of a difference. It is linear in a specular (the specular
product) too: its column is the lobe alone, one render of the scene with every albedo 0 and the glossy
objects' specular 1 for all of them. Finite differences agree with both to a few 1e-5 of the column and
a few 1e-6 in sigma, about their own rounding (``EXACT_ALBEDO = False`` renders them). The shininess, the
light's position and its direction have no such form: finite differences.

Which parameters. A scene without ambient light fixes only exposure x intensity x colour x albedo per
object and channel (``result.identifiability["degenerate"]``) and, for a glossy object whose specular is
free, Q = intensity x specular (the highlight's strength): the render is P_c a + exposure x colour_c x
Q b, a the unit-light diffuse factor and b the unit-light lobe, as in the fit's closed-form solve. So
when every object's albedo is free, those *products* are the parameters, ``products.NAME.r|g|b`` and
``products.NAME.specular``, with the light position or direction and any other free parameter (a free
shininess keeps its name, ``objects.NAME.shininess``). They are varied in a scene whose light has
intensity 1, exposure 1 and the fitted exposure x colour as its colour, with albedo P_c / (exposure x
colour_c) and specular Q. Otherwise, and where a highlight of known strength (a fixed non-zero specular)
measures the light or a free light colour is seen in a fitted highlight, the scene's own fit parameters
are used (``params="scene"`` forces this, ``params="products"`` insists on products).

Directional light. Its direction is a unit vector d (searched as three components, normalised); sigma is
given for two angles about the fitted d, in radians: d turned by the angle |(a, b)| towards a u + b v,
where u = up x d normalised is horizontal (up: the camera's; where d lies along it, another horizontal
axis) and v = d x u points towards up. Their names are ``light.direction.u`` and ``light.direction.v``,
their values 0; they have no bounds. ``light_direction`` in the result gives the frame (``direction``,
``u``, ``v``, world coordinates) and two cone figures in degrees: ``angle_deg``, the square root of the
larger eigenvalue of the angles' 2 x 2 covariance (one sigma along the worse axis), and ``rms_angle_deg``
= sqrt(sigma_u² + sigma_v²), the rms angle between the fitted and the true direction (None where an angle
is not determined).

Which pixels. A channel saturated in the objective (>= 0.999) says only "at least 1": it is left out,
but the pixel's other channels are used, as the fit's closed-form solve uses them (a highlight that
saturates red still shows in green and blue, and those channels measure the specular product and the
shininess: leaving out whole pixels overstated their sigma 2.4 and 1.6 times against the actual spread
of the glossy ball in tests/test_uncertainty.py). Pixels on a
silhouette (a 4-neighbour shows another object) and on a shadow edge (a 4-neighbour differs in whether the
light reaches it) change discontinuously with the parameters, which one sample per pixel cannot represent
as a derivative. Both are left out, as is a pixel saturated in every channel, and with ``clip`` a pixel
whose render crosses 1 within a finite-difference step in a channel that is not saturated (the clip's
kink); everything else, background included, is used. ``excluded`` counts these pixels, and in
``saturated_channels`` the saturated channels left out of pixels otherwise used.

Not determined. The Jacobian's columns are scaled to unit norm and decomposed (singular values and
vectors: from the eigen-decomposition of the scaled JᵀJ when every singular value is above GRAM_RCOND of
the largest, else by QR and SVD of J itself). A parameter that no used pixel responds to (the albedo of
an object no pixel shows, or one the light never reaches) or that enters a numerically zero singular
direction (intensity against albedo when the scene's own parameters are used in a degenerate scene) gets
``None`` as sigma and a warning; the covariance of the rest is computed without them.

What it is not. The fit minimises the L1 loss, not least squares: for Gaussian noise the L1 estimate is
about sqrt(pi/2) ≈ 1.25 times as spread as the least-squares one the formula describes, and the optimiser
adds its own (small) scatter. sigma describes the noise in the photo under the model; it does not cover a
wrong model (a misplaced camera, a wrong shape, an unmodelled light) or a fit short of its optimum: both
show as a ``residual_rms`` above the photo's noise, and s², hence sigma, grows with them.

Cost: one render at the optimum, one for the object index and the unit-light factor, one for the lobes
when a specular is free, and two per parameter other than the albedos and speculars (the light's
position or direction, a shininess), on a handful of used-pixel arrays.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _native
from ._pixels import SATURATED, edges
from .errors import RtloopError
from .fit.products import product_range, products_of, specular_product, specular_range, unit_light
from .scene import Scene, load_scene, scene_to_dict

__all__ = ["estimate_uncertainty"]

#: Default finite-difference step: this fraction of each parameter's scale (its bound range; 1 rad for an angle).
STEP_FRACTION = 1e-3
#: Singular values below this fraction of the largest (unit-norm columns) count as zero.
RCOND = 1e-4
#: A parameter whose component in a null singular vector exceeds this is reported as not determined.
NULL_COMPONENT = 1e-3
#: The decomposition comes from the Gram matrix while every singular value is above this fraction of the
#: largest (its error is then below 1e-9 relative), else from QR and SVD of the Jacobian itself.
GRAM_RCOND = 1e-3
#: The scale of a direction angle (radians): the default step is STEP_FRACTION of it.
ANGLE_SCALE = 1.0
#: Albedo and specular columns from the exact derivative rather than finite differences (False: render
#: them, as a check).
EXACT_ALBEDO = True
#: Rows per block of the tall-skinny QR (see _svd_scaled).
_QR_BLOCK = 512

_LIGHT_SCALE = ("light.intensity", "light.color", "exposure")
_ANGLES = ("light.direction.u", "light.direction.v")


@dataclass
class _Space:
    """The parameters sigma is reported for, and how they map onto a scene that renders them."""

    work: Scene  # the scene whose fit parameters are varied (the products scene, or the fitted one)
    paths: list[str]  # work's fit paths, in the order of its parameter vector
    names: list[str]  # one per parameter
    theta0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    scale: np.ndarray
    albedo: dict[int, tuple[int, int]]  # parameter index -> (object index, channel) of an albedo
    specular: dict[int, int]  # parameter index -> object index of a specular (the image is linear in it)
    factor: np.ndarray  # work's value / the parameter's (1 but for a product under a coloured work light)
    direction: tuple[int, np.ndarray, np.ndarray, np.ndarray] | None  # index of angle u, d, u, v

    def native(self, theta: np.ndarray) -> list[float]:
        """``work``'s parameter vector for ``theta`` (the two angles become a unit direction)."""
        theta = theta * self.factor
        if self.direction is None:
            return [float(v) for v in theta]
        k, d, u, v = self.direction
        return [float(x) for x in (*theta[:k], *_rotate(d, u, v, theta[k], theta[k + 1]), *theta[k + 2 :])]


def estimate_uncertainty(
    result: Any,
    image: np.ndarray,
    *,
    clip: bool = True,
    step: float | dict[str, float] | None = None,
    params: str = "auto",
    mask: np.ndarray | None = None,
) -> dict[str, Any]:
    """Per-parameter standard deviations and correlations of a fit (Gauss-Newton at the optimum).

    ``result``: a :class:`rtloop.FitResult` (or a Scene at the optimum with its ``fit`` section).
    ``image``: the objective the fit saw, linear float (H, W, 3) at the scene's size. ``clip`` compares
    min(render, 1) with it, as the fit does. ``step``: finite-difference step as a fraction of each
    parameter's scale (its bound range, 1 rad for a direction angle; default 1e-3), or
    ``{name: absolute step}`` for some parameters. ``params``: ``"auto"`` (products where the scene
    determines only products, else the scene's fit parameters), ``"products"`` or ``"scene"``.

    Returns a JSON-able dict: ``method`` ("gauss-newton"), ``names``, ``values`` (the parameters at the
    optimum; 0 for the direction angles), ``sigma`` ({name: float or None}), ``correlation`` (rows and
    columns in ``names`` order, None where a parameter is not determined), ``residual_rms``, ``pixels``
    (used), ``excluded`` (saturated / silhouette / shadow-edge / clip-kink pixel counts, and saturated
    channels left out of pixels otherwise used), ``dof``,
    ``condition`` (of the column-scaled Jacobian over the determined parameters), ``parametrization``,
    ``step`` and ``warnings``; for a directional light also ``light_direction`` (see the module docstring).
    """
    scene: Scene = result.scene if hasattr(result, "scene") else load_scene(result)
    ident = getattr(result, "identifiability", None)
    target = np.asarray(image, dtype=np.float64)
    if target.shape != (scene.height, scene.width, 3):
        raise RtloopError(
            f"image: shape {target.shape} does not match the scene's ({scene.height}, {scene.width}, 3)"
        )
    if not np.isfinite(target).all():
        raise RtloopError("image: contains NaN or infinite values")
    if params not in ("auto", "products", "scene"):
        raise RtloopError(f"params: must be 'auto', 'products' or 'scene' (got {params!r})")
    if not scene.fit_paths:
        raise RtloopError("fit: the scene's fit section names no free parameters")

    d = scene_to_dict(scene)
    why_not = _products_blocker(scene, d)
    if params == "products" and why_not:
        raise RtloopError(f"params: products do not describe this scene ({why_not})")
    degenerate = bool(ident["degenerate"]) if ident is not None else why_not is None
    use_products = params == "products" or (params == "auto" and why_not is None and degenerate)
    space, wd = _products_space(scene, d) if use_products else _scene_space(scene, d)
    work, paths, names, theta0 = space.work, space.paths, space.names, space.theta0
    warnings: list[str] = []

    def raw(theta: np.ndarray) -> np.ndarray:
        return _native.render(work.with_params(space.native(theta), paths))

    # Pixels the model can represent as a smooth function of the parameters.
    ids, unit = _native.object_ids(work), unit_light(wd)
    lit = unit > 0
    sat = target.reshape(-1, 3) >= SATURATED  # per channel: the others of the pixel still count
    saturated = sat.all(axis=1).reshape(ids.shape)
    silhouette = edges(ids)
    shadow_edge = edges(np.where(ids >= 0, lit.astype(np.int32), -1)) & ~silhouette
    use = ~(saturated | silhouette | shadow_edge)
    if mask is not None:  # pixels the fit left out (bool (H, W), True = used)
        use &= np.asarray(mask, bool)
    idx = np.flatnonzero(use)  # everything below works on the used pixels only
    n = idx.size
    sat_u = np.take(sat, idx, axis=0)  # saturated channels of used pixels: left out one by one
    free_u = ~sat_u
    raw0_img = raw(theta0)
    raw0 = np.take(raw0_img.reshape(-1, 3), idx, axis=0)
    clipped0 = raw0 >= 1.0

    # Jacobian by central differences (one-sided where a step would cross a bound). With ``clip``, a pixel
    # whose render crosses 1 inside a step in a channel that is not saturated sits on the clip's kink and
    # is left out ("clip_kink"). The image is linear in an albedo and in a specular: their columns are
    # the exact derivatives (the unit-light render, scaled; the lobe alone), with no render per
    # parameter, and a pixel is on the kink where that line crosses 1 inside the step.
    steps = _steps(names, space.scale, step)
    P = len(names)
    kink = np.zeros(n, dtype=bool)
    Jt = np.zeros((P, 3 * n))  # the Jacobian's transpose: one contiguous row per parameter

    def clipped(img: np.ndarray) -> np.ndarray:
        """The used pixels of ``img`` (float32, flat), min(img, 1) with ``clip``, noting kink pixels."""
        g = np.take(img.reshape(-1, 3), idx, axis=0)
        if clip:
            cross = (g >= 1.0) != clipped0
            if cross.any():
                kink[(cross & free_u).any(axis=1)] = True
            g = np.minimum(g, np.float32(1.0))
        return g.ravel()

    f0 = clipped(raw0_img)
    ids_u = np.take(ids.ravel(), idx)
    unit_u = np.take(unit.ravel(), idx).astype(np.float64)
    light_rgb = np.array(wd["light"]["color"], float) * wd["light"]["intensity"]
    lobe_u = None
    if EXACT_ALBEDO and space.specular:
        lobe_u = np.take(_lobes(wd, set(space.specular.values())).reshape(-1, 3), idx, axis=0).astype(np.float64)
    pixels_of: dict[int, tuple[np.ndarray, ...]] = {}
    for k in range(P):
        h = steps[k]
        up_ok, down_ok = theta0[k] + h <= space.hi[k], theta0[k] - h >= space.lo[k]
        tp, tm = theta0.copy(), theta0.copy()
        if up_ok and down_ok or not (up_ok or down_ok):
            tp[k] += h
            tm[k] -= h
            denom = 2 * h
        elif up_ok:
            tp[k] += h
            denom = h
        else:
            tm[k] -= h
            denom = h
        if EXACT_ALBEDO and (k in space.albedo or k in space.specular):
            if k in space.albedo:
                o, c = space.albedo[k]
                chans = slice(c, c + 1)
            else:
                o, chans = space.specular[k], slice(0, 3)
            if o not in pixels_of:  # the object's used pixels, their render and clip state at the optimum
                on = np.flatnonzero(ids_u == o)
                pixels_of[o] = (on, raw0[on].astype(np.float64), clipped0[on], free_u[on])
            on, base, was, free = pixels_of[o]
            base, was, free = base[:, chans], was[:, chans], free[:, chans]  # views
            if k in space.albedo:  # d render / d albedo: exposure x (ambient + light x unit-light factor)
                slope = (wd["exposure"] * (wd["ambient"][c] + light_rgb[c] * unit_u[on]))[:, None]
            else:  # d render / d specular: the lobe alone (albedo 0, specular 1)
                slope = lobe_u[on]
            slope = slope * space.factor[k]  # per unit of the parameter
            moved = [t - theta0[k] for t in (tp[k], tm[k]) if t != theta0[k]]
            if clip:
                for dt in moved:
                    hit = ((base + dt * slope >= 1.0) != was) & free
                    kink[on[hit[:, 0] if hit.shape[1] == 1 else hit.any(axis=1)]] = True
                slope = np.where(was, 0.0, slope)  # clipped at the optimum and on both sides: flat
            if moved:
                Jt[k].reshape(-1, 3)[on, chans] = slope
        else:
            fp = clipped(raw(tp)) if tp[k] != theta0[k] else f0
            fm = clipped(raw(tm)) if tm[k] != theta0[k] else f0
            np.subtract(fp, fm, out=Jt[k], dtype=np.float64)  # float32 values, exact difference in float64
            Jt[k] /= denom
        if theta0[k] <= space.lo[k] or theta0[k] >= space.hi[k]:
            warnings.append(
                f"{names[k]}: at its bound ({theta0[k]:.6g}); the Gauss-Newton sigma assumes an interior optimum"
            )
    r0 = np.subtract(f0, np.take(target.reshape(-1, 3), idx, axis=0).ravel(), dtype=np.float64)
    n_kink = int(kink.sum())
    drop = sat_u | kink[:, None]  # residuals left out
    if drop.any():  # zero rows: the same JᵀJ, QR and |r|² as without them
        rows = drop.ravel()
        Jt[:, rows] = 0.0
        r0[rows] = 0.0
    excluded = {
        "saturated": int(saturated.sum()),
        "saturated_channels": int(sat_u[~kink].sum()),
        "silhouette": int((silhouette & ~saturated).sum()),
        "shadow_edge": int((shadow_edge & ~saturated).sum()),
        "clip_kink": n_kink,
    }
    n_pix = n - n_kink
    n_res = 3 * n_pix - excluded["saturated_channels"]
    rr = float(np.einsum("i,i->", r0, r0))  # not r0 @ r0: a threaded BLAS dot waits on the render's threads

    determined = np.ones(P, dtype=bool)
    gram = Jt @ Jt.T
    col = np.sqrt(np.diag(gram))
    finite = np.isfinite(col)  # a column with a NaN or an infinity has one on the diagonal
    effect = np.where(finite, col * space.scale, 0.0)
    big = effect.max() if P else 0.0
    zero = ~finite | (col == 0) | (effect <= 1e-9 * big)
    if zero.any():
        determined[zero] = False
        warnings.append(
            f"{', '.join(names[k] for k in np.flatnonzero(zero))}: not determined: no pixel used in the fit "
            "changes with it (an object no pixel shows, one the light does not reach, a term the scene does "
            "not use)"
        )

    # Null directions among the rest: columns scaled to unit norm, SVD. A parameter with a component in a
    # numerically zero singular direction is not determined; the others get the pseudo-inverse's
    # covariance, which leaves the undetermined combination free (their sigma is marginal over it, not
    # conditional on holding the undetermined parameters at their fitted values).
    idx_p = np.flatnonzero(determined)
    sigma: dict[str, float | None] = {name: None for name in names}
    corr: list[list[float | None]] = [[None] * P for _ in range(P)]
    condition = None
    rank = 0
    s2 = float("nan")
    cov = None
    if idx_p.size:
        s, vt = _svd_scaled(Jt, idx_p, gram[np.ix_(idx_p, idx_p)], col[idx_p])
        null = s < RCOND * s[0]
        rank = int((~null).sum())
        condition = float(s[0] / s[~null].min())
        if null.any():
            involved = (np.abs(vt[null]) > NULL_COMPONENT).any(axis=0)
            group = [names[i] for i in idx_p[involved]]
            warnings.append(
                f"{', '.join(group)}: not determined: the image fixes only a combination of them "
                f"(singular value {s[null].min() / s[0]:.1e} of the largest)"
            )
            determined[idx_p[involved]] = False
        if n_res - rank <= 0:
            warnings.append(f"only {n_res} residuals for {rank} parameters: no uncertainty can be estimated")
            determined[:] = False
        else:
            s2 = rr / (n_res - rank)
            # (JsᵀJs)⁺ = V S⁻² Vᵀ over the non-zero singular values: no explicit normal-equation inverse.
            v = vt[~null]
            cov_scaled = (v.T / s[~null] ** 2) @ v
            cov = s2 * cov_scaled / np.outer(col[idx_p], col[idx_p])
            sd = np.sqrt(np.diag(cov))
            # Correlations from the scaled covariance: independent of s2 (defined for a perfect fit too).
            dg = np.sqrt(np.diag(cov_scaled))
            r = np.clip(cov_scaled / np.outer(dg, dg), -1.0, 1.0).tolist()
            keep = np.flatnonzero(determined[idx_p]).tolist()
            for a in keep:
                sigma[names[idx_p[a]]] = float(sd[a])
                for b in keep:
                    corr[idx_p[a]][idx_p[b]] = r[a][b]
    dof = n_res - rank
    rms = float(np.sqrt(rr / n_res)) if n_res else float("nan")
    if rms < 1e-6:
        warnings.append(
            f"residual rms {rms:.1e}: the image is reproduced to float32 rounding (a noise-free render?), so "
            "sigma reflects rounding only; the optimiser's own scatter (refit with other seeds) is larger"
        )
    out = {
        "method": "gauss-newton",
        "parametrization": "products" if use_products else "scene",
        "names": names,
        "values": [float(v) for v in theta0],
        "sigma": sigma,
        "correlation": corr,
        "residual_rms": rms,
        "pixels": n_pix,
        "excluded": excluded,
        "dof": int(dof),
        "condition": condition,
        "step": [float(h) for h in steps],
        "warnings": warnings,
    }
    if space.direction is not None:
        k, dvec, u, v = space.direction
        block: dict[str, Any] = {"direction": dvec.tolist(), "u": u.tolist(), "v": v.tolist(),
                                 "angle_deg": None, "rms_angle_deg": None}
        if cov is not None and determined[k] and determined[k + 1]:
            at = [int(np.flatnonzero(idx_p == k)[0]), int(np.flatnonzero(idx_p == k + 1)[0])]
            c2 = cov[np.ix_(at, at)]
            block["angle_deg"] = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(c2)[-1], 0.0))))
            block["rms_angle_deg"] = float(np.degrees(np.sqrt(max(np.trace(c2), 0.0))))
        out["light_direction"] = block
    return out


def _svd_scaled(
    jt: np.ndarray, idx: np.ndarray, gram: np.ndarray, col: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Singular values (descending) and right singular vectors (rows) of Js = J / col, J = ``jt[idx]``ᵀ
    (``gram`` = JᵀJ, ``col`` its columns' norms).

    From the eigen-decomposition of JsᵀJs (``gram`` scaled) when every singular value is above GRAM_RCOND
    of the largest: its eigenvalues are then accurate to about 1e-16 / GRAM_RCOND² relative, at P x P
    cost. Otherwise, where squaring would lose the small singular values to rounding, from the SVD of R in
    Js = QR (the same singular values and vectors as Js's), R by a tall-skinny QR: the QR of each block
    of rows, then of their stacked R factors (cache-sized LAPACK calls; one QR of all of Js is several
    times slower, and much slower still when a threaded BLAS competes with the renderer's threads).
    """
    w, vec = np.linalg.eigh(gram / np.outer(col, col))
    if w[-1] > 0 and w[0] > GRAM_RCOND**2 * w[-1]:
        return np.sqrt(w[::-1]), vec[:, ::-1].T
    js = jt[idx].T / col
    m, p = js.shape
    blocks = -(-m // _QR_BLOCK)
    padded = np.zeros((blocks * _QR_BLOCK, p))  # zero rows leave R unchanged
    padded[:m] = js
    r = np.linalg.qr(padded.reshape(blocks, _QR_BLOCK, p), mode="r").reshape(-1, p)
    _, s, vt = np.linalg.svd(np.linalg.qr(r, mode="r"))
    return s, vt


def _products_blocker(scene: Scene, d: dict[str, Any]) -> str | None:
    """None when the image determines exactly the products of this scene and fit section, else why not."""
    paths = scene.fit_paths
    fixed = [o["name"] for o in d["objects"] if f"objects.{o['name']}.albedo" not in paths]
    if fixed:
        return f"the albedo of {', '.join(fixed)} is fixed"
    if not any(p in paths for p in _LIGHT_SCALE):
        return "no light scale (intensity, colour, exposure) is free"
    if any(v != 0 for v in d["ambient"]) or "ambient" in paths:
        return "the scene has ambient light"
    known = [o["name"] for o in d["objects"]
             if o["material"]["specular"] != 0 and f"objects.{o['name']}.specular" not in paths]
    if known:
        return f"the specular of {', '.join(known)} is fixed (a highlight of known strength measures the light)"
    if "light.color" in paths and any(p.endswith(".specular") for p in paths):
        return "the light colour is free and a specular term is fitted (a highlight shows the light's colour)"
    return None


def _scene_space(scene: Scene, d: dict[str, Any]) -> tuple[_Space, dict[str, Any]]:
    """The scene's own fit parameters (a direction as two angles)."""
    paths = list(scene.fit_paths)
    b = np.array(scene.bounds(paths), dtype=np.float64).reshape(-1, 2)
    return _space(scene, paths, d, b[:, 0], b[:, 1], {}), d


def _products_space(scene: Scene, d: dict[str, Any]) -> tuple[_Space, dict[str, Any]]:
    """A scene that renders the products, and its parameters; ``d`` (the scene as a dict) is changed into
    that scene's dict, and returned.

    The work scene's light has intensity 1 and colour w = exposure x colour (the fitted values; 1 in a
    channel where w is 0 and no specular is fitted), exposure 1: an albedo P_c / w_c there renders the
    diffuse product P_c (the parameter's ``factor`` is 1 / w_c), and a specular Q renders the lobe
    Q x w_c x lobe, as exposure x intensity x colour_c x specular x lobe does in the fitted scene.
    """
    paths = scene.fit_paths
    prods = products_of(d)
    glossy = [o for o in d["objects"] if f"objects.{o['name']}.specular" in paths]
    w = np.array(d["light"]["color"], float) * d["exposure"]
    w_work = np.where((w > 0) | bool(glossy), w, 1.0)  # a dark channel stays dark only under a lobe
    inv_w = np.divide(1.0, w_work, out=np.ones(3), where=w_work > 0)
    color_scale = w
    if "light.intensity" in paths:
        ilo, ihi = scene.bounds(["light.intensity"])[0]
    else:
        ilo = ihi = d["light"]["intensity"]
    if "light.color" in paths:
        cb = np.array(scene.bounds(["light.color"]))
        color_scale = d["exposure"] * np.array([cb[:, 0], cb[:, 1]])  # (2, 3): min and max
    else:
        color_scale = np.array([color_scale, color_scale])
    e_range = np.ones(2)  # the exposure's bounds / its fitted value
    if "exposure" in paths:
        e_range = np.array(scene.bounds(["exposure"])[0]) / d["exposure"]
        color_scale = color_scale * e_range[:, None]
    fit_old = d["fit"]
    fit_new: dict[str, Any] = {}
    bounds: dict[str, tuple[float, float]] = {}  # the products' own bounds, by work's parameter name
    factor: dict[str, float] = {}  # work's value / the product's, by work's parameter name
    rename: dict[str, str] = {}  # work's parameter name -> the product's
    for p in ("light.position", "light.direction"):
        if p in paths:
            fit_new[p] = fit_old[p]
    for o in d["objects"]:
        p = f"objects.{o['name']}.albedo"
        ab = np.array(scene.bounds([p]))
        prod = prods[o["name"]]
        plo, phi = product_range(ilo, ihi, color_scale[0], color_scale[1], ab[:, 0], ab[:, 1])
        o["material"]["albedo"] = [float(v) for v in prod * inv_w]
        top = float(max(np.max(phi), np.max(prod), 1.0) * np.max(inv_w))
        fit_new[p] = {"min": [0.0, 0.0, 0.0], "max": [top] * 3}
        for c, lo_c, hi_c, f_c in zip("rgb", plo, phi, inv_w):
            bounds[f"{p}.{c}"] = (float(lo_c), float(hi_c))
            factor[f"{p}.{c}"] = float(f_c)
            rename[f"{p}.{c}"] = f"products.{o['name']}.{c}"
    for o in glossy:
        # Q = intensity x specular (at the fitted exposure, which the work light's colour carries).
        p = f"objects.{o['name']}.specular"
        klo, khi = scene.bounds([p])[0]
        q = specular_product(d["light"]["intensity"], o["material"]["specular"])
        o["material"]["specular"] = float(q)
        qlo, qhi = specular_range(ilo, ihi, klo, khi)
        bounds[p] = (float(qlo * e_range[0]), float(qhi * e_range[1]))
        fit_new[p] = {"min": 0.0, "max": float(max(bounds[p][1], q, 1.0))}
        rename[p] = f"products.{o['name']}.specular"
    for p in paths:
        if p not in _LIGHT_SCALE and p not in fit_new:
            fit_new[p] = fit_old[p]
    d["light"]["intensity"], d["light"]["color"], d["exposure"] = 1.0, [float(v) for v in w_work], 1.0
    d["fit"] = fit_new
    work = Scene(json.dumps(d, allow_nan=False))  # made from a valid scene: load_scene's checks not needed
    new_paths = list(work.fit_paths)
    native_names = work.param_names(new_paths)
    b = np.array(work.bounds(new_paths), dtype=np.float64).reshape(-1, 2)
    for i, name in enumerate(native_names):
        if name in bounds:
            b[i] = bounds[name]
    return _space(work, new_paths, d, b[:, 0], b[:, 1], rename, factor), d


def _space(
    work: Scene,
    paths: list[str],
    d: dict[str, Any],
    lo: np.ndarray,
    hi: np.ndarray,
    rename: dict[str, str],
    factor: dict[str, float] | None = None,
) -> _Space:
    """The parameters of ``work``'s ``paths``: scales from the bounds, albedos and speculars marked as
    linear, and a direction replaced by two angles about the fitted one (no bounds, scale ANGLE_SCALE).
    ``rename`` and ``factor`` (work's value / the parameter's, default 1) are by work's parameter name;
    ``lo``, ``hi`` are the parameters' own bounds."""
    native = work.param_names(paths)
    fac = np.array([(factor or {}).get(name, 1.0) for name in native])
    values = np.array(work.get_params(paths), dtype=np.float64) / fac
    rng = hi - lo
    scale = np.where(rng > 0, rng, np.maximum(np.abs(values), 1.0))
    objects = {f"objects.{o['name']}.": i for i, o in enumerate(d["objects"])}
    albedo, specular = {}, {}
    for i, name in enumerate(native):
        head, _, tail = name.rpartition(".albedo.")
        if head + "." in objects and tail in ("r", "g", "b"):
            albedo[i] = (objects[head + "."], "rgb".index(tail))
        elif name.endswith(".specular") and name[: -len("specular")] in objects:
            specular[i] = objects[name[: -len("specular")]]
    names = [rename.get(name, name) for name in native]
    direction = None
    if "light.direction.x" in native:
        k = native.index("light.direction.x")
        dvec, u, v = _tangent_basis(np.array(values[k : k + 3]), np.array(d["camera"]["up"], float))
        names[k : k + 3] = list(_ANGLES)
        values = np.concatenate([values[:k], [0.0, 0.0], values[k + 3 :]])
        lo = np.concatenate([lo[:k], [-np.inf, -np.inf], lo[k + 3 :]])
        hi = np.concatenate([hi[:k], [np.inf, np.inf], hi[k + 3 :]])
        scale = np.concatenate([scale[:k], [ANGLE_SCALE, ANGLE_SCALE], scale[k + 3 :]])
        fac = np.concatenate([fac[:k], [1.0, 1.0], fac[k + 3 :]])
        albedo = {(i - 1 if i > k else i): oc for i, oc in albedo.items()}
        specular = {(i - 1 if i > k else i): o for i, o in specular.items()}
        direction = (k, dvec, u, v)
    return _Space(work, paths, names, values, lo, hi, scale, albedo, specular, fac, direction)


def _tangent_basis(d: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit ``d`` and two unit axes perpendicular to it: u = up x d (horizontal), v = d x u (towards up)."""
    d = d / np.linalg.norm(d)
    u = np.cross(up, d)
    if np.linalg.norm(u) < 1e-6 * np.linalg.norm(up):  # d along up: any horizontal axis will do
        u = np.cross(np.eye(3)[int(np.argmin(np.abs(d)))], d)
    u /= np.linalg.norm(u)
    return d, u, np.cross(d, u)


def _rotate(d: np.ndarray, u: np.ndarray, v: np.ndarray, a: float, b: float) -> np.ndarray:
    """``d`` turned by the angle |(a, b)| (radians) towards a u + b v: the exponential map at d."""
    w = a * u + b * v
    angle = float(np.hypot(a, b))
    if angle == 0.0:
        return d
    return np.cos(angle) * d + np.sin(angle) * (w / angle)


def _steps(names: list[str], scale: np.ndarray, step: float | dict[str, float] | None) -> np.ndarray:
    if isinstance(step, dict):
        unknown = [n for n in step if n not in names]
        if unknown:
            raise RtloopError(f"step: unknown parameter {unknown[0]!r} (parameters are: {', '.join(names)})")
        out = STEP_FRACTION * scale
        for k, n in enumerate(names):
            if n in step:
                out[k] = float(step[n])
    else:
        out = (STEP_FRACTION if step is None else float(step)) * scale
    if not (np.isfinite(out).all() and (out > 0).all()):
        raise RtloopError("step: every finite-difference step must be a positive number")
    return out


def _lobes(d: dict[str, Any], objects: set[int]) -> np.ndarray:
    """The scene ``d`` with only the specular lobes of ``objects`` (specular 1, their shininess; every
    albedo, the ambient light and the background 0): exactly the derivative of the render with respect
    to those objects' specular, on their pixels."""
    lobes = {
        **d,
        "ambient": [0.0, 0.0, 0.0],
        "background": [0.0, 0.0, 0.0],
        "objects": [{**o, "material": {"albedo": [0.0, 0.0, 0.0], "specular": 1.0 if k in objects else 0.0,
                                       "shininess": o["material"]["shininess"]}}
                    for k, o in enumerate(d["objects"])],
        "fit": {},
    }
    return _native.render(Scene(json.dumps(lobes, allow_nan=False)))
