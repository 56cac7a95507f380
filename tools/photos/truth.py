"""The truth of a case and what is measured on its renders: the rtloop-format truth and input scenes,
the object ids (rtloop's own ray caster on the truth scene), the effective albedo of a clear-coated
object, the sphere lamp's check, exposure statistics and the Monte Carlo noise."""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np

import rtloop
from photos.cases import (FIT_ALBEDO, FIT_INTENSITY, FIT_LIGHT_POSITION, HEIGHT, INPUT_ALBEDO, INPUT_LIGHT,
                          WIDTH, Case)
from photos.mitsuba import mitsuba_dict, render
from photos.pixels import interior, srgb_oetf, unit

GLOSS_CALIBRATION_SPP = 256


def object_ids(case: Case, *, sub: int = 1, lamp: bool = False) -> np.ndarray:
    """Which object each pixel centre shows: int32 (HEIGHT*sub, WIDTH*sub), an index into ``case.objects``,
    -1 where none is hit; rtloop's own ray caster (:func:`rtloop.object_ids`) on the case's truth scene, at
    the centres of a grid ``sub`` times finer each way where ``sub`` > 1. ``lamp``: the sphere lamp is one
    more object, first (index 0; the case's objects follow from 1)."""
    scene = truth_scene(case, {o["name"]: list(INPUT_ALBEDO) for o in case.objects})
    if lamp:
        scene["objects"].insert(0, {"name": "lamp", "shape": "sphere",
                                    "center": [float(c) for c in case.light_position],
                                    "radius": float(case.lamp_radius), "material": {"albedo": [0.0, 0.0, 0.0]}})
    return rtloop.object_ids(scene, WIDTH * sub, HEIGHT * sub)


def lamp_in_frame(case: Case) -> bool:
    """Whether the sphere lamp shows in the image (checked on a 4x supersampled grid)."""
    return bool(np.any(object_ids(case, sub=4, lamp=True) == 0))


def effective_albedo(case: Case, obj: dict[str, Any], ids: np.ndarray, index: int) -> tuple[list[float], dict]:
    """The Lambertian albedo that renders a roughplastic object's diffuse base the same (measured).

    Two direct-light renders of the case (point light at the lamp's centre, no environment,
    ``GLOSS_CALIBRATION_SPP`` samples): A with the roughplastic's ``specular_reflectance`` 0 (the base
    under the coat, with its Fresnel transmission in and out and the internal reflections of the coat),
    B with a ``diffuse`` BSDF of the same colour.  With ``nonlinear`` false A is linear in the colour,
    so one factor k = sum(A B) / sum(B B) over the object's lit interior pixels and channels gives
    albedo_eff = k x diffuse_reflectance (least squares; the per-pixel ratio A / B is reported too: it
    falls at grazing angles, where the coat transmits less).
    """
    common = {"spp": GLOSS_CALIBRATION_SPP, "seed": case.seed + 7, "integrator": "direct",
              "environment": False, "point_lamp": True}
    a = render(mitsuba_dict(case, material="specular_off", **common))
    b = render(mitsuba_dict(case, material="diffuse_only", **common))
    sel = interior(ids) & (ids == index) & (b.max(axis=2) > 0.02)
    av, bv = a[sel], b[sel]
    k = float(np.sum(av * bv) / np.sum(bv * bv))
    ratio = (av.sum(axis=1) / bv.sum(axis=1))
    albedo = [round(k * c, 4) for c in obj["bsdf"]["diffuse"]]
    info = {
        "method": "least squares factor k between two direct-light renders of this case (point light at the "
                  f"light position, no environment, {GLOSS_CALIBRATION_SPP} spp): roughplastic with "
                  "specular_reflectance 0 against diffuse with the same diffuse_reflectance, over the object's "
                  "lit interior pixels; albedo = k x diffuse_reflectance",
        "k": round(k, 4),
        "pixels": int(sel.sum()),
        "ratio_p10_p50_p90": [round(float(q), 4) for q in np.percentile(ratio, [10, 50, 90])],
    }
    return albedo, info


