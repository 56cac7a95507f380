#!/usr/bin/env python3
"""Render rtloop's camera-pipeline test photos: Mitsuba 3 renders passed through a camera's processing.

Each scene (a ball on a floor under a point light, direct light only) is rendered once by Mitsuba 3 in
linear float (``tools/make_photos.py``'s conventions: box filter, 128x96, ``scalar_rgb``), then passed
through one camera pipeline per photo:

``vignette``
    the natural cos^4 falloff of a pinhole (theta the angle off the optical axis, from the camera's field
    of view) times a lens's radial falloff 1 + k1 r^2 + k2 r^4 (r = 1 at the image corner), together 40 %
    of the centre in the corners; 8-bit sRGB PNG.
``tone``
    a camera tone curve that is not sRGB: a display gamma 1/2.2 followed by a contrast S-curve with a
    toe and a shoulder, S(u) = u^a / (u^a + (1 - u)^a) (a = 1.5); JPEG quality 90 (4:2:0).
``bayer``
    an RGGB mosaic of the linear image, high-ISO noise (shot noise of variance GAIN x value plus read noise
    READ^2, in linear units), 12-bit quantisation, OpenCV's bilinear demosaic, sRGB, JPEG quality 85.

For each photo the script writes ``OUT/SCENE-PIPELINE/`` with ``objective.png`` (the decoded JPEG where
there is one, and ``objective.jpg``), ``scene.json`` (the truth), ``scene_input.json`` (what a user writes:
neutral light and colours, the fit section freeing the light and every albedo), ``meta.json`` (the
pipeline's parameters) and, once per scene, ``OUT/SCENE-linear.npz`` (the render in float16, the input of
every pipeline, for tests of the camera terms that need the linear truth). Needs Mitsuba 3, NumPy, Pillow
and OpenCV (rtloop is not imported).
"""

from __future__ import annotations

import argparse
import io
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
import make_photos as mp  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "tests" / "fixtures" / "camera"
SPP = 1024

#: The lens's radial falloff 1 + K1 r^2 + K2 r^4 (r = 1 at the corner); with cos^4 the corners are at
#: CORNER of the centre (K2 fixed, K1 solved per camera).
CORNER = 0.40
K2 = -0.06
#: The S-curve's contrast exponent and the display gamma under it.
S_CURVE_A = 1.5
GAMMA = 2.2
#: High-ISO noise in linear units: variance GAIN x value + READ^2 (about 4 codes RMS at mid grey).
GAIN = 0.0015
READ = 0.006
RAW_BITS = 12

SCENES: list[mp.Case] = [
    mp.Case(
        "blue-ball", "blue ball under a light nearly overhead, short shadow", "the camera's processing",
        mp.CAM_A, [0.6, 4.1, -0.7], 34.0, [1.0, 1.0, 1.0],
        [mp._sphere("ball", [0.0, 0.8, 0.0], 0.8, mp._diffuse([0.22, 0.45, 0.78])), mp._floor([0.52, 0.5, 0.46])],
        seed=31,
    ),
    mp.Case(
        "orange-ball", "orange ball lit from the side at 21 deg elevation, long shadow", "the camera's processing",
        mp.CAM_B, [-3.6, 2.2, -1.3], 48.0, [1.0, 0.86, 0.72],
        [mp._sphere("ball", [0.0, 0.7, 0.0], 0.7, mp._diffuse([0.82, 0.38, 0.16])), mp._floor([0.46, 0.5, 0.5])],
        seed=32,
    ),
]


