#!/usr/bin/env python3
"""Render rtloop's test photos "as cameras take them" with an independent renderer (Mitsuba 3).

Every case is a small scene (one or two balls on an infinite floor, one lamp) rendered by Mitsuba 3
(``mitsuba==3.9.1``, variant ``scalar_rgb``: no LLVM needed; ``pip install '.[photos]'``) with effects
that rtloop's own renderer does not model yet: a pixel footprint (box filter, many samples per pixel),
a constant environment light that the objects occlude, interreflection, a GGX clear coat
(``roughplastic``), a spherical lamp of finite size, sensor noise and JPEG.  For each case the script
writes a folder ``OUT/NAME/`` with

``scene.json``
    the truth in rtloop's scene format (what a perfect fit recovers; a constant environment as the
    top-level key ``"environment": [r, g, b]``, radiance in the units of ``ambient``);
``scene_input.json``
    what a user writes today: the same camera and geometry, a neutral guess for the light and the
    colours, and the ``fit`` section freeing ``light.position``, ``light.intensity`` and every albedo;
``objective.png``
    the photo: 128x96, 8-bit sRGB, the sRGB OETF of clamp(x, 0, 1) (``lamp-*``: the decoded JPEG);
``objective.jpg``
    ``lamp-*`` only: the JPEG itself (quality 85);
``meta.json``
    how it was made (Mitsuba settings, integrator and depth, samples, seed, post-processing), what makes
    the case hard, the truth rtloop's format cannot hold yet (environment, lamp radius and radiance,
    roughplastic parameters and how the effective albedo was measured), exposure statistics and the
    measured Monte Carlo noise.

Conventions (checked against rtloop: ``--compare-with`` renders a reference scene's truth through the same
code path and prints the mean absolute difference from its ``objective.png`` in 8-bit codes): point
light ``intensity`` in W/sr = Mitsuba ``point`` ``intensity`` (times the light's colour); ``vfov_deg``
is the vertical field of view (``fov_axis: "y"``); the camera is Mitsuba's ``look_at`` of the scene's
position, look_at and up; an infinite plane is a two-sided 2000 m x 2000 m rectangle; a pixel is the
average radiance over its area (box reconstruction filter, stratified samples) times exposure 1.

Renders run on every core Mitsuba finds; run it under ``nice -n 10`` on a shared machine.
Only Mitsuba, NumPy and Pillow are needed (rtloop is not imported).
"""

from __future__ import annotations

import argparse
import copy
import io
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

MITSUBA_VERSION = "3.9.1"
VARIANT = "scalar_rgb"
WIDTH, HEIGHT = 128, 96
PLANE_HALF_SIZE = 1000.0  # metres: the "infinite" floor is a 2000 m x 2000 m two-sided rectangle
NOISE_SPP_DIVISOR = 4  # the noise check renders a second image with spp / 4 samples and another seed
GLOSS_CALIBRATION_SPP = 256
REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "tests" / "fixtures" / "photos"

# What a user writes today: the same for every case, wide, not centred on any truth.
FIT_LIGHT_POSITION = {"min": [-8.0, 0.5, -8.0], "max": [8.0, 8.0, 8.0]}
FIT_INTENSITY = {"min": 1.0, "max": 400.0}
FIT_ALBEDO = {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0]}
INPUT_LIGHT = {"position": [0.0, 4.25, 0.0], "intensity": 50.0, "color": [1.0, 1.0, 1.0]}
INPUT_ALBEDO = [0.5, 0.5, 0.5]


# --------------------------------------------------------------------------------------------------
# Cases
# --------------------------------------------------------------------------------------------------


@dataclass
class Case:
    """One test photo: the scene, how Mitsuba renders it and what is done to the image afterwards.

    ``objects`` are rtloop-style dicts (``name``, ``shape`` sphere/plane, geometry) with a ``bsdf``:
    ``{"type": "diffuse", "albedo": [r, g, b]}`` or ``{"type": "roughplastic", "alpha": a,
    "diffuse": [r, g, b]}`` (GGX, int_ior 1.5).  ``lamp_radius`` > 0 makes the light a Mitsuba
    ``sphere`` area light of that radius centred on ``light_position`` whose equivalent point intensity
    is ``intensity`` x ``color`` (see :func:`lamp_radiance`).
    """

    name: str
    description: str
    hard_because: str
    camera: dict[str, Any]
    light_position: list[float]
    intensity: float
    color: list[float]
    objects: list[dict[str, Any]]
    integrator: str = "direct"  # "direct" or "path"
    max_depth: int | None = None
    environment: list[float] | None = None
    lamp_radius: float = 0.0
    spp: int = 1024
    seed: int = 0
    noise_sigma: float = 0.0
    noise_seed: int | None = None
    jpeg_quality: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)