def lamp_equivalence(case: Case, ids: np.ndarray) -> dict[str, Any]:
    """Check the sphere lamp against a point light of the equivalent intensity at its centre.

    Two direct-light renders (no environment, every object diffuse, ``GLOSS_CALIBRATION_SPP`` samples):
    the ratio sphere / point over lit interior pixels (1 where the pixel sees the whole lamp) and the
    number of penumbra pixels lit by the sphere only.
    """
    common = {"spp": GLOSS_CALIBRATION_SPP, "seed": case.seed + 9, "integrator": "direct",
              "environment": False, "material": "diffuse_only"}
    a = render(mitsuba_dict(case, **common))
    b = render(mitsuba_dict(case, point_lamp=True, **common))
    flat = interior(ids)
    lit = flat & (b.max(axis=2) > 0.05)
    ratio = a[lit].sum(axis=1) / b[lit].sum(axis=1)
    return {
        "sphere_over_point_ratio_p1_p50_p99": [round(float(q), 4) for q in np.percentile(ratio, [1, 50, 99])],
        "penumbra_pixels_lit_by_the_sphere_only": int(np.sum(flat & (b.max(axis=2) < 1e-6)
                                                            & (a.max(axis=2) > 0.002))),
        "method": f"direct integrator, no environment, diffuse objects, {GLOSS_CALIBRATION_SPP} spp: the "
                  "sphere lamp against a point light of intensity radiance x pi r^2 at its centre, over lit "
                  "pixels away from silhouettes",
    }


def truth_scene(case: Case, albedos: dict[str, list[float]]) -> dict[str, Any]:
    """rtloop-format truth of a case (``environment`` as a top-level key where there is one)."""
    scene: dict[str, Any] = {
        "image": {"width": WIDTH, "height": HEIGHT},
        "camera": copy.deepcopy(case.camera),
        "light": {"position": [float(c) for c in case.light_position], "intensity": float(case.intensity),
                  "color": [float(c) for c in case.color]},
        "ambient": [0.0, 0.0, 0.0],
        # no sky is in frame in any case (the floor fills it); a camera ray that missed would see the
        # environment, so that is the truth's background
        "background": [float(c) for c in (case.environment or [0.0, 0.0, 0.0])],
        "exposure": 1.0,
    }
    if case.environment is not None:
        scene["environment"] = [float(c) for c in case.environment]
    scene["objects"] = []
    for obj in case.objects:
        o = {k: copy.deepcopy(v) for k, v in obj.items() if k != "bsdf"}
        mat: dict[str, Any] = {"albedo": albedos[obj["name"]]}
        if obj["shape"] == "sphere":
            mat.update(specular=0.0, shininess=0.0)
        o["material"] = mat
        scene["objects"].append(o)
    scene["fit"] = fit_section(case)
    return scene


def fit_section(case: Case) -> dict[str, Any]:
    """The fit section a user writes today: light position and intensity, every object's albedo."""
    fit: dict[str, Any] = {"light.position": copy.deepcopy(FIT_LIGHT_POSITION),
                           "light.intensity": copy.deepcopy(FIT_INTENSITY)}
    for obj in case.objects:
        fit[f"objects.{obj['name']}.albedo"] = copy.deepcopy(FIT_ALBEDO)
    return fit


def input_scene(truth: dict[str, Any]) -> dict[str, Any]:
    """What a user writes: the truth's camera and geometry, neutral light and colours, no environment."""
    scene = copy.deepcopy(truth)
    scene.pop("environment", None)
    scene["light"] = copy.deepcopy(INPUT_LIGHT)
    scene["background"] = [0.0, 0.0, 0.0]
    for obj in scene["objects"]:
        obj["material"]["albedo"] = list(INPUT_ALBEDO)
    return scene