def off_axis(camera: dict[str, Any], width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel centre: cos(theta) off the optical axis and r, the distance from the image centre over the
    half-diagonal (a pinhole with the scene's vertical field of view)."""
    f = (height / 2) / math.tan(math.radians(camera["vfov_deg"]) / 2)
    x = np.arange(width) + 0.5 - width / 2
    y = np.arange(height) + 0.5 - height / 2
    rr = np.hypot(*np.meshgrid(x, y))
    return f / np.hypot(f, rr), rr / math.hypot(width / 2, height / 2)


def vignetting(camera: dict[str, Any], width: int, height: int) -> tuple[np.ndarray, dict[str, float]]:
    """The photo's falloff cos^4 x (1 + k1 r^2 + k2 r^4), CORNER at the corners; and its parameters."""
    cos, r = off_axis(camera, width, height)
    corner_cos = float(cos.min())  # the corner pixels' centres, within half a pixel of the corner
    k1 = CORNER / corner_cos**4 - 1 - K2
    return cos**4 * (1 + k1 * r**2 + K2 * r**4), {"k1": k1, "k2": K2, "corner": CORNER}


def tone_curve(x: np.ndarray) -> np.ndarray:
    """Linear radiance -> the file's value in [0, 1]: gamma 1/GAMMA then S(u) = u^a / (u^a + (1 - u)^a)."""
    u = np.clip(x, 0.0, 1.0) ** (1 / GAMMA)
    return u**S_CURVE_A / (u**S_CURVE_A + (1 - u) ** S_CURVE_A)


def jpeg(codes: np.ndarray, quality: int) -> tuple[np.ndarray, bytes]:
    buf = io.BytesIO()
    Image.fromarray(codes, "RGB").save(buf, "JPEG", quality=quality)
    data = buf.getvalue()
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB")), data


def bayer(linear: np.ndarray, seed: int) -> np.ndarray:
    """RGGB mosaic, noise, 12-bit quantisation and OpenCV's bilinear demosaic: linear RGB."""
    import cv2

    h, w, _ = linear.shape
    raw = np.empty((h, w))
    raw[0::2, 0::2] = linear[0::2, 0::2, 0]
    raw[0::2, 1::2] = linear[0::2, 1::2, 1]
    raw[1::2, 0::2] = linear[1::2, 0::2, 1]
    raw[1::2, 1::2] = linear[1::2, 1::2, 2]
    rng = np.random.default_rng(seed)
    raw = raw + rng.normal(size=raw.shape) * np.sqrt(GAIN * np.clip(raw, 0, None) + READ**2)
    top = 2**RAW_BITS - 1
    counts = np.clip(np.round(raw * top), 0, top).astype(np.uint16)
    # OpenCV names a pattern by the second row's second and third pixels: RGGB is its "BayerBG"; with
    # the 2BGR code the output is RGB-ordered for an RGGB mosaic read as BGR (checked below).
    rgb = cv2.cvtColor(counts, cv2.COLOR_BayerBG2RGB).astype(np.float64) / top
    return rgb


def _check_demosaic() -> None:
    flat = np.broadcast_to(np.array([0.2, 0.5, 0.8]), (8, 8, 3)).copy()
    global GAIN, READ
    saved, GAIN, READ = (GAIN, READ), 0.0, 0.0
    try:
        out = bayer(flat, 0)
    finally:
        GAIN, READ = saved
    if not np.allclose(out[2:-2, 2:-2], flat[2:-2, 2:-2], atol=1e-3):
        raise SystemExit(f"demosaic check: a flat (0.2, 0.5, 0.8) came back {out[4, 4]}")


def make_scene(case: mp.Case, out: Path) -> list[str]:
    linear = mp.render(mp.mitsuba_dict(case, spp=SPP, seed=case.seed))
    np.savez_compressed(out / f"{case.name}-linear.npz", linear=linear.astype(np.float16))
    truth = mp.truth_scene(case, {o["name"]: [float(c) for c in o["bsdf"]["albedo"]] for o in case.objects})
    v, vparams = vignetting(case.camera, mp.WIDTH, mp.HEIGHT)
    made = []
    photos: dict[str, tuple[np.ndarray, bytes | None, dict[str, Any]]] = {}
    photos["vignette"] = (mp.encode8(linear * v[..., None]), None,
                          {"pipeline": "cos^4 x (1 + k1 r^2 + k2 r^4), r = 1 at the corner; 8-bit sRGB", **vparams})
    tone = np.round(tone_curve(linear) * 255).astype(np.uint8)
    photos["tone"] = (*jpeg(tone, 90), {"pipeline": "gamma 1/2.2, then S(u) = u^a / (u^a + (1 - u)^a); JPEG 90",
                                        "a": S_CURVE_A, "gamma": GAMMA, "jpeg_quality": 90})
    demosaiced = bayer(linear, case.seed + 100)
    photos["bayer"] = (*jpeg(mp.encode8(demosaiced), 85),
                       {"pipeline": "RGGB mosaic, noise, 12-bit, OpenCV bilinear demosaic, sRGB, JPEG 85",
                        "noise": f"variance {GAIN} x value + {READ}^2 (linear)", "raw_bits": RAW_BITS,
                        "noise_seed": case.seed + 100, "jpeg_quality": 85})
    for kind, (codes, data, post) in photos.items():
        folder = out / f"{case.name}-{kind}"
        folder.mkdir(parents=True, exist_ok=True)
        mp.write_json(folder / "scene.json", truth)
        mp.write_json(folder / "scene_input.json", mp.input_scene(truth))
        (folder / "objective.png").write_bytes(mp.png_bytes(codes))
        if data is not None:
            (folder / "objective.jpg").write_bytes(data)
        mp.write_json(folder / "meta.json", {
            "name": folder.name, "scene": case.description, "render": f"Mitsuba {mp.MITSUBA_VERSION} "
            f"{mp.VARIANT}, direct integrator, {SPP} spp, seed {case.seed}, box filter", "post": post,
            "linear": f"../{case.name}-linear.npz", "generator": "tools/make_camera_photos.py"})
        made.append(folder.name)
    return made


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--only", nargs="*", help="scene names")
    args = ap.parse_args(argv)
    _check_demosaic()
    args.out.mkdir(parents=True, exist_ok=True)
    for case in SCENES:
        if args.only and case.name not in args.only:
            continue
        print(*make_scene(case, args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