CAM_A = {"position": [0.0, 2.6, -5.2], "look_at": [0.0, 0.55, 0.0], "up": [0.0, 1.0, 0.0], "vfov_deg": 34.0}
CAM_B = {"position": [1.2, 2.9, -4.8], "look_at": [0.0, 0.5, 0.0], "up": [0.0, 1.0, 0.0], "vfov_deg": 36.0}
CAM_C = {"position": [-1.0, 2.4, -5.6], "look_at": [0.1, 0.6, 0.2], "up": [0.0, 1.0, 0.0], "vfov_deg": 32.0}
FLOOR = {"name": "floor", "shape": "plane", "point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0]}


def _sphere(name: str, center: list[float], radius: float, bsdf: dict[str, Any]) -> dict[str, Any]:
    return {"name": name, "shape": "sphere", "center": center, "radius": radius, "bsdf": bsdf}


def _floor(albedo: list[float]) -> dict[str, Any]:
    return {**FLOOR, "bsdf": {"type": "diffuse", "albedo": albedo}}


def _diffuse(albedo: list[float]) -> dict[str, Any]:
    return {"type": "diffuse", "albedo": albedo}


def _plastic(diffuse: list[float], alpha: float) -> dict[str, Any]:
    return {"type": "roughplastic", "diffuse": diffuse, "alpha": alpha}


PATH_DEPTH = 8
# interreflection is noisier than direct light: 1024 samples left about 1 code RMS (0.7 robust) on a ball's
# underside; 4096 (the next count the stratified sampler takes) halves it
BOUNCE_SPP = 4096

CASES: list[Case] = [
    Case(
        "direct-overhead",
        "blue ball under a light nearly overhead (74 deg), short shadow; direct light only",
        "what rtloop models except the pixel footprint: silhouette and shadow-edge pixels average their area",
        CAM_A, [0.6, 4.1, -0.7], 34.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.8, 0.0], 0.8, _diffuse([0.22, 0.45, 0.78])), _floor([0.52, 0.5, 0.46])],
        seed=11,
    ),
    Case(
        "direct-side",
        "orange ball lit from the right of the photo at 21 deg elevation by a warm lamp, long shadow; direct light",
        "low side light: the long shadow's soft-looking (footprint-averaged) edge carries the light height",
        CAM_B, [-3.6, 2.2, -1.3], 48.0, [1.0, 0.86, 0.72],
        [_sphere("ball", [0.0, 0.7, 0.0], 0.7, _diffuse([0.82, 0.38, 0.16])), _floor([0.46, 0.5, 0.5])],
        seed=12,
    ),
    Case(
        "direct-two-balls",
        "two balls (yellow and green) of different sizes lit from the front left (30 deg); direct light only",
        "three objects, the small ball partly in the big one's light; edges of two silhouettes and shadows",
        CAM_C, [2.6, 3.1, -2.4], 55.0, [0.95, 1.0, 1.0],
        [
            _sphere("big", [-0.8, 0.62, 0.3], 0.62, _diffuse([0.72, 0.66, 0.22])),
            _sphere("small", [0.75, 0.42, -0.35], 0.42, _diffuse([0.28, 0.72, 0.4])),
            _floor([0.58, 0.58, 0.6]),
        ],
        seed=13,
    ),
    # More clean direct photos (the model-exact class of studies/coverage.py): point light, diffuse balls on
    # a floor, no environment, no bounce; light positions, heights, colours and ball counts varied.
    Case(
        "direct-front-high",
        "red ball under a white light high in front (53 deg), shadow behind the ball; direct light",
        "the light towards the camera: the lit side faces the camera, the shadow falls behind the ball",
        CAM_A, [0.3, 3.6, -2.2], 40.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.7, 0.0], 0.7, _diffuse([0.75, 0.2, 0.18])), _floor([0.5, 0.5, 0.5])],
        seed=14,
    ),
    Case(
        "direct-back-left",
        "white ball lit from behind on the photo's left (29 deg); the shadow comes towards the camera",
        "backlight: the camera sees mostly the ball's dark side and its terminator; the shadow points at the camera",
        CAM_B, [2.8, 2.6, 2.0], 46.0, [1.0, 0.98, 0.94],
        [_sphere("ball", [0.0, 0.7, 0.0], 0.7, _diffuse([0.78, 0.78, 0.74])), _floor([0.45, 0.47, 0.5])],
        seed=15,
    ),
    Case(
        "direct-three-balls",
        "three balls (red, green, blue) of different sizes, light high front right (58 deg); direct light",
        "four objects: three silhouettes, three shadows, a ball partly shadowing another",
        CAM_A, [-1.5, 3.8, -1.8], 50.0, [1.0, 0.95, 0.9],
        [
            _sphere("red", [-1.0, 0.45, 0.2], 0.45, _diffuse([0.7, 0.16, 0.14])),
            _sphere("green", [1.0, 0.4, -0.3], 0.4, _diffuse([0.2, 0.6, 0.25])),
            _sphere("blue", [0.1, 0.6, 0.7], 0.6, _diffuse([0.18, 0.3, 0.72])),
            _floor([0.55, 0.53, 0.5]),
        ],
        seed=16,
    ),
    Case(
        "direct-low-left",
        "cyan ball lit very low (10 deg) from the photo's left, very long shadow; direct light",
        "a grazing light: the lit floor is dim, the shadow runs out of frame",
        CAM_C, [3.8, 1.3, 0.5], 45.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.6, 0.0], 0.6, _diffuse([0.25, 0.68, 0.7])), _floor([0.6, 0.6, 0.58])],
        seed=17,
    ),
    Case(
        "direct-two-overhead",
        "magenta and white balls under a light nearly overhead (78 deg); direct light",
        "two small shadows nearly under the balls: the light's height rests on shadow sizes",
        CAM_B, [0.2, 4.4, 0.3], 50.0, [1.0, 1.0, 1.0],
        [
            _sphere("magenta", [-0.6, 0.5, 0.0], 0.5, _diffuse([0.7, 0.25, 0.6])),
            _sphere("white", [0.7, 0.35, -0.4], 0.35, _diffuse([0.8, 0.8, 0.8])),
            _floor([0.48, 0.5, 0.46]),
        ],
        seed=18,
    ),
    Case(
        "direct-far-right",
        "yellow-green ball, bluish light far (5.3 m) to the photo's right (26 deg); direct light",
        "a distant light: nearly parallel rays, so distance is weakly fixed by the light falloff",
        CAM_A, [-4.5, 3.0, 1.5], 80.0, [0.85, 0.92, 1.0],
        [_sphere("ball", [0.0, 0.7, 0.0], 0.7, _diffuse([0.6, 0.7, 0.2])), _floor([0.52, 0.5, 0.5])],
        seed=19,
    ),
    Case(
        "direct-near-small",
        "small purple ball under a warm light close above it (2.2 m, 47 deg); direct light",
        "a near light: strong falloff across the floor, a large shadow for a small ball",
        CAM_C, [0.9, 2.0, -1.2], 15.0, [1.0, 0.9, 0.8],
        [_sphere("ball", [0.0, 0.4, 0.0], 0.4, _diffuse([0.5, 0.3, 0.7])), _floor([0.5, 0.52, 0.55])],
        seed=20,
    ),
    Case(
        "direct-three-low",
        "three balls (orange, grey, teal) on a dark floor, warm light low in front left (16 deg); direct light",
        "low light across several balls: long overlapping shadows on a dark floor",
        CAM_B, [2.8, 1.8, -2.6], 45.0, [1.0, 0.9, 0.78],
        [
            _sphere("orange", [-0.9, 0.5, 0.3], 0.5, _diffuse([0.85, 0.45, 0.15])),
            _sphere("grey", [0.5, 0.35, -0.5], 0.35, _diffuse([0.5, 0.5, 0.5])),
            _sphere("teal", [0.8, 0.45, 0.8], 0.45, _diffuse([0.15, 0.55, 0.55])),
            _floor([0.3, 0.28, 0.26]),
        ],
        seed=23,
    ),
    Case(
        "env-overhead",
        "terracotta ball, light high above (67 deg) a little to the right, dim grey room light (constant environment)",
        "environment light occluded by the ball: the floor darkens under and around it (ambient occlusion), "
        "the ball's underside sees the floor, not the sky; shadows are not black",
        CAM_A, [-1.1, 3.7, 0.6], 30.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.75, 0.0], 0.75, _diffuse([0.7, 0.42, 0.28])), _floor([0.5, 0.5, 0.5])],
        integrator="path", max_depth=2, environment=[0.012, 0.012, 0.012], seed=21,
    ),
    Case(
        "env-bluish-low",
        "pale ball lit low (14 deg) from the left, slightly bluish environment (daylight through a window)",
        "a bluish occluded environment and a low light: the long shadow is filled with blue light, the floor "
        "and ball colours mix the lamp and the sky",
        CAM_B, [3.9, 1.7, -1.4], 48.0, [1.0, 0.95, 0.88],
        [_sphere("ball", [0.0, 0.65, 0.0], 0.65, _diffuse([0.86, 0.8, 0.68])), _floor([0.42, 0.45, 0.48])],
        integrator="path", max_depth=2, environment=[0.011, 0.014, 0.02], seed=22,
    ),
    Case(
        "bounce-red-ball",
        "saturated red ball on a white floor, light front right at 45 deg; interreflection, no environment",
        "colour bleeding: the red ball tints the white floor around it red, the floor lights the ball's "
        "underside; rtloop's single bounce sees neither",
        CAM_A, [-1.6, 3.3, -2.1], 30.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.7, 0.0], 0.7, _diffuse([0.85, 0.06, 0.04])), _floor([0.85, 0.85, 0.85])],
        integrator="path", max_depth=PATH_DEPTH, spp=BOUNCE_SPP, seed=31,
    ),
    Case(
        "bounce-two-balls",
        "two balls 8 cm apart (white and blue) on a beige floor, light low (24 deg) from the front right; "
        "interreflection",
        "sphere to sphere and floor to sphere light between close balls; the gap is lit by bounces only",
        CAM_C, [-2.8, 1.9, -2.2], 28.0, [1.0, 0.97, 0.92],
        [
            _sphere("white", [-0.55, 0.5, 0.0], 0.5, _diffuse([0.8, 0.8, 0.78])),
            _sphere("blue", [0.53, 0.5, 0.1], 0.5, _diffuse([0.18, 0.42, 0.8])),
            _floor([0.62, 0.56, 0.48]),
        ],
        integrator="path", max_depth=PATH_DEPTH, spp=BOUNCE_SPP, seed=32,
    ),
    Case(
        "env-bounce-overhead",
        "light-blue ball, light high above (76 deg), dim grey environment and interreflection",
        "both the occluded environment and interreflection, a light almost overhead (a small shadow)",
        CAM_B, [0.4, 4.9, 0.9], 52.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.8, 0.0], 0.8, _diffuse([0.55, 0.68, 0.8])), _floor([0.7, 0.66, 0.6])],
        integrator="path", max_depth=PATH_DEPTH, environment=[0.02, 0.02, 0.02], spp=BOUNCE_SPP, seed=41,
    ),
    Case(
        "env-bounce-low",
        "yellow ball lit very low (8 deg) from the right and behind, bluish environment and interreflection",
        "low light far to the side (5.4 m), bluish environment filling the long shadow, and interreflection",
        CAM_C, [-4.7, 1.4, 2.6], 100.0, [1.0, 0.92, 0.8],
        [_sphere("ball", [0.0, 0.6, 0.0], 0.6, _diffuse([0.9, 0.62, 0.18])), _floor([0.55, 0.6, 0.55])],
        integrator="path", max_depth=PATH_DEPTH, environment=[0.01, 0.013, 0.019], spp=BOUNCE_SPP,
        seed=42,
    ),
    Case(
        "gloss-a010",
        "red plastic ball (GGX clear coat, alpha 0.1) on a grey floor, light front left (38 deg); direct light",
        "a sharp GGX highlight (partly clipped) that Blinn-Phong with specular 0 cannot explain, and a diffuse "
        "base dimmed at grazing angles by the coat's Fresnel transmission",
        CAM_A, [2.1, 3.4, -2.6], 46.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.75, 0.0], 0.75, _plastic([0.62, 0.14, 0.1], 0.1)), _floor([0.5, 0.5, 0.5])],
        seed=51,
    ),
    Case(
        "gloss-a025",
        "blue plastic ball (GGX clear coat, alpha 0.25) on a light floor, light front right (40 deg); direct light",
        "a broad GGX highlight over a large part of the ball: easy to mistake for a brighter diffuse colour",
        CAM_B, [-2.4, 3.8, -2.9], 85.0, [1.0, 0.96, 0.9],
        [_sphere("ball", [0.0, 0.7, 0.0], 0.7, _plastic([0.18, 0.36, 0.66], 0.25)), _floor([0.64, 0.62, 0.6])],
        seed=52,
    ),
    Case(
        "gloss-back",
        "red plastic ball (GGX clear coat, alpha 0.1) lit from behind on the left (38 deg); direct light",
        "the camera sees the coat at grazing angles: a rim highlight and a diffuse base that Fresnel dims, "
        "which Blinn-Phong over Lambert does not describe (its colour products 5.4 % off: a known gap)",
        CAM_A, [1.8, 3.0, 2.2], 46.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.75, 0.0], 0.75, _plastic([0.62, 0.14, 0.1], 0.1)), _floor([0.5, 0.5, 0.5])],
        seed=53,
    ),
    # Outlines: photos whose light lies mostly on silhouette pixels (a rim lit from behind), against a
    # nearly black floor, or straight overhead; clean direct light, as the direct-* cases.
    Case(
        "edge-back",
        "orange ball lit from behind (the light beyond the ball, 148 deg from the camera): a thin lit rim "
        "along the top of its silhouette; direct light",
        "the ball's light is all on its silhouette: two to three pixels wide, each pixel part ball, part floor",
        CAM_A, [0.25, 1.4, 3.3], 11.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.7, 0.0], 0.7, _diffuse([0.8, 0.55, 0.3])), _floor([0.5, 0.5, 0.5])],
        seed=71,
    ),
    Case(
        "edge-back-side",
        "green ball lit from behind on the photo's right: a lit crescent on one side of its silhouette; "
        "direct light",
        "a back light to one side: the rim and the long shadow towards the camera carry the light",
        CAM_B, [-2.2, 1.8, 2.6], 24.0, [1.0, 0.97, 0.92],
        [_sphere("ball", [0.0, 0.65, 0.0], 0.65, _diffuse([0.3, 0.7, 0.35])), _floor([0.55, 0.52, 0.5])],
        seed=72,
    ),
    Case(
        "edge-dark-floor",
        "pale blue ball under a warm light from the front left over a nearly black floor; direct light",
        "the floor says almost nothing: the ball's outline against the black floor carries the light",
        CAM_B, [2.0, 3.0, -1.5], 40.0, [1.0, 0.8, 0.6],
        [_sphere("ball", [0.0, 0.7, 0.0], 0.7, _diffuse([0.55, 0.7, 0.85])), _floor([0.03, 0.03, 0.03])],
        seed=73,
    ),
    Case(
        "edge-overhead",
        "pink ball under a light straight overhead (90 deg), its shadow right under it; direct light",
        "the terminator at the ball's equator meets its silhouette against the shadow",
        CAM_C, [0.0, 4.0, 0.0], 35.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.6, 0.0], 0.6, _diffuse([0.75, 0.35, 0.5])), _floor([0.5, 0.5, 0.48])],
        seed=74,
    ),
    Case(
        "lamp-desk",
        "phone photo: green plastic ball under a 20 cm spherical desk lamp front left (48 deg, out of frame), "
        "dim room, "
        "sensor noise and JPEG 85",
        "everything at once: a lamp of finite size (soft shadow edges), a glossy ball, environment and "
        "interreflection, Gaussian noise and JPEG blocks",
        CAM_A, [1.3, 2.9, -1.5], 28.0, [1.0, 0.93, 0.82],
        [_sphere("ball", [0.0, 0.7, 0.0], 0.7, _plastic([0.3, 0.62, 0.3], 0.15)), _floor([0.56, 0.54, 0.5])],
        integrator="path", max_depth=PATH_DEPTH, environment=[0.012, 0.012, 0.014], lamp_radius=0.2,
        spp=BOUNCE_SPP, seed=61, noise_sigma=0.01, noise_seed=6101, jpeg_quality=85,
    ),
    Case(
        "lamp-side",
        "phone photo: white plastic ball and a 20 cm spherical lamp low (20 deg) to the left (out of frame), "
        "bluish dim room, sensor noise and JPEG 85",
        "as lamp-desk with a low lamp 4 m away: long soft shadow, a highlight near the silhouette",
        CAM_C, [3.6, 2.0, -0.9], 40.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.65, 0.0], 0.65, _plastic([0.78, 0.76, 0.72], 0.2)), _floor([0.32, 0.3, 0.28])],
        integrator="path", max_depth=PATH_DEPTH, environment=[0.008, 0.01, 0.014], lamp_radius=0.2,
        spp=BOUNCE_SPP, seed=62, noise_sigma=0.01, noise_seed=6201, jpeg_quality=85,
    ),
    Case(
        "lamp-front",
        "phone photo: yellow plastic ball and a 20 cm spherical lamp in front on the left (31 deg, out of "
        "frame), bluish dim room, sensor noise and JPEG 85",
        "as lamp-side with the lamp between the camera and the ball: the room's dim light shows only once the "
        "bounce and the lobe are explained (the first held-out photo on which the environment was missed)",
        CAM_C, [1.2, 2.6, -3.0], 40.0, [1.0, 1.0, 1.0],
        [_sphere("ball", [0.0, 0.65, 0.0], 0.65, _plastic([0.8, 0.7, 0.3], 0.1)), _floor([0.35, 0.33, 0.3])],
        integrator="path", max_depth=PATH_DEPTH, environment=[0.008, 0.01, 0.014], lamp_radius=0.2,
        spp=BOUNCE_SPP, seed=63, noise_sigma=0.01, noise_seed=6301, jpeg_quality=85,
    ),
]


