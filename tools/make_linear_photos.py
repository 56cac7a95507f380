"""Linear camera files of a ball under one far light, rendered by Mitsuba 3 (``pip install mitsuba``, its
``scalar_rgb`` variant): the kind of photo photometric-stereo datasets hold (a ball seen from far, one light
505 m away in each of 12 directions within 50 deg of the view, 16-bit linear PNG with shot and read noise,
the ball's mask eroded by a pixel). Two materials: Mitsuba's roughplastic (a coated ball, GGX alpha 0.15,
IOR 1.49) and a diffuse one, both of reflectance (0.55, 0.45, 0.3).

Each case folder holds objective.png, mask.png, scene_input.json (the light's position free in a +-1000 m
box, its intensity and the ball's albedo free: the distance is not determined) and truth.json (the light's
unit direction from the ball's centre). ``studies/linear_photos.py`` fits them; tests/fixtures/linear holds
four of them.

    python tools/make_linear_photos.py OUT
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

WIDTH = 96
DISTANCE = 505.0
INTENSITY = 314159.2653589793
#: The photo's gain (its brightest diffuse pixel about 0.5) and the sensor's full well (electrons at 1.0)
#: and read noise (a fraction of full scale).
GAIN, FULL_WELL, READ_NOISE = 2.3, 20000.0, 0.0005
REFLECTANCE = [0.55, 0.45, 0.3]
MATERIALS = {
    "coat": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.15, "int_ior": 1.49, "nonlinear": False,
             "diffuse_reflectance": {"type": "rgb", "value": REFLECTANCE}},
    "matte": {"type": "diffuse", "reflectance": {"type": "rgb", "value": REFLECTANCE}},
}


def directions() -> list[list[float]]:
    """12 light directions, 10 to 50 deg from the view axis (+z), spread in azimuth."""
    out = []
    for k in range(12):
        theta, phi = math.radians(10 + 40 * (k % 4) / 3), 2 * math.pi * k / 12 + 0.3
        out.append([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)])
    return out


def scene_input() -> dict:
    """The scene a user would write: a unit ball at the origin seen from 1000 m, a grey ball and a light
    straight ahead as the start."""
    return {
        "image": {"width": WIDTH, "height": WIDTH},
        "camera": {"position": [0.0, 0.0, 1000.0], "look_at": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                   "vfov_deg": math.degrees(2 * math.atan(1.15 / 1000.0))},
        "light": {"position": [0.0, 0.0, DISTANCE], "intensity": INTENSITY, "color": [1.0, 1.0, 1.0]},
        "ambient": [0.0, 0.0, 0.0], "background": [0.0, 0.0, 0.0], "exposure": 1.0,
        "objects": [{"name": "ball", "shape": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1.0,
                     "material": {"albedo": [0.5, 0.5, 0.5]}}],
        "fit": {"light.position": {"min": [-1000.0, -1000.0, 10.0], "max": [1000.0, 1000.0, 1000.0]},
                "light.intensity": {"min": INTENSITY / 100, "max": INTENSITY * 100},
                "objects.ball.albedo": {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0]}},
    }


def render(bsdf: dict, light: list[float], seed: int) -> np.ndarray:
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    cam = scene_input()["camera"]
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": cam["vfov_deg"], "fov_axis": "y", "near_clip": 900.0,
                   "far_clip": 1100.0,
                   "to_world": mi.ScalarTransform4f().look_at(origin=cam["position"], target=cam["look_at"],
                                                              up=cam["up"]),
                   "film": {"type": "hdrfilm", "width": WIDTH, "height": WIDTH, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": 256}},
        "ball": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "bsdf": bsdf},
        "light": {"type": "point", "position": light, "intensity": {"type": "rgb", "value": [INTENSITY] * 3}},
    })
    return np.array(mi.render(scene, seed=seed), dtype=np.float64)[..., :3] * GAIN


def main(out: Path) -> None:
    import cv2
    from PIL import Image

    import rtloop

    rng = np.random.default_rng(7)
    scene = scene_input()
    ids = np.asarray(rtloop.object_ids(rtloop.load_scene(scene))).reshape(WIDTH, WIDTH)
    ball = ids == 0
    mask = ball.copy()
    mask[1:] &= ball[:-1]
    mask[:-1] &= ball[1:]
    mask[:, 1:] &= ball[:, :-1]
    mask[:, :-1] &= ball[:, 1:]
    for material, bsdf in MATERIALS.items():
        for k, d in enumerate(directions()):
            image = render(bsdf, (DISTANCE * np.array(d)).tolist(), k)
            noisy = rng.poisson(np.clip(image, 0, None) * FULL_WELL) / FULL_WELL + rng.normal(0, READ_NOISE, image.shape)
            codes = np.clip(np.round(noisy * 65535), 0, 65535).astype(np.uint16)
            case = out / f"{material}-{k:02d}"
            case.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(case / "objective.png"), codes[..., ::-1])
            Image.fromarray((mask * 255).astype(np.uint8)).save(case / "mask.png")
            (case / "scene_input.json").write_text(json.dumps(scene, indent=1) + "\n")
            (case / "truth.json").write_text(json.dumps({"direction": d, "material": material}) + "\n")
            print(case.name, flush=True)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(Path(sys.argv[1]))
