"""A surface of known reflectance in the photo (a grey card lying on the floor) breaks the intensity x albedo
degeneracy: :func:`pin_to_reference` turns a fit's products into absolute albedos and the light's intensity."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from .. import _native
from ..errors import RtloopError
from ..scene import Scene, scene_to_dict

__all__ = ["check_reference", "pin_to_reference"]

_LUMA = np.array([0.2126, 0.7152, 0.0722])
#: Fewest card pixels (at the scene's size) the measurement accepts.
MIN_CARD_PIXELS = 4


def check_reference(scene: Scene, card: np.ndarray, reflectance: float, where: str = "grey card") -> np.ndarray:
    """The card's mask as bool (H, W) at the scene's size, or an RtloopError naming what is wrong (checked
    before a fit, so that a bad reference costs no fit)."""
    if isinstance(reflectance, bool) or not (isinstance(reflectance, (int, float)) and math.isfinite(reflectance)
                                             and 0 < reflectance <= 1):
        raise RtloopError(f"{where}: reflectance must be in (0, 1] (got {reflectance!r}); 0.18 for a grey card")
    card = np.asarray(card, bool)
    if card.shape != (scene.height, scene.width):
        raise RtloopError(f"{where}: the card's mask is {'x'.join(map(str, card.shape[::-1]))}, the scene "
                          f"{scene.width}x{scene.height}")
    return card


def pin_to_reference(scene: Scene, image: np.ndarray, card: np.ndarray, reflectance: float,
                     where: str = "grey card") -> tuple[Scene, dict[str, Any]]:
    """The fitted ``scene`` rescaled so that the card (bool (H, W) at the scene's size, True on it) has
    ``reflectance``, and the record of how (``FitResult.reference``).

    The card lies on one of the scene's planes, left out of the fit: where the fitted scene renders that
    plane, the photo shows the card instead, and everything the scene renders there (direct light and the
    environment) is proportional to the albedo. So per channel the card's albedo in the fit's units is
    ``albedo_plane x sum(photo) / sum(render)`` over its pixels, and ``k = reflectance / that`` is the gauge:
    every albedo times k, the light's intensity x colour (and the environment, the ambient) over k leave
    every product, hence the direct and environment render, unchanged. Interreflection, quadratic in the
    albedos, is the one term this rescales (by k); with it the fit has measured the gauge already, and k
    near 1 is the check.
    """
    card = check_reference(scene, card, reflectance, where)
    d = scene_to_dict(scene)
    ids = _native.object_ids(scene)
    on = ids[card]
    if on.size < MIN_CARD_PIXELS:
        raise RtloopError(f"{where}: only {on.size} pixel(s) of the card at the scene's size "
                          f"({scene.width}x{scene.height}); draw a larger rectangle or use a larger --width")
    planes = [k for k, o in enumerate(d["objects"]) if o["shape"] == "plane"]
    counts = np.bincount(on[on >= 0], minlength=len(d["objects"])) if (on >= 0).any() else np.zeros(1, int)
    plane = int(np.argmax(counts)) if counts.any() else -1
    if plane not in planes or counts[plane] < 0.9 * on.size:
        raise RtloopError(f"{where}: the card's pixels are not on one of the scene's planes (it must lie on the "
                          "floor, away from the ball)")
    render = _native.render(scene, None, None, 16).astype(np.float64)
    photo = np.asarray(image, np.float64)
    sel = card & (ids == plane)
    rendered = render[sel].sum(axis=0)
    seen = photo[sel].sum(axis=0)
    if not (np.all(rendered > 0) and np.all(seen > 0)):
        raise RtloopError(f"{where}: the card is black in the photo or in the fitted render; is it lit?")
    rho_plane = np.asarray(d["objects"][plane]["material"]["albedo"], float)
    card_albedo = rho_plane * seen / rendered  # in the fit's units
    k = reflectance / card_albedo
    light = d["light"]
    rgb = float(light["intensity"]) * np.asarray(light["color"], float) / k
    intensity = float(rgb @ _LUMA)
    out = json.loads(json.dumps(d))
    out["light"]["intensity"] = intensity
    out["light"]["color"] = [float(v) for v in rgb / intensity]
    for o in out["objects"]:
        o["material"]["albedo"] = [float(v) for v in np.asarray(o["material"]["albedo"], float) * k]
        if o["material"].get("specular"):
            o["material"]["specular"] = float(o["material"]["specular"] * light["intensity"] / intensity)
    for key in ("ambient", "environment"):
        if key in out:
            out[key] = [float(v) for v in np.asarray(out[key], float) / k]
    pinned = Scene(json.dumps(out, allow_nan=False))
    albedos = {o["name"]: o["material"]["albedo"] for o in out["objects"]}
    record: dict[str, Any] = {
        "source": where,
        "reflectance": float(reflectance),
        "plane": d["objects"][plane]["name"],
        "pixels": int(sel.sum()),
        "card_albedo_before": [float(v) for v in card_albedo],
        "gauge": [float(v) for v in k],
        "albedos": albedos,
        "light_intensity_w_sr": intensity,
        "light_color": out["light"]["color"],
        "note": ("absolute: the card's known reflectance fixes the light's intensity (W/sr, in the photo's "
                 "radiance units: exposure x radiance) and the albedos, not only their products"),
    }
    if "environment" in out:
        record["environment"] = out["environment"]
    high = [f"{n} {max(a):.3f}" for n, a in albedos.items() if max(a) > 1.0]
    if high:
        record["warning"] = (f"albedo above 1 ({', '.join(high)}) with the card at {reflectance:g}: is its "
                             "reflectance right, and is the card in the shade or lit like the floor around it?")
    return pinned, record