# --------------------------------------------------------------------------------------------------
# sRGB and small image helpers
# --------------------------------------------------------------------------------------------------


def srgb_oetf(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 encoding of clamp(x, 0, 1), in [0, 1]."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_decode(v: np.ndarray) -> np.ndarray:
    """Inverse of :func:`srgb_oetf` for values in [0, 1]."""
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, np.power((v + 0.055) / 1.055, 2.4))


def encode8(linear: np.ndarray) -> np.ndarray:
    """8-bit sRGB codes (rounded) of a linear image."""
    return np.round(255.0 * srgb_oetf(linear)).astype(np.uint8)


def png_bytes(codes: np.ndarray) -> bytes:
    """A losslessly compressed 8-bit RGB PNG of ``codes``."""
    buf = io.BytesIO()
    Image.fromarray(codes, "RGB").save(buf, "PNG", optimize=True)
    return buf.getvalue()


# --------------------------------------------------------------------------------------------------
# Geometry shared with rtloop's camera model (object ids at pixel centres, for statistics only)
# --------------------------------------------------------------------------------------------------


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def camera_rays(camera: dict[str, Any], width: int, height: int, sub: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Ray origin and unit directions (height*sub, width*sub, 3) of rtloop's camera (docs/scene-format.md)."""
    pos = np.array(camera["position"], float)
    fwd = _unit(np.array(camera["look_at"], float) - pos)
    right = _unit(np.cross(fwd, np.array(camera.get("up", [0, 1, 0]), float)))
    up = np.cross(right, fwd)
    t = math.tan(math.radians(camera["vfov_deg"]) / 2)
    w, h = width * sub, height * sub
    x = (2 * (np.arange(w) + 0.5) / w - 1) * t * width / height
    y = (1 - 2 * (np.arange(h) + 0.5) / h) * t
    d = fwd + x[None, :, None] * right + y[:, None, None] * up
    return pos, _unit(d)


def ray_ids(origin: np.ndarray, dirs: np.ndarray, shapes: list[dict[str, Any]]) -> np.ndarray:
    """Index of the nearest shape hit by each ray (-1: none); spheres and infinite planes."""
    best = np.full(dirs.shape[:-1], np.inf)
    ids = np.full(dirs.shape[:-1], -1, np.int32)
    for k, s in enumerate(shapes):
        if s["shape"] == "sphere":
            oc = origin - np.array(s["center"], float)
            b = dirs @ oc
            disc = b * b - (oc @ oc - s["radius"] ** 2)
            root = np.sqrt(np.maximum(disc, 0))
            t = np.where(-b - root > 1e-9, -b - root, -b + root)
            t = np.where((disc >= 0) & (t > 1e-9), t, np.inf)
        else:
            n = np.array(s["normal"], float)
            den = dirs @ n
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((np.array(s["point"], float) - origin) @ n) / den
            t = np.where(np.isfinite(t) & (t > 1e-9), t, np.inf)
        closer = t < best
        best = np.where(closer, t, best)
        ids = np.where(closer, k, ids)
    return ids


def interior(ids: np.ndarray) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood shows one object (away from silhouettes)."""
    pad = np.pad(ids, 1, mode="edge")
    same = np.ones(ids.shape, bool)
    for dy in range(3):
        for dx in range(3):
            same &= pad[dy:dy + ids.shape[0], dx:dx + ids.shape[1]] == ids
    return same


# --------------------------------------------------------------------------------------------------
# Mitsuba scene
# --------------------------------------------------------------------------------------------------


def _mi():
    """Mitsuba with the scalar_rgb variant set (imported lazily so that --help works without it)."""
    try:
        import mitsuba as mi
    except ImportError:
        sys.exit(f"make_photos.py: needs Mitsuba 3: pip install 'mitsuba=={MITSUBA_VERSION}' "
                 "(or pip install '.[photos]')")
    if mi.__version__ != MITSUBA_VERSION:
        print(f"make_photos.py: warning: Mitsuba {mi.__version__}, the fixtures were made with "
              f"{MITSUBA_VERSION}", file=sys.stderr)
    mi.set_variant(VARIANT)
    return mi


def _rgb(v: list[float] | np.ndarray) -> dict[str, Any]:
    return {"type": "rgb", "value": [float(c) for c in v]}


def lamp_radiance(intensity_rgb: np.ndarray, radius: float) -> np.ndarray:
    """Radiance of a uniformly emitting sphere whose radiant intensity is ``intensity_rgb`` (W/sr).

    A Lambertian sphere of radius r and radiance L shows the projected area pi r^2 in every direction,
    so its intensity is I = L pi r^2 in every direction, and the irradiance it gives a surface that sees
    the whole sphere above its horizon is exactly I cos(theta) / d^2 (d to the centre), the point light
    at its centre.  So L = I / (pi r^2).
    """
    return np.asarray(intensity_rgb, float) / (math.pi * radius * radius)


def bsdf_dict(bsdf: dict[str, Any], *, specular_off: bool = False, diffuse_only: bool = False) -> dict[str, Any]:
    """Mitsuba BSDF of a case's material (two-sided wrapping is added for planes by the caller).

    ``specular_off``: a roughplastic with specular_reflectance 0 (its diffuse base only, Fresnel
    transmission included); ``diffuse_only``: a Lambertian BSDF with the roughplastic's diffuse colour.
    """
    if bsdf["type"] == "diffuse":
        return {"type": "diffuse", "reflectance": _rgb(bsdf["albedo"])}
    if diffuse_only:
        return {"type": "diffuse", "reflectance": _rgb(bsdf["diffuse"])}
    out = {
        "type": "roughplastic",
        "distribution": "ggx",
        "alpha": float(bsdf["alpha"]),
        "int_ior": 1.5,
        "nonlinear": False,
        "diffuse_reflectance": _rgb(bsdf["diffuse"]),
    }
    if specular_off:
        out["specular_reflectance"] = _rgb([0.0, 0.0, 0.0])
    return out


def mitsuba_dict(case: Case, *, spp: int, seed: int, integrator: str | None = None,
                 max_depth: int | None = None, environment: bool = True, point_lamp: bool = False,
                 material: str = "case") -> dict[str, Any]:
    """The Mitsuba scene dictionary of a case.

    Overrides (for calibration renders): ``integrator``/``max_depth``, ``environment=False``,
    ``point_lamp`` (a point light in place of the sphere lamp, same intensity), ``material`` "case",
    "specular_off" or "diffuse_only" (see :func:`bsdf_dict`).
    """
    mi = _mi()
    cam = case.camera
    integ = integrator or case.integrator
    depth = max_depth if integrator else case.max_depth
    scene: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": integ, **({"max_depth": depth} if depth is not None else {})},
        "sensor": {
            "type": "perspective",
            "fov": float(cam["vfov_deg"]),
            "fov_axis": "y",
            "near_clip": 0.01,
            "far_clip": 10000.0,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=cam["position"], target=cam["look_at"], up=cam.get("up", [0.0, 1.0, 0.0])),
            "film": {"type": "hdrfilm", "width": WIDTH, "height": HEIGHT, "pixel_format": "rgb",
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "stratified", "sample_count": spp, "seed": seed, "jitter": True},
        },
    }
    intensity_rgb = case.intensity * np.asarray(case.color, float)
    if case.lamp_radius > 0 and not point_lamp:
        scene["lamp"] = {
            "type": "sphere",
            "center": [float(c) for c in case.light_position],
            "radius": case.lamp_radius,
            "bsdf": {"type": "diffuse", "reflectance": _rgb([0.0, 0.0, 0.0])},
            "emitter": {"type": "area", "radiance": _rgb(lamp_radiance(intensity_rgb, case.lamp_radius))},
        }
    else:
        scene["light"] = {"type": "point", "position": [float(c) for c in case.light_position],
                          "intensity": _rgb(intensity_rgb)}
    if environment and case.environment is not None:
        scene["environment"] = {"type": "constant", "radiance": _rgb(case.environment)}
    for obj in case.objects:
        bsdf = bsdf_dict(obj["bsdf"], specular_off=material == "specular_off",
                         diffuse_only=material == "diffuse_only")
        if obj["shape"] == "sphere":
            scene[obj["name"]] = {"type": "sphere", "center": [float(c) for c in obj["center"]],
                                  "radius": float(obj["radius"]), "bsdf": bsdf}
        elif obj["shape"] == "mesh":  # an OBJ, flat-shaded, two-sided as rtloop's
            scene[obj["name"]] = {
                "type": "obj", "filename": str(obj["file"]), "face_normals": True,
                "to_world": mi.ScalarTransform4f().translate([float(c) for c in obj.get("position", [0, 0, 0])])
                @ mi.ScalarTransform4f().scale(float(obj.get("scale", 1.0))),
                "bsdf": {"type": "twosided", "bsdf": bsdf},
            }
        else:
            p = np.array(obj["point"], float)
            n = _unit(np.array(obj["normal"], float))
            helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
            frame = mi.ScalarTransform4f().look_at(origin=p.tolist(), target=(p + n).tolist(),
                                                   up=np.cross(n, helper).tolist())
            scene[obj["name"]] = {
                "type": "rectangle",
                "to_world": frame @ mi.ScalarTransform4f().scale([PLANE_HALF_SIZE, PLANE_HALF_SIZE, 1.0]),
                "bsdf": {"type": "twosided", "bsdf": bsdf},
            }
    return scene


def render(scene_dict: dict[str, Any]) -> np.ndarray:
    """Linear radiance (HEIGHT, WIDTH, 3) float64 of a Mitsuba scene dictionary."""
    mi = _mi()
    return np.array(mi.render(mi.load_dict(scene_dict)), dtype=np.float64)


# --------------------------------------------------------------------------------------------------
# Truth, input, measurements
# --------------------------------------------------------------------------------------------------


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


def lamp_in_frame(case: Case) -> bool:
    """Whether the sphere lamp shows in the image (checked on a 4x supersampled grid)."""
    origin, dirs = camera_rays(case.camera, WIDTH, HEIGHT, sub=4)
    shapes = [{"shape": "sphere", "center": case.light_position, "radius": case.lamp_radius}]
    shapes += [o for o in case.objects]
    return bool(np.any(ray_ids(origin, dirs, shapes) == 0))


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


def light_geometry(case: Case) -> dict[str, Any]:
    """Where the light is, seen from the first sphere's centre: distance, elevation, side in the photo."""
    ball = np.array(next(o["center"] for o in case.objects if o["shape"] == "sphere"), float)
    rel = np.array(case.light_position, float) - ball
    pos = np.array(case.camera["position"], float)
    fwd = _unit(np.array(case.camera["look_at"], float) - pos)
    right = _unit(np.cross(fwd, np.array(case.camera.get("up", [0, 1, 0]), float)))
    fwd_h = _unit(np.array([fwd[0], 0.0, fwd[2]]))
    horizontal = math.hypot(rel[0], rel[2])
    return {
        "distance_from_ball_m": round(float(np.linalg.norm(rel)), 3),
        "elevation_deg": round(math.degrees(math.atan2(rel[1], horizontal)), 1),
        "right_in_photo_m": round(float(rel @ right), 3),
        "towards_camera_m": round(float(-(rel @ fwd_h)), 3),
        "note": "from the first sphere's centre; right_in_photo < 0: the light is on the photo's left",
    }


def write_json(path: Path, data: Any) -> None:
    path.write_text(json.dumps(data, indent=2) + "\n")


def make_case(case: Case, out: Path) -> dict[str, Any]:
    """Render one case and write its folder; returns a summary for the console."""
    t0 = time.perf_counter()
    names = [o["name"] for o in case.objects]
    origin, dirs = camera_rays(case.camera, WIDTH, HEIGHT)
    ids = ray_ids(origin, dirs, case.objects)
    if np.any(ids < 0):
        raise SystemExit(f"{case.name}: sky in frame ({int(np.sum(ids < 0))} pixels)")
    if case.lamp_radius > 0 and lamp_in_frame(case):
        raise SystemExit(f"{case.name}: the lamp is in frame")

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

    t_render = time.perf_counter()
    linear = render(mitsuba_dict(case, spp=case.spp, seed=case.seed))
    render_s = time.perf_counter() - t_render
    check = render(mitsuba_dict(case, spp=case.spp // NOISE_SPP_DIVISOR, seed=case.seed + 1000))
    noise = mc_noise_codes(linear, check, ids, names, NOISE_SPP_DIVISOR)

    codes, jpeg, post = post_process(case, linear)
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

    floor_index = next((k for k, o in enumerate(case.objects) if o["shape"] == "plane"), None)
    floor_l = lit_floor_radiance(linear, ids, floor_index) if floor_index is not None else None
    renderer: dict[str, Any] = {
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
    extra_truth: dict[str, Any] = {}
    if case.environment is not None:
        extra_truth["environment_radiance"] = case.environment
        extra_truth["environment_over_median_lit_floor_radiance"] = round(
            float(np.mean(case.environment)) / floor_l, 4)
    if case.max_depth and case.max_depth > 2:
        extra_truth["interreflection"] = f"path tracer, max_depth {case.max_depth}"
    if case.lamp_radius > 0:
        intensity_rgb = case.intensity * np.asarray(case.color, float)
        extra_truth["lamp"] = {
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
        extra_truth["glossy_objects"] = gloss
        extra_truth["glossy_note"] = ("scene.json holds the effective Lambertian albedo of the diffuse base and "
                                      "specular 0; the GGX coat has no counterpart in rtloop's format")
    if any(c != 1.0 for c in case.color):
        extra_truth["light_color_note"] = ("the light is coloured; scene_input.json says [1, 1, 1] as a user "
                                           "would, so the determined products are intensity x color x albedo")
    meta = {
        "name": case.name,
        "set": "tests/fixtures/photos",
        "description": case.description,
        "hard_because": case.hard_because,
        "light_geometry": light_geometry(case),
        "renderer": renderer,
        "post": post,
        "extra_truth": extra_truth,
        "files": files,
        "exposure_stats_clean_linear": exposure_stats(linear, ids, names),
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
    return {"name": case.name, "seconds": meta["generation_seconds"], "noise": noise["max_sigma_codes_robust"],
            "noise_rms": noise["max_rms_codes"],
            "clipped": meta["exposure_stats_clean_linear"]["fraction_pixels_clipped(any>1)"],
            "ball_p90": meta["exposure_stats_clean_linear"][names[0]]["max_channel_p10_p50_p90_p99"][2],
            "env_ratio": extra_truth.get("environment_over_median_lit_floor_radiance")}


# --------------------------------------------------------------------------------------------------
# Cross-check against a reference scene (rtloop format, diffuse, point light)
# --------------------------------------------------------------------------------------------------


def case_from_rtloop_scene(scene: dict[str, Any], *, spp: int, seed: int) -> Case:
    """A direct-light case of an rtloop scene (point light, diffuse objects, no ambient/specular)."""
    objects = []
    for obj in scene["objects"]:
        o = {k: v for k, v in obj.items() if k != "material"}
        o["bsdf"] = _diffuse(obj.get("material", {}).get("albedo", [0.5, 0.5, 0.5]))
        objects.append(o)
    light = scene["light"]
    return Case("compare", "", "", scene["camera"], light["position"], float(light["intensity"]),
                light.get("color", [1.0, 1.0, 1.0]), objects, spp=spp, seed=seed)


def compare_with(folder: Path, spp: int) -> float:
    """Render ``folder/scene.json`` through this script's code path; mean |codes - objective.png|."""
    scene = json.loads((folder / "scene.json").read_text())
    if (scene["image"]["width"], scene["image"]["height"]) != (WIDTH, HEIGHT):
        raise SystemExit(f"--compare-with: only {WIDTH}x{HEIGHT} scenes")
    case = case_from_rtloop_scene(scene, spp=spp, seed=1)
    mine = encode8(render(mitsuba_dict(case, spp=spp, seed=1))).astype(np.int32)
    ref = np.asarray(Image.open(folder / "objective.png").convert("RGB"), np.int32)
    diff = np.abs(mine - ref)
    mad = float(diff.mean())
    print(f"{folder}: mean |codes - objective.png| = {mad:.3f}, max {int(diff.max())}, "
          f"pixels differing by > 2 codes: {float(np.mean(diff.max(axis=2) > 2)) * 100:.2f} %")
    return mad


def main(argv: list[str] | None = None) -> int:
    """Command line: render every case (or one) into OUT."""
    parser = argparse.ArgumentParser(
        prog="make_photos.py",
        description=__doc__.split("\n\n")[0] + "\n\nCases: " + ", ".join(c.name for c in CASES) + ".",
        epilog="Examples: nice -n 10 python tools/make_photos.py  (all cases into tests/fixtures/photos)\n"
               "          python tools/make_photos.py --only gloss-a010 --out /tmp/photos\n"
               "          python tools/make_photos.py --compare-with ../shared/scenes/yellow-ball\n"
               "Each case folder gets scene.json (truth), scene_input.json (fit section a user writes), "
               "objective.png (8-bit sRGB), meta.json (how it was made); lamp-* also objective.jpg.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--only", metavar="NAME", action="append",
                        help="render only this case (repeatable); default: all")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="output folder, one sub-folder per case (default: tests/fixtures/photos)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--compare-with", type=Path, metavar="DIR",
                        help="convention check: render DIR/scene.json (rtloop format, point light, diffuse) "
                             "with the direct integrator through this script's code path and print the mean "
                             "absolute difference from DIR/objective.png in 8-bit codes; renders no case")
    parser.add_argument("--compare-spp", type=int, default=1024, help="samples for --compare-with (1024)")
    args = parser.parse_args(argv)

    if args.list:
        for c in CASES:
            print(f"{c.name:22s} {c.description}")
        return 0
    if args.compare_with:
        compare_with(args.compare_with, args.compare_spp)
        return 0
    by_name = {c.name: c for c in CASES}
    names = args.only or list(by_name)
    unknown = [n for n in names if n not in by_name]
    if unknown:
        parser.error(f"unknown case {', '.join(unknown)} (cases: {', '.join(by_name)})")
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for name in names:
        s = make_case(by_name[name], args.out)
        print(f"{s['name']:22s} {s['seconds']:6.1f} s  MC noise {s['noise']:.3f} "
              f"(rms {s['noise_rms']:.3f}) codes  clipped "
              f"{100 * s['clipped']:.2f} %  ball p90 {s['ball_p90']:.3f}"
              + (f"  env/floor {s['env_ratio']:.3f}" if s["env_ratio"] is not None else ""), flush=True)
    print(f"{len(names)} case(s) in {time.perf_counter() - t0:.1f} s -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
