"""The test photos' cases: the Case type, the cameras, the object and material helpers, the cases of
tests/fixtures/photos, and what a user writes today (the input scene's guesses and fit ranges)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

WIDTH, HEIGHT = 128, 96

# What a user writes today: the same for every case, wide, not centred on any truth.
FIT_LIGHT_POSITION = {"min": [-8.0, 0.5, -8.0], "max": [8.0, 8.0, 8.0]}
FIT_INTENSITY = {"min": 1.0, "max": 400.0}
FIT_ALBEDO = {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0]}
INPUT_LIGHT = {"position": [0.0, 4.25, 0.0], "intensity": 50.0, "color": [1.0, 1.0, 1.0]}
INPUT_ALBEDO = [0.5, 0.5, 0.5]


@dataclass
class Case:
    """One test photo: the scene, how Mitsuba renders it and what is done to the image afterwards.

    ``objects`` are rtloop-style dicts (``name``, ``shape`` sphere/plane, geometry) with a ``bsdf``:
    ``{"type": "diffuse", "albedo": [r, g, b]}`` or ``{"type": "roughplastic", "alpha": a,
    "diffuse": [r, g, b]}`` (GGX, int_ior 1.5).  ``lamp_radius`` > 0 makes the light a Mitsuba
    ``sphere`` area light of that radius centred on ``light_position`` whose equivalent point intensity
    is ``intensity`` x ``color`` (see :func:`photos.mitsuba.lamp_radiance`).
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

