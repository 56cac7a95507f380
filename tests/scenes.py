"""Scenes built in code and the starts a user would hand the fit, shared by the tests (through conftest),
tests/pinned_cases.py and the studies (which put this folder on sys.path). Plain dicts; no pytest."""

from __future__ import annotations

import copy

import numpy as np

#: The paper's scene: a sphere on a floor, one point light, its light and both albedos free; 64x48.
BALL_ON_FLOOR = {
    "image": {"width": 64, "height": 48},
    "camera": {"position": [0, 1.6, -6], "look_at": [0, 0.8, 0], "up": [0, 1, 0], "vfov_deg": 35},
    "light": {"position": [2.5, 4.5, -1.0], "intensity": 70.0, "color": [1, 1, 1]},
    "objects": [
        {"name": "ball", "shape": "sphere", "center": [0, 1, 0], "radius": 1,
         "material": {"albedo": [0.8, 0.7, 0.1]}},
        {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
         "material": {"albedo": [0.6, 0.6, 0.6]}},
    ],
    "fit": {
        "light.position": {"min": [-8, 0.5, -8], "max": [8, 8, 8]},
        "light.intensity": {"min": 1, "max": 400},
        "objects.ball.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]},
        "objects.floor.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]},
    },
}


def centred_start(truth: dict) -> dict:
    """``truth`` with the light at the centre of its position bounds and every albedo grey (0.5)."""
    start = copy.deepcopy(truth)
    lo, hi = np.array(truth["fit"]["light.position"]["min"]), np.array(truth["fit"]["light.position"]["max"])
    start["light"]["position"] = list((lo + hi) / 2)
    for o in start["objects"]:
        o["material"]["albedo"] = [0.5, 0.5, 0.5]
    return start


def matte_start(truth: dict) -> dict:
    """What a user writes for a photo of ``truth``: its camera and geometry, every material matte grey, a
    neutral light overhead, the light and the ball's and floor's albedos free (tools/make_photos.py's fit
    section)."""
    d = copy.deepcopy(truth)
    d["light"] = {"position": [0.0, 4.25, 0.0], "intensity": 50.0, "color": [1, 1, 1]}
    for o in d["objects"]:
        o["material"] = {"albedo": [0.5, 0.5, 0.5]}
    d["fit"] = copy.deepcopy(BALL_ON_FLOOR["fit"])
    return d


def sphere(name: str, center: list[float], radius: float, albedo: list[float]) -> dict:
    """A matte sphere's scene entry, with only the fields a scene must give."""
    return {"name": name, "shape": "sphere", "center": center, "radius": radius, "material": {"albedo": albedo}}


def floor(albedo: list[float], name: str = "floor") -> dict:
    """A matte floor's scene entry: the plane y = 0, facing up."""
    return {"name": name, "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
            "material": {"albedo": albedo}}


#: A ball lit from behind: the light beyond the ball from the camera, low, so that the side the camera
#: sees is lit on a thin rim along its outline only (the floor lit beyond and beside it); 128x96.
BACKLIT_BALL = {
    "image": {"width": 128, "height": 96},
    "camera": {"position": [1.2, 2.9, -4.8], "look_at": [0.0, 0.5, 0.0], "up": [0, 1, 0], "vfov_deg": 36.0},
    "light": {"position": [-0.5, 1.3, 2.4], "intensity": 30.0, "color": [1.0, 0.9, 0.8]},
    "objects": [sphere("ball", [0.0, 0.7, 0.0], 0.7, [0.8, 0.4, 0.2]), floor([0.5, 0.5, 0.45])],
    "fit": copy.deepcopy(BALL_ON_FLOOR["fit"]),
}


def supersampled_photo(truth: dict, spp: int = 256) -> np.ndarray:
    """``truth`` rendered by rtloop with ``spp`` sub-pixel rays per pixel (16 x 16: a camera's area average,
    independent of the fit's outline model), rounded to 8-bit sRGB and read back as linear values."""
    import rtloop
    from rtloop._srgb import encode8, srgb_to_linear

    return srgb_to_linear(encode8(rtloop.render(truth, spp=spp)))