def exposure_stats(linear: np.ndarray, ids: np.ndarray, names: list[str]) -> dict[str, Any]:
    """Exposure of the clean render: clipped fraction, per object percentiles of the brightest channel."""
    peak = linear.max(axis=2)
    out: dict[str, Any] = {"fraction_pixels_clipped(any>1)": round(float(np.mean(peak > 1.0)), 4),
                           "fraction_pixels_under_0.02": round(float(np.mean(peak < 0.02)), 4)}
    for k, name in enumerate(names):
        sel = ids == k
        if not sel.any():
            out[name] = {"pixels": 0}
            continue
        v = peak[sel]
        out[name] = {
            "pixels": int(sel.sum()),
            "max_channel_p10_p50_p90_p99": [round(float(q), 4) for q in np.percentile(v, [10, 50, 90, 99])],
            "fraction_clipped": round(float(np.mean(v > 1.0)), 4),
        }
    return out


def lit_floor_radiance(linear: np.ndarray, ids: np.ndarray, floor_index: int) -> float:
    """Median radiance (mean over RGB) of the floor's lit interior pixels (above 20 % of its maximum)."""
    sel = interior(ids) & (ids == floor_index)
    v = linear[sel].mean(axis=1)
    return float(np.median(v[v > 0.2 * v.max()]))


def mc_noise_codes(clean: np.ndarray, check: np.ndarray, ids: np.ndarray, names: list[str],
                   ratio: int) -> dict[str, Any]:
    """Monte Carlo noise of ``clean`` in 8-bit codes, per object, from an independent render ``check`` with
    1/ratio the samples: var(diff) = s^2 (1 + ratio), so s = std(diff) / sqrt(1 + ratio).

    Over flat pixels: one object in the 3x3 neighbourhood and codes 8..247 (not clipped or black).  Both the
    robust standard deviation (1.4826 x MAD) and the RMS (heavier: bounce paths are heavy-tailed) are given.
    """
    ca = 255.0 * srgb_oetf(clean)
    cb = 255.0 * srgb_oetf(check)
    flat = interior(ids)[..., None] & (ca > 8) & (ca < 247)
    scale = math.sqrt(1 + ratio)
    out: dict[str, Any] = {}
    for k, name in enumerate(names):
        d = (ca - cb)[flat & (ids == k)[..., None]]
        if d.size == 0:
            continue
        mad = float(np.median(np.abs(d - np.median(d))))
        out[name] = {"sigma_codes_robust": round(1.4826 * mad / scale, 3),
                     "rms_codes": round(float(np.sqrt(np.mean(d * d))) / scale, 3),
                     "p99_abs_codes": round(float(np.percentile(np.abs(d), 99)) / scale, 3),
                     "samples": int(d.size)}
    out["max_sigma_codes_robust"] = max(v["sigma_codes_robust"] for v in out.values())
    out["max_rms_codes"] = max(v["rms_codes"] for k, v in out.items() if k != "max_sigma_codes_robust")
    return out


def light_geometry(case: Case) -> dict[str, Any]:
    """Where the light is, seen from the first sphere's centre: distance, elevation, side in the photo."""
    ball = np.array(next(o["center"] for o in case.objects if o["shape"] == "sphere"), float)
    rel = np.array(case.light_position, float) - ball
    pos = np.array(case.camera["position"], float)
    fwd = unit(np.array(case.camera["look_at"], float) - pos)
    right = unit(np.cross(fwd, np.array(case.camera.get("up", [0, 1, 0]), float)))
    fwd_h = unit(np.array([fwd[0], 0.0, fwd[2]]))
    horizontal = math.hypot(rel[0], rel[2])
    return {
        "distance_from_ball_m": round(float(np.linalg.norm(rel)), 3),
        "elevation_deg": round(math.degrees(math.atan2(rel[1], horizontal)), 1),
        "right_in_photo_m": round(float(rel @ right), 3),
        "towards_camera_m": round(float(-(rel @ fwd_h)), 3),
        "note": "from the first sphere's centre; right_in_photo < 0: the light is on the photo's left",
    }
