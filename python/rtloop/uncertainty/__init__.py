"""Per-parameter uncertainty of a fit: the Gauss-Newton covariance at the optimum, scaled by the residual.

    u = estimate_uncertainty(result, photo)
    u["sigma"]["light.position.x"]      # one standard deviation, metres
    u["sigma"]["products.ball.r"]       # exposure x intensity x colour x albedo, where only products count

The Jacobian comes from central differences of rtloop's renderer (exact columns for albedos and
speculars); parameters no used pixel fixes get None. The parameters are chosen in :mod:`.space`, the
pixels in :mod:`.pixels`, the decomposition is :mod:`.linalg`'s. See docs/uncertainty.md.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from .. import _native
from ..errors import RtloopError
from ..fit.products import albedo_derivative, unit_environment_scene, unit_lobes_scene
from ..scene import Scene, load_scene, scene_to_dict
from .bars import error_bars
from .covariance import _Covariance, _direction_cone, _product_sigma
from .light import light_distance
from .linalg import _svd_scaled
from .nuisance import Nuisance, basis, held_terms, profile
from .pixels import UsedPixels, used_pixels
from .sandwich import block_sandwich, block_side, sandwich_norm
from .space import _products_blocker, _products_space, _scene_space, _Space

__all__ = ["estimate_uncertainty"]

#: Default finite-difference step: this fraction of each parameter's scale (its bound range; 1 rad for an angle).
STEP_FRACTION = 1e-3
#: Singular values below this fraction of the largest (unit-norm columns) count as zero.
RCOND = 1e-4
#: A parameter whose component in a null singular vector exceeds this is reported as not determined.
NULL_COMPONENT = 1e-3
#: Albedo and specular columns from the exact derivative rather than finite differences (False: render
#: them, as a check).
EXACT_ALBEDO = True
#: The robust covariance holds the shift that pixels averaged over their area cause a pixel-centre fit
#: (``_footprint_bias``); False: not estimated.
FOOTPRINT_BIAS = True


def estimate_uncertainty(
    result: Any,
    image: np.ndarray,
    *,
    clip: bool = True,
    step: float | dict[str, float] | None = None,
    params: str = "auto",
    mask: np.ndarray | None = None,
    render: np.ndarray | None = None,
    compared: np.ndarray | None = None,
    nuisance: Nuisance | None = None,
) -> dict[str, Any]:
    """Per-parameter standard deviations and correlations of a fit (Gauss-Newton at the optimum).

    ``result``: a :class:`rtloop.FitResult` (or a Scene at the optimum with its ``fit`` section).
    ``image``: the objective the fit saw, linear float (H, W, 3) at the scene's size. ``clip`` compares
    min(render, 1) with it, as the fit does. ``step``: finite-difference step as a fraction of each
    parameter's scale (its bound range, 1 rad for a direction angle; default 1e-3), or
    ``{name: absolute step}`` for some parameters. ``params``: ``"auto"`` (products where the scene
    determines only products, else the scene's fit parameters), ``"products"`` or ``"scene"``.
    ``render``: the scene's render at the optimum (float32 (H, W, 3), spp 1) when the caller has it
    (:func:`rtloop.fit` shares its goodness-of-fit render); else the pixels used are rendered, in the pass
    that finds them. ``compared``: the model
    image the fit compared with the photo, whose residual sigma scales (default: for a fit that took the
    pixel footprint, ``result.settings["footprint"]``, the footprint render; else the render at the
    optimum). The Jacobian's columns stay pixel-centre differences: the footprint changes only pixels at
    shadow edges and terminators, which the Gauss-Newton model leaves out. ``nuisance``
    (:class:`.nuisance.Nuisance`): parameters the fit estimated and held besides the scene's (a tone curve
    that corrected ``image``), profiled out: every sigma is marginal over them (``u["nuisance"]``); so is
    the roughness of a coat the fit chose for a highlight (:func:`.nuisance.held_terms`).

    Returns a JSON-able dict: ``method`` ("gauss-newton"), ``names``, ``values`` (the parameters at the
    optimum; 0 for the direction angles), ``sigma`` ({name: float or None}), ``correlation`` (rows and
    columns in ``names`` order, None where a parameter is not determined), ``residual_rms``, ``pixels``
    (used), ``excluded`` (saturated / silhouette / shadow-edge / clip-kink / jump pixel counts, and saturated
    channels left out of pixels otherwise used), ``dof``,
    ``condition`` (of the column-scaled Jacobian over the determined parameters), ``parametrization``,
    ``step`` and ``warnings``; for a directional light also ``light_direction`` (the frame u, v and two
    cone angles in degrees); ``robust``: the block sandwich's sigma (see :mod:`.sandwich`: for an L1 fit
    the median regression's, ``norm`` "l1" with its density ``bandwidth``), which holds when neighbouring
    residuals are correlated, plus the systematic shift that pixels averaged over their area cause a
    pixel-centre fit (``footprint_shift`` per parameter, in the covariance as its outer product: a mean
    squared error; see ``_footprint_bias``), with the light as a whole (``light_position_m``, the
    largest axis; ``light_direction_deg``) and its cost, ``seconds``. ``light_distance`` (and
    ``robust["light_distance"]``), for a point light whose position is fitted: its distance from the
    spheres' mean centre and direction from there, each with its sigma, and whether the distance is
    determined (:mod:`.light`). ``product_sigma`` (and
    ``robust["product_sigma"]``): the sigma of every diffuse product ``products.<object>.<r|g|b>``
    (exposure x intensity x colour x albedo) in either parametrization, propagated from the scene parameters'
    covariance where those are the parameters.
    """
    scene: Scene = result.scene if hasattr(result, "scene") else load_scene(result)
    target = _checked_target(scene, image, params)
    d = scene_to_dict(scene)
    space, wd, use_products = _parameter_space(scene, d, params, getattr(result, "identifiability", None))
    warnings: list[str] = []
    if render is not None and np.shape(render) != target.shape:
        raise RtloopError(f"render: shape {np.shape(render)} does not match the scene's {target.shape}")
    px, got, got_full, exact, unlit = _render_used(scene, space, wd, target, mask, render)
    steps = _steps(space.names, space.scale, step)
    raw0 = got["optimum"] if render is None else np.take(np.asarray(render, np.float32).reshape(-1, 3), px.idx,
                                                          axis=0)
    Jt, f0, kink, jump = _jacobian(space, wd, px, steps, clip, warnings, raw0, exact,
                                   env_u=got.get("environment"), lobe_u=got.get("lobes"), unlit=unlit,
                                   unlit_u=got.get("unlit"))
    f0, r0 = _residual(result, scene, target, px.idx, f0, compared, clip)
    drop, excluded, n_pix, n_res = _leave_out(Jt, r0, px, kink, jump)
    rr = float(np.einsum("i,i->", r0, r0))  # not r0 @ r0: a threaded BLAS dot waits on the render's threads
    # What the fit estimated and holds besides the scene's parameters (a tone curve, a coat's roughness):
    # nuisance parameters, profiled out (least squares: the orthogonal complement of their columns)
    held = [n for n in (nuisance, held_terms(result, space, wd, px.idx, clip)) if n is not None]
    q, Jt_gn = None, Jt
    if held:
        q = basis(np.hstack([n.columns(px.idx) for n in held]), drop.ravel() if drop.any() else None)
        Jt_gn = profile(Jt, q)
    fit = _covariance(Jt_gn, space, rr, n_res - (0 if q is None else q.shape[1]), warnings)
    out = _summary(space, fit, use_products, rr, n_res, n_pix, excluded, steps, warnings)
    if held:
        out["dof"] -= q.shape[1]
        out["nuisance"] = {"what": "; ".join(n.what for n in held), "names": [m for n in held for m in n.names],
                           "profiled": int(q.shape[1])}
    centre = got_full["optimum"] if render is None else np.asarray(render, np.float32)
    _robust(out, result, scene, d, space, wd, fit, use_products, Jt, r0, f0, px.idx, drop, centre, rr, q, Jt_gn)
    out["bars"] = _bars(out, scene, d, getattr(result, "goodness", None), getattr(result, "products", None))
    return out


def _checked_target(scene: Scene, image: np.ndarray, params: str) -> np.ndarray:
    """The objective as float64, checked against the scene's size and for finite values; ``params`` and
    the scene's fit section checked too."""
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
    return target


