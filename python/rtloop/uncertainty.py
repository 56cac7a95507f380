"""How sure are we: per-parameter uncertainty of a fit from the Gauss-Newton approximation at the optimum.

    result = rtloop.fit(scene, photo, seed=1)
    u = estimate_uncertainty(result, photo)
    u["sigma"]["light.position.x"]      # one standard deviation, metres
    u["sigma"]["products.ball.r"]       # exposure x intensity x colour x albedo of the ball, red

Residuals are r(θ) = min(render(θ), 1) - image over every used pixel and channel. Near the optimum
r(θ) ≈ r(θ̂) + J (θ - θ̂), and if the image is the model plus independent noise of one variance σ², the
least-squares estimate has covariance σ² (JᵀJ)⁻¹; σ² is estimated from the residuals as
s² = |r|² / (N - P) (P the rank of J). J is taken by central finite differences of rtloop's own renderer,
with steps of 1e-3 of each parameter's bound range: the renderer works in float32, and smaller steps let
its rounding through (the intensity-albedo degeneracy then no longer looks singular).

Which parameters. A matte scene without ambient light fixes only exposure x intensity x colour x albedo
per object and channel (``result.identifiability["degenerate"]``), so when every object's albedo is free
those *products* are the parameters (varied by scaling albedos under a light of unit intensity and
colour, exposure 1), with the light position and any other free parameter; their names are
``products.NAME.r|g|b``. Otherwise the scene's own fit parameters are used (``params="scene"`` forces
this, ``params="products"`` insists on products).

Which pixels. Pixels saturated in the objective (any channel >= 0.999) say only "at least 1"; pixels on a
silhouette (a 4-neighbour shows another object) and on a shadow edge (a 4-neighbour differs in whether the
light reaches it) change discontinuously with the parameters, which one sample per pixel cannot represent
as a derivative. All three are left out, and with ``clip`` so is a pixel whose render crosses 1 within a
finite-difference step (the clip's kink); everything else, background included, is used.

Not determined. The Jacobian's columns are scaled to unit norm and decomposed (SVD). A parameter that no
used pixel responds to (the albedo of an object no pixel shows, or one the light never reaches) or that
enters a numerically zero singular direction (intensity against albedo when the scene's own parameters
are used in a degenerate scene) gets ``None`` as sigma and a warning; the covariance of the rest is
computed without them.

What it is not. The fit minimises the L1 loss, not least squares: for Gaussian noise the L1 estimate is
about sqrt(pi/2) ≈ 1.25 times as spread as the least-squares one the formula describes, and the optimiser
adds its own (small) scatter. sigma describes the noise in the photo under the model; it does not cover a
wrong model (a misplaced camera, a wrong shape, an unmodelled light) or a fit short of its optimum: both
show as a ``residual_rms`` above the photo's noise, and s², hence sigma, grows with them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _native
from .errors import RtloopError
from .scene import Scene, load_scene, scene_to_dict

__all__ = ["estimate_uncertainty"]

#: Default finite-difference step: this fraction of each parameter's scale (its bound range).
STEP_FRACTION = 1e-3
#: Objective pixels with any channel at or above this are saturated and left out.
SATURATED = 0.999
#: Singular values below this fraction of the largest (unit-norm columns) count as zero.
RCOND = 1e-4
#: A parameter whose component in a null singular vector exceeds this is reported as not determined.
NULL_COMPONENT = 1e-3

_LIGHT_SCALE = ("light.intensity", "light.color", "exposure")


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
    parameter's bound range (default 1e-3), or ``{name: absolute step}`` for some parameters.
    ``params``: ``"auto"`` (products where the scene determines only products, else the scene's fit
    parameters), ``"products"`` or ``"scene"``.

    Returns a JSON-able dict: ``method`` ("gauss-newton"), ``names``, ``values`` (the parameters at the
    optimum), ``sigma`` ({name: float or None}), ``correlation`` (rows and columns in ``names`` order,
    None where a parameter is not determined), ``residual_rms``, ``pixels`` (used), ``excluded``
    (saturated / silhouette / shadow-edge pixel counts), ``dof``, ``condition`` (of the column-scaled
    Jacobian over the determined parameters), ``parametrization`` and ``warnings``.
    """
    scene: Scene = result.scene if hasattr(result, "scene") else load_scene(result)
    if scene_to_dict(scene)["light"].get("type") == "directional":
        # The direction is a unit vector searched through three components: the parametrisation below
        # assumes a point light. Say so rather than report a misleading sigma.
        raise RtloopError("uncertainty: not available for directional lights yet")
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

    why_not = _products_blocker(scene)
    if params == "products" and why_not:
        raise RtloopError(f"params: products do not describe this scene ({why_not})")
    degenerate = bool(ident["degenerate"]) if ident is not None else why_not is None
    use_products = params == "products" or (params == "auto" and why_not is None and degenerate)
    work, paths, names, lo, hi, scale = _products_space(scene) if use_products else _scene_space(scene)
    theta0 = np.array(work.get_params(paths), dtype=np.float64)
    warnings: list[str] = []

    def raw(theta: np.ndarray) -> np.ndarray:
        return _native.render(work.with_params([float(v) for v in theta], paths))

    # Pixels the model can represent as a smooth function of the parameters.
    ids = _native.object_ids(work)
    lit = _lit_mask(work)
    saturated = (target >= SATURATED).any(axis=2)
    silhouette = _edges(ids)
    shadow_edge = _edges(np.where(ids >= 0, lit.astype(np.int32), -1)) & ~silhouette
    use = ~(saturated | silhouette | shadow_edge)
    if mask is not None:  # pixels the fit left out (bool (H, W), True = used)
        use &= np.asarray(mask, bool)
    raw0 = raw(theta0)
    clipped0 = raw0 >= 1.0

    # Jacobian by central differences (one-sided where a step would cross a bound). With ``clip``, a pixel
    # whose render crosses 1 inside a step sits on the clip's kink and is left out ("clip_kink").
    steps = _steps(names, scale, step)
    P = len(names)
    kink = np.zeros(use.shape, dtype=bool)
    J = np.zeros((int(use.sum()) * 3, P))

    def clipped(img: np.ndarray) -> np.ndarray:
        nonlocal kink
        if clip:
            kink |= ((img >= 1.0) != clipped0).any(axis=2)
            img = np.minimum(img, 1.0)
        return img[use].astype(np.float64).ravel()

    f0 = clipped(raw0)
    for k in range(P):
        h = steps[k]
        up_ok, down_ok = theta0[k] + h <= hi[k], theta0[k] - h >= lo[k]
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
        fp = clipped(raw(tp)) if tp[k] != theta0[k] else f0
        fm = clipped(raw(tm)) if tm[k] != theta0[k] else f0
        J[:, k] = (fp - fm) / denom
        if theta0[k] <= lo[k] or theta0[k] >= hi[k]:
            warnings.append(
                f"{names[k]}: at its bound ({theta0[k]:.6g}); the Gauss-Newton sigma assumes an interior optimum"
            )
    kink &= use
    rows = np.repeat(~kink[use], 3)
    J = J[rows]
    r0 = (f0 - target[use].astype(np.float64).ravel())[rows]
    use &= ~kink
    excluded = {
        "saturated": int(saturated.sum()),
        "silhouette": int((silhouette & ~saturated).sum()),
        "shadow_edge": int((shadow_edge & ~saturated).sum()),
        "clip_kink": int(kink.sum()),
    }
    n_pix = int(use.sum())
    n_res = r0.size

    determined = np.ones(P, dtype=bool)
    col = np.linalg.norm(J, axis=0)
    finite = np.isfinite(J).all(axis=0)
    effect = np.where(finite, col * scale, 0.0)
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
    idx = np.flatnonzero(determined)
    sigma: dict[str, float | None] = {n: None for n in names}
    corr: list[list[float | None]] = [[None] * P for _ in range(P)]
    condition = None
    rank = 0
    s2 = float("nan")
    if idx.size:
        # SVD of R from Js = QR: the same singular values and vectors as Js's, at P x P cost.
        _, s, vt = np.linalg.svd(np.linalg.qr(J[:, idx] / col[idx], mode="r"))
        null = s < RCOND * s[0]
        rank = int((~null).sum())
        condition = float(s[0] / s[~null].min())
        if null.any():
            involved = (np.abs(vt[null]) > NULL_COMPONENT).any(axis=0)
            group = [names[i] for i in idx[involved]]
            warnings.append(
                f"{', '.join(group)}: not determined: the image fixes only a combination of them "
                f"(singular value {s[null].min() / s[0]:.1e} of the largest)"
            )
            determined[idx[involved]] = False
        if n_res - rank <= 0:
            warnings.append(f"only {n_res} residuals for {rank} parameters: no uncertainty can be estimated")
            determined[:] = False
        else:
            s2 = float(r0 @ r0) / (n_res - rank)
            # (JsᵀJs)⁺ = V S⁻² Vᵀ over the non-zero singular values: no explicit normal-equation inverse.
            v = vt[~null]
            cov_scaled = (v.T / s[~null] ** 2) @ v
            cov = s2 * cov_scaled / np.outer(col[idx], col[idx])
            sd = np.sqrt(np.diag(cov))
            # Correlations from the scaled covariance: independent of s2 (defined for a perfect fit too).
            d = np.sqrt(np.diag(cov_scaled))
            keep = np.flatnonzero(determined[idx])
            for a in keep:
                sigma[names[idx[a]]] = float(sd[a])
                for b in keep:
                    corr[idx[a]][idx[b]] = float(np.clip(cov_scaled[a, b] / (d[a] * d[b]), -1.0, 1.0))
    dof = n_res - rank
    rms = float(np.sqrt(r0 @ r0 / n_res)) if n_res else float("nan")
    if rms < 1e-6:
        warnings.append(
            f"residual rms {rms:.1e}: the image is reproduced to float32 rounding (a noise-free render?), so "
            "sigma reflects rounding only; the optimiser's own scatter (refit with other seeds) is larger"
        )
    return {
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


def _products_blocker(scene: Scene) -> str | None:
    """None when the image determines exactly the products of this scene and fit section, else why not."""
    d = scene_to_dict(scene)
    paths = scene.fit_paths
    fixed = [o["name"] for o in d["objects"] if f"objects.{o['name']}.albedo" not in paths]
    if fixed:
        return f"the albedo of {', '.join(fixed)} is fixed"
    if not any(p in paths for p in _LIGHT_SCALE):
        return "no light scale (intensity, colour, exposure) is free"
    if any(v != 0 for v in d["ambient"]) or "ambient" in paths:
        return "the scene has ambient light"
    if any(o["material"]["specular"] != 0 for o in d["objects"]) or any(p.endswith(".specular") for p in paths):
        return "an object has a specular term"
    return None


def _scene_space(scene: Scene) -> tuple[Scene, list[str], list[str], np.ndarray, np.ndarray, np.ndarray]:
    paths = list(scene.fit_paths)
    names = scene.param_names(paths)
    b = np.array(scene.bounds(paths), dtype=np.float64).reshape(-1, 2)
    values = np.array(scene.get_params(paths), dtype=np.float64)
    rng = b[:, 1] - b[:, 0]
    scale = np.where(rng > 0, rng, np.maximum(np.abs(values), 1.0))
    return scene, paths, names, b[:, 0], b[:, 1], scale


def _products_space(scene: Scene) -> tuple[Scene, list[str], list[str], np.ndarray, np.ndarray, np.ndarray]:
    """A scene whose albedos are the products under a unit light, and its parameters."""
    d = scene_to_dict(scene)
    paths = scene.fit_paths
    light = np.array(d["light"]["color"], float) * d["light"]["intensity"] * d["exposure"]
    color_scale = np.array(d["light"]["color"], float) * d["exposure"]
    if "light.intensity" in paths:
        ilo, ihi = scene.bounds(["light.intensity"])[0]
    else:
        ilo = ihi = d["light"]["intensity"]
    if "light.color" in paths:
        cb = np.array(scene.bounds(["light.color"]))
        color_scale = d["exposure"] * np.array([cb[:, 0], cb[:, 1]])  # (2, 3): min and max
    else:
        color_scale = np.array([color_scale, color_scale])
    if "exposure" in paths:
        elo, ehi = scene.bounds(["exposure"])[0]
        color_scale = color_scale / d["exposure"] * np.array([[elo], [ehi]])
    fit_old = d["fit"]
    fit_new: dict[str, Any] = {}
    lo: list[float] = []
    hi: list[float] = []
    names: list[str] = []
    new_paths: list[str] = []
    if "light.position" in paths:
        fit_new["light.position"] = fit_old["light.position"]
    for o in d["objects"]:
        p = f"objects.{o['name']}.albedo"
        ab = np.array(scene.bounds([p]))
        prod = light * np.array(o["material"]["albedo"], float)
        plo = ilo * color_scale[0] * ab[:, 0]
        phi = ihi * color_scale[1] * ab[:, 1]
        o["material"]["albedo"] = [float(v) for v in prod]
        top = float(max(np.max(phi), np.max(prod), 1.0))
        fit_new[p] = {"min": [0.0, 0.0, 0.0], "max": [top] * 3}
        lo.extend(float(v) for v in plo)
        hi.extend(float(v) for v in phi)
        names.extend(f"products.{o['name']}.{c}" for c in "rgb")
    rest = [p for p in paths if p not in _LIGHT_SCALE and not p.endswith(".albedo") and p != "light.position"]
    for p in rest:
        fit_new[p] = fit_old[p]
    d["light"]["intensity"], d["light"]["color"], d["exposure"] = 1.0, [1.0, 1.0, 1.0], 1.0
    d["fit"] = fit_new
    work = load_scene(d)
    if "light.position" in paths:
        new_paths.append("light.position")
    new_paths.extend(f"objects.{o['name']}.albedo" for o in d["objects"])
    new_paths.extend(rest)
    all_names: list[str] = []
    all_lo: list[float] = []
    all_hi: list[float] = []
    if "light.position" in paths:
        all_names += work.param_names(["light.position"])
        b = work.bounds(["light.position"])
        all_lo += [v[0] for v in b]
        all_hi += [v[1] for v in b]
    all_names += names
    all_lo += lo
    all_hi += hi
    if rest:
        all_names += work.param_names(rest)
        b = work.bounds(rest)
        all_lo += [v[0] for v in b]
        all_hi += [v[1] for v in b]
    lo_a, hi_a = np.array(all_lo), np.array(all_hi)
    values = np.array(work.get_params(new_paths), dtype=np.float64)
    rng = hi_a - lo_a
    scale = np.where(rng > 0, rng, np.maximum(np.abs(values), 1.0))
    return work, new_paths, all_names, lo_a, hi_a, scale


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


def _lit_mask(scene: Scene) -> np.ndarray:
    """Whether the light reaches the surface each pixel shows (unit light, unit albedos, no ambient)."""
    d = scene_to_dict(scene)
    d["light"]["intensity"], d["light"]["color"], d["ambient"], d["exposure"] = 1.0, [1.0, 1.0, 1.0], [0, 0, 0], 1.0
    d["background"] = [0.0, 0.0, 0.0]
    for o in d["objects"]:
        o["material"] = {"albedo": [1.0, 1.0, 1.0]}
    d["fit"] = {}
    return _native.render(load_scene(d))[..., 0] > 0


def _edges(labels: np.ndarray) -> np.ndarray:
    """Pixels with a 4-neighbour of a different label."""
    e = np.zeros(labels.shape, dtype=bool)
    diff_v = labels[1:, :] != labels[:-1, :]
    diff_h = labels[:, 1:] != labels[:, :-1]
    e[1:, :] |= diff_v
    e[:-1, :] |= diff_v
    e[:, 1:] |= diff_h
    e[:, :-1] |= diff_h
    return e
