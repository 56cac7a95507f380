"""Error numbers of a fit: against the true scene (per parameter, the light position in metres, each
object's product) and of the fitted render against the objective."""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import _srgb as _srgb_codec
from ..fit.products import products_of
from ..scene import Scene, load_scene, scene_to_dict

__all__ = ["image_metrics", "truth_errors", "truth_values"]


def truth_values(scene: Scene, truth: Any) -> tuple[Scene, np.ndarray]:
    """The truth scene (path, dict or Scene) read with ``scene``'s fit section, and the true values of
    ``scene.param_names()``. Raises RtloopError/SceneError if the truth lacks one of the fitted things."""
    truth_scene = load_scene(truth)
    d = scene_to_dict(truth_scene)
    d["fit"] = scene_to_dict(scene)["fit"]
    aligned = load_scene(d)
    return aligned, np.asarray(aligned.get_params(scene.fit_paths), float)


def truth_errors(result: Any, truth: Any) -> dict[str, Any]:
    """Compare a fit with the true scene: per-parameter values and errors, the light position error in
    metres (when the position was fitted) and each object's product relative error,
    |P_fit - P_true| / |P_true| over R, G, B (products: exposure x intensity x colour x albedo); ``sigmas``:
    each error over the fit's block-sandwich sigma, where it has one; ``split_convention``: the parameters
    the photo does not determine one by one (the factors of a determined product), whose errors say how the
    fit split the product, not how well it fitted."""
    scene = result.scene
    aligned, true = truth_values(scene, truth)
    names = scene.param_names()
    fitted = np.asarray(scene.get_params(scene.fit_paths), float)
    out: dict[str, Any] = {
        "values": {n: float(v) for n, v in zip(names, true)},
        "errors": {n: float(f - t) for n, f, t in zip(names, fitted, true)},
    }
    # Where the photo fixes only products, the factors' own errors depend on how the fit split them.
    ident = getattr(result, "identifiability", None) or {}
    factors = {p for term in ident.get("determined", []) if "*" in term for p in term.split("*")}
    out["split_convention"] = ([n for n in names if any(n == p or n.startswith(p + ".") for p in factors)]
                               if ident.get("degenerate") else [])
    bars = ((getattr(result, "uncertainty", None) or {}).get("robust") or {}).get("sigma") or {}
    out["sigmas"] = {n: e / bars[n] for n, e in out["errors"].items() if bars.get(n)}  # error / sigma
    pos = [names.index(f"light.position.{c}") for c in "xyz" if f"light.position.{c}" in names]
    if len(pos) == 3:
        out["light_position_m"] = float(np.linalg.norm(fitted[pos] - true[pos]))
    fit_p, true_p = products_of(scene_to_dict(scene)), products_of(scene_to_dict(aligned))
    rel = {}
    for name, p in fit_p.items():
        t = true_p.get(name)
        if t is not None:
            denom = float(np.linalg.norm(t))
            rel[name] = float(np.linalg.norm(p - t) / denom) if denom > 0 else float("nan")
    out["products_true"] = {k: [float(v) for v in p] for k, p in true_p.items()}
    out["product_relative"] = rel
    return out


def image_metrics(render_linear: np.ndarray, objective_linear: np.ndarray) -> dict[str, float]:
    """L1 (mean |difference|) and RMSE in linear RGB, PSNR (dB, peak 1) of the sRGB-encoded images, and the
    fit's own whole-image loss (sum of |difference|). The render is clipped to 1 as the fit compares it."""
    r = np.minimum(np.asarray(render_linear, np.float64), 1.0)
    o = np.asarray(objective_linear, np.float64)
    d = r - o
    mse_srgb = float(np.mean((_srgb_codec.encode(r, np.float64) - _srgb_codec.encode(o, np.float64)) ** 2))
    return {
        "l1_linear": float(np.mean(np.abs(d))),
        "rmse_linear": float(np.sqrt(np.mean(d * d))),
        "psnr_srgb_db": float(10 * np.log10(1.0 / mse_srgb)) if mse_srgb > 0 else float("inf"),
        "sum_abs_linear": float(np.sum(np.abs(d))),
    }