def _parameter_space(
    scene: Scene, d: dict[str, Any], params: str, ident: dict[str, Any] | None
) -> tuple[_Space, dict[str, Any], bool]:
    """The parameters the uncertainty is over: the products (asked for, or with ``"auto"`` where the scene
    determines only products, as ``ident`` or the scene says) or the scene's fit parameters. Returns the
    space, its work scene dict and whether the products were chosen."""
    why_not = _products_blocker(scene, d)
    if params == "products" and why_not:
        raise RtloopError(f"params: products do not describe this scene ({why_not})")
    degenerate = bool(ident["degenerate"]) if ident is not None else why_not is None
    use_products = params == "products" or (params == "auto" and why_not is None and degenerate)
    space, wd = _products_space(scene, d) if use_products else _scene_space(scene, d)
    return space, wd, use_products


def _render_used(
    scene: Scene,
    space: _Space,
    wd: dict[str, Any],
    target: np.ndarray,
    mask: np.ndarray | None,
    render: np.ndarray | None,
) -> tuple[UsedPixels, dict[str, Any], dict[str, Any], bool, bool]:
    """The used pixels, and the renders the Jacobian needs besides the unit light's, in the same pass: by
    name at the used pixels and in full. Returns those and whether the albedo columns (``exact``) and the
    light intensity's (``unlit``) are exact derivatives."""
    names = space.names
    # The renders the Jacobian needs besides the unit light's, in the same pass: the fitted scene's (without
    # the fit's), the unit environment's, the specular lobes' and the scene's without its light (exact
    # columns; interreflection makes an object's pixels depend on the other objects' albedos, and its own
    # nonlinearly: then the albedo columns are rendered; a lobe, and the light's intensity, stay linear).
    exact = EXACT_ALBEDO and not wd.get("interreflection", False)
    unlit = EXACT_ALBEDO and "light.intensity" in names and float(wd["light"]["intensity"]) > 0
    also = {"optimum": scene if render is None else None,
            "environment": unit_environment_scene(wd) if exact and space.albedo and any(
                wd.get("environment", [0.0, 0.0, 0.0])) else None,
            "lobes": unit_lobes_scene(wd, set(space.specular.values())) if EXACT_ALBEDO and space.specular else None,
            "unlit": _unlit_scene(wd) if unlit and (any(wd["ambient"]) or any(wd.get("environment", [0.0] * 3)))
            else None}
    also = {k: v for k, v in also.items() if v is not None}
    px = used_pixels(space.work, wd, target, mask, also=list(also.values()))
    got = dict(zip(also, px.rendered))
    got_full = dict(zip(also, px.images))
    return px, got, got_full, exact, unlit


