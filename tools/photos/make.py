"""One case of the test photos rendered and written: the render and its noise check, the post-processing
(noise, 8-bit sRGB, JPEG), and the folder (scene.json, scene_input.json, objective.png, objective.jpg for
JPEG cases, meta.json)."""

from __future__ import annotations

import io
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from photos.cases import PATH_DEPTH, Case
from photos.mitsuba import PLANE_HALF_SIZE, VARIANT, _mi, lamp_radiance, mitsuba_dict, render
from photos.pixels import encode8, png_bytes
from photos.truth import (effective_albedo, exposure_stats, input_scene, lamp_equivalence, lamp_in_frame,
                          light_geometry, lit_floor_radiance, mc_noise_codes, object_ids, truth_scene)

NOISE_SPP_DIVISOR = 4  # the noise check renders a second image with spp / 4 samples and another seed


def post_process(case: Case, linear: np.ndarray) -> tuple[np.ndarray, bytes | None, dict[str, Any]]:
    """Noise (linear, fixed seed), 8-bit sRGB encoding and JPEG: the PNG codes, the JPEG bytes, a record."""
    record: dict[str, Any] = {"noise_sigma_linear": case.noise_sigma, "noise_seed": case.noise_seed,
                              "jpeg_quality": case.jpeg_quality, "downsample_from": None}
    img = linear
    if case.noise_sigma > 0:
        rng = np.random.default_rng(case.noise_seed)
        img = linear + rng.normal(0.0, case.noise_sigma, linear.shape)
        record["noise"] = "additive Gaussian, independent per pixel and channel, on the linear render"
    codes = encode8(img)
    record["encoding"] = "sRGB OETF of clamp(x,0,1), rounded, 8-bit"
    jpeg = None
    if case.jpeg_quality:
        buf = io.BytesIO()
        Image.fromarray(codes, "RGB").save(buf, "JPEG", quality=case.jpeg_quality)
        jpeg = buf.getvalue()
        codes = np.asarray(Image.open(io.BytesIO(jpeg)).convert("RGB"))
        record["jpeg"] = (f"Pillow {Image.__version__}, quality {case.jpeg_quality}, default 4:2:0 chroma "
                          "subsampling; objective.png is the decoded JPEG")
    return codes, jpeg, record


def write_json(path: Path, data: Any) -> None:
    path.write_text(json.dumps(data, indent=2) + "\n")


def checked_ids(case: Case) -> np.ndarray:
    """The case's object ids; stops when a pixel shows no object (sky) or the sphere lamp is in frame."""
    ids = object_ids(case)
    if np.any(ids < 0):
        raise SystemExit(f"{case.name}: sky in frame ({int(np.sum(ids < 0))} pixels)")
    if case.lamp_radius > 0 and lamp_in_frame(case):
        raise SystemExit(f"{case.name}: the lamp is in frame")
    return ids


def albedos_of(case: Case, ids: np.ndarray) -> tuple[dict[str, list[float]], dict[str, Any]]:
    """Each object's truth albedo (a clear-coated one's measured effective albedo) and the coats' records."""
    albedos: dict[str, list[float]] = {}
    gloss: dict[str, Any] = {}
    for k, obj in enumerate(case.objects):
        if obj["bsdf"]["type"] == "diffuse":
            albedos[obj["name"]] = [float(c) for c in obj["bsdf"]["albedo"]]
        else:
            albedo, info = effective_albedo(case, obj, ids, k)
            albedos[obj["name"]] = albedo
            gloss[obj["name"]] = {
                "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": obj["bsdf"]["alpha"],
                         "int_ior": 1.5, "ext_ior": "air (1.000277), eta 1.49958", "nonlinear": False,
                         "diffuse_reflectance": obj["bsdf"]["diffuse"], "specular_reflectance": [1, 1, 1]},
                "effective_albedo": albedo,
                "effective_albedo_measurement": info,
            }
    return albedos, gloss


def write_files(case: Case, out: Path, albedos: dict[str, list[float]], codes: np.ndarray,
                jpeg: bytes | None) -> tuple[Path, list[str]]:
    """scene.json, scene_input.json, objective.png and (JPEG cases) objective.jpg; the folder, the names."""
    folder = out / case.name
    folder.mkdir(parents=True, exist_ok=True)
    truth = truth_scene(case, albedos)
    write_json(folder / "scene.json", truth)
    write_json(folder / "scene_input.json", input_scene(truth))
    (folder / "objective.png").write_bytes(png_bytes(codes))
    files = ["meta.json", "objective.png", "scene.json", "scene_input.json"]
    if jpeg is not None:
        (folder / "objective.jpg").write_bytes(jpeg)
        files.insert(1, "objective.jpg")
    else:
        stale = folder / "objective.jpg"
        if stale.exists():
            stale.unlink()
    return folder, files


