#!/usr/bin/env python3
"""Render the coated-material fixtures (tests/fixtures/coat) with Mitsuba 3's ``roughplastic``.

Each case is one ball on a grey floor under a point light, the ball a Lambertian base under a GGX clear
coat (``roughplastic``, ``nonlinear`` false, ``ext_ior`` 1 so that ``int_ior`` is the relative IOR rtloop's
``coat.ior`` means). The scene conventions (camera, floor, box filter, stratified samples) are
tools/make_photos.py's. For each case ``OUT/NAME/`` gets

``scene.json``     the truth in rtloop's scene format (the ball's ``material.coat``);
``linear.npz``     ``image``: the linear render (float32, H x W x 3) and ``noise``: half the absolute
                   difference from a second render with another seed (a per-pixel Monte Carlo scale);
``objective.png``  the 8-bit sRGB photo of ``image``;
``meta.json``      how it was made.

    python tools/make_coat_photos.py [--out DIR] [--spp N] [--only NAME,...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import make_photos as mp  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "tests" / "fixtures" / "coat"
CAMERA = {"position": [0.0, 2.2, -5.0], "look_at": [0.0, 0.6, 0.0], "up": [0.0, 1.0, 0.0], "vfov_deg": 30.0}

#: name: (diffuse colour, alpha, ior, specular weight, light position, intensity)
CASES = {
    "coat-a010-red": ([0.62, 0.14, 0.10], 0.1, 1.49, 1.0, [1.6, 3.2, -2.4], 30.0),
    "coat-a030-blue": ([0.15, 0.35, 0.70], 0.3, 1.49, 1.0, [-1.8, 2.8, -2.0], 30.0),
    "coat-a010-green-half": ([0.20, 0.55, 0.25], 0.1, 1.6, 0.5, [0.6, 3.6, -3.0], 35.0),
}


def scene_of(name: str) -> dict:
    diffuse, alpha, ior, ks, light, intensity = CASES[name]
    return {
        "name": name,
        "image": {"width": mp.WIDTH, "height": mp.HEIGHT},
        "camera": CAMERA,
        "light": {"position": light, "intensity": intensity, "color": [1.0, 1.0, 1.0]},
        "objects": [
            {"name": "ball", "shape": "sphere", "center": [0.0, 0.6, 0.0], "radius": 0.6,
             "material": {"albedo": diffuse, "specular": ks, "coat": {"roughness": alpha, "ior": ior}}},
            {"name": "floor", "shape": "plane", "point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0],
             "material": {"albedo": [0.5, 0.5, 0.5]}},
        ],
    }


def mitsuba_scene(truth: dict, spp: int, seed: int) -> dict:
    ball, floor = truth["objects"]
    case = mp.Case(name=truth["name"], description="", hard_because="", camera=truth["camera"],
                   light_position=truth["light"]["position"], intensity=truth["light"]["intensity"],
                   color=[1.0, 1.0, 1.0],
                   objects=[{**ball, "bsdf": {"type": "diffuse", "albedo": [0, 0, 0]}},
                            {**floor, "bsdf": {"type": "diffuse", "albedo": floor["material"]["albedo"]}}])
    d = mp.mitsuba_dict(case, spp=spp, seed=seed)
    m = ball["material"]
    d["ball"]["bsdf"] = {
        "type": "roughplastic", "distribution": "ggx", "alpha": float(m["coat"]["roughness"]),
        "int_ior": float(m["coat"]["ior"]), "ext_ior": 1.0, "nonlinear": False,
        "diffuse_reflectance": mp._rgb(m["albedo"]),
        "specular_reflectance": mp._rgb([m["specular"]] * 3),
    }
    return d


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--spp", type=int, default=2048)
    ap.add_argument("--only", default="")
    a = ap.parse_args(argv)
    names = [n for n in CASES if not a.only or n in a.only.split(",")]
    for name in names:
        t0 = time.time()
        truth = scene_of(name)
        image = mp.render(mitsuba_scene(truth, a.spp, seed=1))
        check = mp.render(mitsuba_scene(truth, a.spp, seed=2))
        out = a.out / name
        out.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(out / "linear.npz", image=image.astype(np.float32),
                            noise=(0.5 * np.abs(image - check)).astype(np.float16))
        (out / "objective.png").write_bytes(mp.png_bytes(mp.encode8(image)))
        (out / "scene.json").write_text(json.dumps(truth, indent=1) + "\n")
        meta = {"renderer": {"mitsuba": mp.MITSUBA_VERSION, "variant": mp.VARIANT, "integrator": "direct",
                             "spp": a.spp, "seeds": [1, 2], "sampler": "stratified (jittered)",
                             "rfilter": "box", "plane": "rectangle 2000 m x 2000 m, twosided"},
                "bsdf": mitsuba_scene(truth, 1, 1)["ball"]["bsdf"] | {"note": "ext_ior 1: int_ior is coat.ior"},
                "command": "python tools/make_coat_photos.py " + " ".join(argv or sys.argv[1:])}
        (out / "meta.json").write_text(json.dumps(meta, indent=1, default=str) + "\n")
        print(f"{name}: {time.time() - t0:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