def _residual(
    result: Any,
    scene: Scene,
    target: np.ndarray,
    idx: np.ndarray,
    f0: np.ndarray,
    compared: np.ndarray | None,
    clip: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """The model values the fit compared with the photo at the used pixels (flat; the footprint render for
    a fit that took the pixel footprint, ``compared`` where given, else ``f0``) and the residual."""
    settings = getattr(result, "settings", {})
    if compared is None and settings.get("footprint", "off") != "off":
        compared = _native.render(scene, scene.width, scene.height, 1, True,
                                  outlines=bool(settings.get("silhouettes", False)))
    if compared is not None:
        if np.shape(compared) != target.shape:
            raise RtloopError(f"compared: shape {np.shape(compared)} does not match the scene's {target.shape}")
        f0 = np.take(np.asarray(compared, np.float32).reshape(-1, 3), idx, axis=0)
        f0 = (np.minimum(f0, np.float32(1.0)) if clip else f0).ravel()
    r0 = np.subtract(f0, np.take(target.reshape(-1, 3), idx, axis=0).ravel(), dtype=np.float64)
    return f0, r0


def _leave_out(
    Jt: np.ndarray, r0: np.ndarray, px: UsedPixels, kink: np.ndarray, jump: np.ndarray
) -> tuple[np.ndarray, dict[str, int], int, int]:
    """Zero the rows of the saturated channels and of the kink and jump pixels in ``Jt`` and ``r0`` (in
    place). Returns the residuals left out (used, 3), the excluded counts, the pixels and residuals used."""
    n_kink = int(kink.sum())
    kink = kink | jump  # left out alike
    drop = px.sat_u | kink[:, None]  # residuals left out
    if drop.any():  # zero rows: the same JᵀJ, QR and |r|² as without them
        rows = drop.ravel()
        Jt[:, rows] = 0.0
        r0[rows] = 0.0
    excluded = {
        "saturated": int(px.saturated.sum()),
        "saturated_channels": int(px.sat_u[~kink].sum()),
        "silhouette": int((px.silhouette & ~px.saturated).sum()),
        "shadow_edge": int((px.shadow_edge & ~px.saturated).sum()),
        "clip_kink": n_kink,
        "jump": int(jump.sum()),
    }
    n_pix = px.idx.size - int(kink.sum())
    n_res = 3 * n_pix - excluded["saturated_channels"]
    return drop, excluded, n_pix, n_res


def _summary(
    space: _Space,
    fit: _Covariance,
    use_products: bool,
    rr: float,
    n_res: int,
    n_pix: int,
    excluded: dict[str, int],
    steps: np.ndarray,
    warnings: list[str],
) -> dict[str, Any]:
    """The Gauss-Newton part of :func:`estimate_uncertainty`'s answer, from the covariance ``fit`` and the
    residual's sum of squares ``rr`` over ``n_res`` residuals; a warning for a noise-free fit."""
    dof = n_res - fit.rank
    rms = float(np.sqrt(rr / n_res)) if n_res else float("nan")
    if rms < 1e-6:
        warnings.append(
            f"residual rms {rms:.1e}: the image is reproduced to float32 rounding (a noise-free render?), so "
            "sigma reflects rounding only; the optimiser's own scatter (refit with other seeds) is larger"
        )
    out = {
        "method": "gauss-newton",
        "parametrization": "products" if use_products else "scene",
        "names": space.names,
        "values": [float(v) for v in space.theta0],
        "sigma": fit.sigma,
        "correlation": fit.corr,
        "residual_rms": rms,
        "pixels": n_pix,
        "excluded": excluded,
        "dof": int(dof),
        "condition": fit.condition,
        "step": [float(h) for h in steps],
        "warnings": warnings,
    }
    if space.direction is not None:
        out["light_direction"] = _direction_cone(space, fit)
    return out


def _robust(
    out: dict[str, Any],
    result: Any,
    scene: Scene,
    d: dict[str, Any],
    space: _Space,
    wd: dict[str, Any],
    fit: _Covariance,
    use_products: bool,
    Jt: np.ndarray,
    r0: np.ndarray,
    f0: np.ndarray,
    idx: np.ndarray,
    drop: np.ndarray,
    centre: np.ndarray,
    rr: float,
    q: np.ndarray | None = None,
    Jt_gn: np.ndarray | None = None,
) -> None:
    """Add to ``out`` the light's distance, the products' sigma and ``robust``: the block sandwich's
    covariance (with the footprint's shift, from the pixel-centre render ``centre``) and the same
    quantities from it. ``q``: the nuisance columns' basis (:func:`.nuisance.basis`) the sandwich profiles
    out, and ``Jt_gn`` the Jacobian with them profiled out by least squares (Gauss-Newton's, ``fit``'s)."""
    names = space.names
    dof = out["dof"]
    s2 = rr / dof if dof > 0 else 0.0
    bias = _footprint_bias(centre, idx, f0, Jt if Jt_gn is None else Jt_gn, drop.ravel() if drop.any() else None,
                           fit, s2) if FOOTPRINT_BIAS else None
    robust, robust_fit = block_sandwich(Jt, r0, idx, scene.width, fit, s2, names,
                                        block_side(scene.width, scene.height),
                                        norm=sandwich_norm(getattr(result, "settings", {})), bias=bias,
                                        nuisance=q)
    if space.direction is not None:
        robust["light_direction_deg"] = (_direction_cone(space, robust_fit)["angle_deg"]
                                         if robust_fit is not None else None)
    if (distance := light_distance(names, fit.cov, fit.idx_p, fit.determined, d)) is not None:
        out["light_distance"] = distance
        robust["light_distance"] = (light_distance(names, robust_fit.cov, robust_fit.idx_p, robust_fit.determined, d)
                                    if robust_fit is not None else None)
    out["product_sigma"] = _product_sigma(space, wd, fit, use_products)
    robust["product_sigma"] = _product_sigma(space, wd, robust_fit, use_products)
    out["robust"] = robust


def _bars(u: dict[str, Any], scene: Scene, d: dict[str, Any], goodness: dict[str, Any] | None,
          products: dict[str, list[float]] | None) -> dict[str, Any]:
    """:func:`.bars.error_bars` of ``u`` with the scene's bounds by parameter name and the fitted values
    (the products' from ``products``)."""
    bounds = dict(zip(scene.param_names(), scene.bounds(scene.fit_paths)))
    values = {f"products.{o}.{c}": float(v[i]) for o, v in (products or {}).items() for i, c in enumerate("rgb")}
    return error_bars(u, d, bounds, values, goodness)


def _footprint_bias(centre: np.ndarray, idx: np.ndarray, f0: np.ndarray, Jt: np.ndarray,
                    dropped: np.ndarray | None, fit: _Covariance, s2: float) -> np.ndarray | None:
    """The shift of the determined parameters that pixels averaged over their area (as a camera's are)
    would cause in a fit that compares pixel centres: (JᵀJ)⁺ Jᵀ Δ over the used residuals, Δ a pixel's area
    average less its centre value, (f_xx + f_yy) / 24 for a value f that varies smoothly over the pixel (the
    box's second moment, 1/12 per axis, times f''/2), the second derivatives from the 4-neighbour Laplacian
    of ``centre``, the pixel-centre render (float32 (H, W, 3)). A used pixel is no silhouette or shadow edge,
    so its four neighbours show the same object, lit alike; at the image border, where a neighbour clips
    (at 1) and where the fit compared a footprint render's value rather than the centre's (``f0``, flat), Δ
    counts 0. None where the covariance is not formed."""
    if fit.cov is None or not s2 > 0:
        return None
    delta = _native.footprint_delta(np.ascontiguousarray(centre, np.float32), idx.astype(np.uint32), f0)
    if dropped is not None:
        delta[dropped] = 0.0
    # not Jt @ delta: a threaded BLAS product waits on the render's threads (as the residual's sum)
    return (fit.cov / s2) @ np.einsum("ij,j->i", Jt, delta)[fit.idx_p]


def _unlit_scene(d: dict[str, Any]) -> Scene:
    """Scene dict ``d`` with its light's intensity 0: its ambient and environment light alone (with their
    bounce, where the scene has interreflection)."""
    return Scene(json.dumps({**d, "light": {**d["light"], "intensity": 0.0}, "fit": {}}, allow_nan=False))


def _jacobian(space: _Space, wd: dict[str, Any], px: UsedPixels, steps: np.ndarray, clip: bool,
              warnings: list[str], raw0: np.ndarray, exact: bool, env_u: np.ndarray | None = None,
              lobe_u: np.ndarray | None = None, unlit: bool = False, unlit_u: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The Jacobian's transpose over the used pixels' channels, the render there at the optimum (flat,
    min(render, 1) with ``clip``, from ``raw0``: the fitted scene's render at the used pixels, float32
    (used, 3)), which used pixels sit on the clip's kink and which on a jump. With ``exact`` the albedo
    columns are exact derivatives, from the unit-environment render ``env_u`` at the used pixels (float32
    (used, 3); needed where the scene has an environment); a specular's column is the lobes' render
    ``lobe_u`` (where given: exact with interreflection too, which bounces diffuse light only). With
    ``unlit`` the light intensity's column is exact too: (render - render without the light) / intensity
    on the objects' pixels, ``unlit_u`` that render (None: the scene has no ambient or environment light,
    so it is 0 there); the background does not change.

    Central differences (one-sided where a step would cross a bound). With ``clip``, a pixel whose render
    crosses 1 inside a step in a channel that is not saturated sits on the clip's kink and is left out.
    A pixel whose forward and backward changes of a rendered column disagree like a jump rather than a
    smooth function's (a shadow edge or the terminator crossing it inside the step: the shadow-edge mask
    holds the pixels on the edge at the optimum, a step moves a long shadow's edge further) is left out
    too: its central difference would be the jump / 2h (``fd_column``).
    The image is linear in an albedo, a specular and the light's intensity: their columns are the exact
    derivatives (the unit-light render, scaled; the lobe alone; the light's share of the render, scaled),
    and a pixel is on the kink where that line crosses 1.
    """
    names, theta0, idx = space.names, space.theta0, px.idx
    n = idx.size
    free_u = ~px.sat_u
    # The products' work scene renders the fitted image (to float32 rounding): the fit's own render serves.
    clipped0 = raw0 >= 1.0
    P = len(names)
    kink = np.zeros(n, dtype=bool)
    jump = np.zeros(n, dtype=bool)
    by_object: dict[int, list[tuple[int, int, float]]] = {}  # one-sided albedo columns: (k, channel, ±h)
    if wd.get("interreflection", False) and not exact:
        n_objects = len({o for o, _ in space.albedo.values()})
    else:
        n_objects = 0
    # the Jacobian's transpose: one contiguous row per parameter (and a scratch row per object whose albedo
    # columns are rendered one-sided: Jt[:P], the rows above them, is still one contiguous block)
    Jt = np.zeros((P + n_objects, 3 * n))
    if clip:  # min(render, 1), noting kink pixels
        cross = (raw0 >= 1.0) != clipped0
        if cross.any():
            kink[(cross & free_u).any(axis=1)] = True
        f0 = np.minimum(raw0, np.float32(1.0)).ravel()
    else:
        f0 = raw0.ravel()
    exact_at = _ExactAt(wd, px, raw0, clipped0, free_u, env_u, lobe_u, unlit_u)
    k_light = space.names.index("light.intensity") if unlit else -1
    rendered: list[tuple[Any, Any, float, int]] = []  # (up, down, denom, row) of the rendered columns
    for k in range(P):
        h = steps[k]
        tp, tm, denom, up_ok, down_ok = _steps_around(space, k, h)
        if (exact and k in space.albedo) or (lobe_u is not None and k in space.specular) or k == k_light:
            _exact_column(Jt, kink, space, k, tp[k], tm[k], exact_at, clip)
        else:  # the renders, the clip and the difference (float32 values, exact in float64) in the core
            _queue_rendered(space, wd, k, h, tp, tm, denom, up_ok, down_ok, by_object, rendered)
        if theta0[k] <= space.lo[k] or theta0[k] >= space.hi[k]:
            warnings.append(
                f"{names[k]}: at its bound ({theta0[k]:.6g}); the Gauss-Newton sigma assumes an interior optimum"
            )
    _render_columns(Jt, space, by_object, rendered, f0, idx, clipped0, free_u, clip, kink, jump)
    return Jt[:P], f0, kink, jump & ~kink


def _steps_around(space: _Space, k: int, h: float) -> tuple[np.ndarray, np.ndarray, float, bool, bool]:
    """The parameters moved by ``h`` up and down in parameter ``k`` (central; one-sided where a step would
    cross a bound, the other side then left at the optimum), the difference's denominator, and whether each
    side is within the bounds."""
    theta0 = space.theta0
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
    return tp, tm, denom, up_ok, down_ok


class _ExactAt:
    """What the exact columns read at the used pixels: the object ids, the unit light's render, the unit
    environment's (grey: the red channel) and the lobes' (float64), the render without the light, and per
    object (-1: every object's) its used pixels with their render and clip state at the optimum."""

    def __init__(self, wd: dict[str, Any], px: UsedPixels, raw0: np.ndarray, clipped0: np.ndarray,
                 free_u: np.ndarray, env_u: np.ndarray | None, lobe_u: np.ndarray | None,
                 unlit_u: np.ndarray | None) -> None:
        self.wd, self.raw0, self.clipped0, self.free_u, self.unlit_u = wd, raw0, clipped0, free_u, unlit_u
        self.ids_u = np.take(px.ids.ravel(), px.idx)
        self.unit_u = np.take(px.unit.ravel(), px.idx).astype(np.float64)
        self.env_u = None if env_u is None else env_u[:, 0].astype(np.float64)  # grey: the red channel
        self.lobe_u = None if lobe_u is None else lobe_u.astype(np.float64)
        self.pixels_of: dict[int, tuple[np.ndarray, ...]] = {}  # by object index; -1: every object's

    def pixels(self, o: int) -> tuple[np.ndarray, ...]:
        """Object ``o``'s used pixels, their render (float64) and clip state at the optimum, and which
        channels are not saturated."""
        if o not in self.pixels_of:  # the object's used pixels, their render and clip state at the optimum
            on = np.flatnonzero(self.ids_u == o if o >= 0 else self.ids_u >= 0)
            self.pixels_of[o] = (on, self.raw0[on].astype(np.float64), self.clipped0[on], self.free_u[on])
        return self.pixels_of[o]


def _exact_column(Jt: np.ndarray, kink: np.ndarray, space: _Space, k: int, tp_k: float, tm_k: float,
                  at: _ExactAt, clip: bool) -> None:
    """Parameter ``k``'s column as the exact derivative, into ``Jt[k]``: an albedo's from the unit light's
    (and environment's) render, a specular's the lobe alone, the light intensity's the light's share of the
    render; with ``clip``, pixels whose line crosses 1 within the steps to ``tp_k`` and ``tm_k`` noted in
    ``kink``, and the channels clipped at the optimum flat."""
    wd, theta0 = at.wd, space.theta0
    if k in space.albedo:
        o, c = space.albedo[k]
        chans = slice(c, c + 1)
    else:
        o, chans = (space.specular[k] if k in space.specular else -1), slice(0, 3)
    on, base, was, free = at.pixels(o)
    base, was, free = base[:, chans], was[:, chans], free[:, chans]  # views
    if k in space.albedo:
        slope = albedo_derivative(wd, c, at.unit_u[on], None if at.env_u is None else at.env_u[on])[:, None]
    elif k in space.specular:  # d render / d specular: the lobe alone (albedo 0, specular 1)
        slope = at.lobe_u[on]
    else:  # d render / d intensity: the light's share of the render, per unit intensity
        lit = base if at.unlit_u is None else base - at.unlit_u[on].astype(np.float64)
        slope = lit / float(wd["light"]["intensity"])
    slope = slope * space.factor[k]  # per unit of the parameter
    moved = [t - theta0[k] for t in (tp_k, tm_k) if t != theta0[k]]
    if clip:
        for dt in moved:
            hit = ((base + dt * slope >= 1.0) != was) & free
            kink[on[hit[:, 0] if hit.shape[1] == 1 else hit.any(axis=1)]] = True
        slope = np.where(was, 0.0, slope)  # clipped at the optimum and on both sides: flat
    if moved:
        Jt[k].reshape(-1, 3)[on, chans] = slope


def _queue_rendered(space: _Space, wd: dict[str, Any], k: int, h: float, tp: np.ndarray, tm: np.ndarray,
                    denom: float, up_ok: bool, down_ok: bool, by_object: dict[int, list[tuple[int, int, float]]],
                    rendered: list[tuple[Any, Any, float, int]]) -> None:
    """Parameter ``k``'s column by finite differences of renders: queued in ``rendered`` (the scenes up and
    down, the denominator, the row), or, for a one-sided albedo with interreflection, in ``by_object``."""
    theta0 = space.theta0
    one_sided = bool(wd.get("interreflection", False) and (k in space.albedo or k in space.specular)
                     and (up_ok or down_ok))
    if one_sided and k in space.albedo:
        # An albedo moves no edge and the bounce makes the image a low-degree polynomial in it (the
        # sender's albedo times the receiver's): one side, against the optimum's render, errs by
        # h f'' / 2f' relative, under 1e-3, at half the renders (the clip's kink checked on that
        # side). Channel c of the image depends on channel c of the albedos alone, so one render
        # moves all of an object's channels at once and each column is read from its own channel.
        o, c = space.albedo[k]
        by_object.setdefault(o, []).append((k, c, h if up_ok else -h))
    else:
        if one_sided:  # a specular, likewise one-sided (it acts on every channel: a render of its own)
            if up_ok:
                tm, denom = theta0.copy(), h
            else:
                tp, denom = theta0.copy(), h
        up, down = (space.work.with_params(space.native(t), space.paths) if t[k] != theta0[k] else None
                    for t in (tp, tm))
        rendered.append((up, down, float(denom), k))


def _render_columns(Jt: np.ndarray, space: _Space, by_object: dict[int, list[tuple[int, int, float]]],
                    rendered: list[tuple[Any, Any, float, int]], f0: np.ndarray, idx: np.ndarray,
                    clipped0: np.ndarray, free_u: np.ndarray, clip: bool, kink: np.ndarray,
                    jump: np.ndarray) -> None:
    """Render the queued columns into ``Jt`` (kink and jump pixels noted), all in one pass over the used
    pixels, with one render per object for its one-sided albedo columns."""
    theta0, P = space.theta0, len(space.names)
    # One render per object for its one-sided albedo columns: the difference from the optimum (denominator
    # 1, exact) into a scratch row below the Jacobian's, then channel c of it divided by that channel's step
    # (negative for a step down): (f(θ - h) - f0) / -h is (f0 - f(θ - h)) / h to the last bit.
    scratch = {}
    for o, moves in by_object.items():
        t = theta0.copy()
        for k, _, signed_h in moves:
            t[k] += signed_h
        scratch[o] = P + len(scratch)
        rendered.append((space.work.with_params(space.native(t), space.paths), None, 1.0, scratch[o]))
    if rendered:  # all their renders in one pass over the used pixels (the first hits found once)
        ups, downs, denoms, rows = (list(v) for v in zip(*rendered))
        _native.fd_columns(ups, downs, denoms, rows, f0, idx.astype(np.uint32), clipped0.ravel(), free_u.ravel(),
                           clip, kink, jump, Jt)
    for o, moves in by_object.items():
        diff = Jt[scratch[o]].reshape(-1, 3)
        for k, c, signed_h in moves:
            col = Jt[k].reshape(-1, 3)
            col[:, c] = diff[:, c] / abs(signed_h)
            if signed_h < 0:
                np.negative(col[:, c], out=col[:, c])


def _covariance(Jt: np.ndarray, space: _Space, rr: float, n_res: int, warnings: list[str]) -> _Covariance:
    """s² (JᵀJ)⁺ from the column-scaled decomposition; parameters no used pixel responds to, or in a
    numerically zero singular direction, are not determined (sigma None)."""
    names = space.names
    P = len(names)
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
    return _Covariance(sigma, corr, condition, rank, cov, determined, idx_p)


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