def renderer_record(case: Case) -> dict[str, Any]:
    """meta.json's "renderer": how Mitsuba rendered the case."""
    return {
        "mitsuba": _mi().__version__,
        "drjit": __import__("drjit").__version__,
        "variant": VARIANT,
        "integrator": case.integrator,
        "max_depth": case.max_depth,
        "max_depth_note": {None: "direct integrator: one emitter sample and one BSDF sample per camera sample",
                           2: "path, max_depth 2: direct light only (point light and environment, both "
                              "occluded), no interreflection",
                           PATH_DEPTH: "path, max_depth 8: interreflection (up to 7 bounces), Russian "
                                       "roulette from depth 5"}[case.max_depth],
        "spp": case.spp,
        "sampler": "stratified (jittered)",
        "seed": case.seed,
        "rfilter": "box (a pixel is the average over its area)",
        "plane": f"rectangle {2 * PLANE_HALF_SIZE:g} m x {2 * PLANE_HALF_SIZE:g} m, twosided",
        "camera": "perspective, fov = vfov_deg with fov_axis y, to_world = look_at(position, look_at, up)",
        "light": (f"sphere area light, radius {case.lamp_radius:g} m, centre = light.position, radiance = "
                  "intensity x color / (pi r^2)") if case.lamp_radius > 0 else
                 "point emitter, intensity = light.intensity x light.color (W/sr)",
        "environment": f"constant emitter, radiance {case.environment}" if case.environment else "none",
    }


def extra_truth(case: Case, ids: np.ndarray, gloss: dict[str, Any], floor_l: float | None) -> dict[str, Any]:
    """meta.json's "extra_truth": what rtloop's format cannot hold (environment, bounces, lamp, coats)."""
    extra: dict[str, Any] = {}
    if case.environment is not None:
        extra["environment_radiance"] = case.environment
        extra["environment_over_median_lit_floor_radiance"] = round(
            float(np.mean(case.environment)) / floor_l, 4)
    if case.max_depth and case.max_depth > 2:
        extra["interreflection"] = f"path tracer, max_depth {case.max_depth}"
    if case.lamp_radius > 0:
        intensity_rgb = case.intensity * np.asarray(case.color, float)
        extra["lamp"] = {
            "shape": "sphere", "radius_m": case.lamp_radius, "center": case.light_position,
            "radiance_rgb": [round(float(v), 4) for v in lamp_radiance(intensity_rgb, case.lamp_radius)],
            "equivalent_point_intensity": (
                "light.intensity x light.color = radiance x pi r^2 (W/sr): a uniform sphere's projected "
                "area is pi r^2 from every direction, and its irradiance on a surface that sees all of it "
                "is exactly that of a point light of this intensity at its centre; near the edge of the "
                "shadow (the sphere partly below a point's horizon or partly occluded) it differs"),
            "in_frame": False,
            "check": lamp_equivalence(case, ids),
        }
    if gloss:
        extra["glossy_objects"] = gloss
        extra["glossy_note"] = ("scene.json holds the effective Lambertian albedo of the diffuse base and "
                                "specular 0; the GGX coat has no counterpart in rtloop's format")
    if any(c != 1.0 for c in case.color):
        extra["light_color_note"] = ("the light is coloured; scene_input.json says [1, 1, 1] as a user "
                                     "would, so the determined products are intensity x color x albedo")
    return extra


def make_case(case: Case, out: Path) -> dict[str, Any]:
    """Render one case and write its folder; returns a summary for the console."""
    t0 = time.perf_counter()
    names = [o["name"] for o in case.objects]
    ids = checked_ids(case)
    albedos, gloss = albedos_of(case, ids)
    t_render = time.perf_counter()
    linear = render(mitsuba_dict(case, spp=case.spp, seed=case.seed))
    render_s = time.perf_counter() - t_render
    check = render(mitsuba_dict(case, spp=case.spp // NOISE_SPP_DIVISOR, seed=case.seed + 1000))
    noise = mc_noise_codes(linear, check, ids, names, NOISE_SPP_DIVISOR)
    codes, jpeg, post = post_process(case, linear)
    folder, files = write_files(case, out, albedos, codes, jpeg)
    floor_index = next((k for k, o in enumerate(case.objects) if o["shape"] == "plane"), None)
    floor_l = lit_floor_radiance(linear, ids, floor_index) if floor_index is not None else None
    extra = extra_truth(case, ids, gloss, floor_l)
    stats = exposure_stats(linear, ids, names)
    meta = {
        "name": case.name, "set": "tests/fixtures/photos", "description": case.description,
        "hard_because": case.hard_because, "light_geometry": light_geometry(case),
        "renderer": renderer_record(case), "post": post, "extra_truth": extra, "files": files,
        "exposure_stats_clean_linear": stats,
        "lit_floor_median_radiance": round(floor_l, 4) if floor_l is not None else None,
        "mc_noise_clean_8bit": {**noise, "method": (
            f"per object: codes of this render minus an independent render with spp/{NOISE_SPP_DIVISOR} and "
            "seed+1000, over pixels away from silhouettes with codes 8..247, scaled by "
            f"1/sqrt(1+{NOISE_SPP_DIVISOR}); robust sigma = 1.4826 MAD")},
        "render_seconds": round(render_s, 2),
        "generation_seconds": round(time.perf_counter() - t0, 2),
        "generator": "tools/make_photos.py",
    }
    write_json(folder / "meta.json", meta)
    return {"name": case.name, "seconds": meta["generation_seconds"],
            "noise": noise["max_sigma_codes_robust"], "noise_rms": noise["max_rms_codes"], "clipped": stats["fraction_pixels_clipped(any>1)"],
            "ball_p90": stats[names[0]]["max_channel_p10_p50_p90_p99"][2],
            "env_ratio": extra.get("environment_over_median_lit_floor_radiance")}
