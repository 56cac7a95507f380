#!/usr/bin/env python3
"""Render rtloop's one-photo test views with an independent renderer (Mitsuba 3): a ChArUco board lying on
the floor beside a ball, a grey card of known reflectance, one point light and a dim room light.

The board is OpenCV's own board image (``cv2.aruco.CharucoBoard.generateImage``) with a white paper margin of
one square, as a bitmap texture (linear reflectance: paper 0.85, ink 0.04) on a rectangle lying on the floor;
the grey card is a diffuse rectangle of reflectance ``CARD_REFLECTANCE`` 1 mm above the floor; the ball is a
diffuse sphere of radius ``BALL_RADIUS`` resting on the floor; the floor is a 2000 m two-sided rectangle.
Mitsuba's path tracer (``scalar_rgb``, depth ``MAX_DEPTH``: the environment's occlusion and interreflection),
a box pixel filter, a constant environment. World frame: rtloop-scene's (metres, +y up, the board's centre at
the origin, x along its columns, z along its rows).

For each view ``OUT/NAME/`` gets ``photo.png`` (640x480 8-bit sRGB with EXIF FocalLength and
FocalPlaneXResolution, as a camera writes them), ``scene.json`` (the truth in rtloop's format at the
160 px working width rtloop-scene uses, with the ``fit`` section rtloop-scene writes) and ``meta.json``
(camera, ball, light, albedos, the card's pixel rectangle, the board, how it was rendered).
Needs Mitsuba, NumPy, OpenCV, Pillow and rtloop for its sRGB encoding (tools/photos/pixels.py: the
repository's ``python/`` with its extension built, or an installed rtloop). ``nice -n 10`` on a shared
machine.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from photos.pixels import encode8  # noqa: E402

MITSUBA_VERSION = "3.9.1"
WIDTH, HEIGHT = 640, 480
WORK_WIDTH = 160  # rtloop-scene's default working width
SPP = 256
MAX_DEPTH = 4  # camera ray + three bounces: the environment's occlusion and interreflection
REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "tests" / "fixtures" / "onephoto"
#: The view that ships as the end-to-end example of docs/acquisition.md (written to EXAMPLE_DIR when --out is
#: the default).
EXAMPLE_VIEW = "oblique"
EXAMPLE_DIR = REPO / "examples" / "one-photo"

#: The board as rtloop-scene is told: 6x4 squares of 100 mm, markers 75 mm, DICT_5X5_100 (OpenCV >= 4.6).
BOARD = {"squares": [6, 4], "square_m": 0.1, "marker_m": 0.075, "dictionary": "DICT_5X5_100"}
BOARD_SPEC = "6x4,100mm,75mm,DICT_5X5_100"
PAPER, INK = 0.85, 0.04  # linear reflectances of the board's paper and of its black squares
TEXTURE_PX_PER_SQUARE = 64
BOARD_THICKNESS = 0.0005  # the board (with its paper) lies this far above the floor the ball rests on
BALL_RADIUS = 0.1
BALL_CENTRE = [0.56, BALL_RADIUS, 0.04]
BALL_ALBEDO = [0.72, 0.28, 0.14]
FLOOR_ALBEDO = [0.46, 0.42, 0.36]
CARD_REFLECTANCE = 0.18
CARD_CENTRE = [-0.02, 0.001, -0.43]  # in front of the board, towards the cameras
CARD_SIZE = [0.20, 0.15]  # x, z (metres)
LIGHT_POSITION = [-0.6, 2.3, -1.2]
LIGHT_INTENSITY = 6.0  # W/sr, white
ENVIRONMENT = [0.02, 0.02, 0.022]
#: A virtual sensor: 100 pixels per millimetre at 640x480 (6.4 x 4.8 mm), written as EXIF.
PX_PER_MM = 100.0

VIEWS: list[dict[str, Any]] = [
    {"name": "oblique", "description": "45 deg down from the front right, the usual handheld shot",
     "position": [0.6, 1.2, -1.3], "look_at": [0.12, 0.02, -0.08], "up": [0.0, 1.0, 0.0], "vfov_deg": 42.0},
    {"name": "side", "description": "from the front left, 35 deg down, a wider lens",
     "position": [-0.75, 0.9, -0.95], "look_at": [0.18, 0.03, -0.06], "up": [0.0, 1.0, 0.0], "vfov_deg": 50.0},
    {"name": "low", "description": "low and far (22 deg down), a longer lens: the board strongly foreshortened",
     "position": [0.8, 0.7, -1.8], "look_at": [0.12, 0.02, -0.06], "up": [0.0, 1.0, 0.0], "vfov_deg": 32.0},
    {"name": "frontal", "description": "nearly straight down (12 deg from the vertical): the board alone "
     "cannot fix the focal length",
     "position": [0.2, 1.6, -0.45], "look_at": [0.14, 0.0, -0.1], "up": [0.0, 0.0, 1.0], "vfov_deg": 46.0},
    {"name": "overhead", "description": "straight down (3 deg from the vertical) beside the board, a lower light "
     "from the back left: the ball's shadow long, on the floor away from the board",
     "position": [0.36, 1.7, 0.0], "look_at": [0.3, 0.0, -0.04], "up": [0.0, 0.0, 1.0], "vfov_deg": 44.0,
     "light": [-0.8, 1.7, 1.4]},
    {"name": "above", "description": "nearly straight down (12 deg) from the ball's front, the light high behind "
     "the camera: the ball's shadow peeks out behind it",
     "position": [0.62, 1.6, -0.42], "look_at": [0.28, 0.0, -0.06], "up": [0.0, 0.0, 1.0], "vfov_deg": 46.0,
     "light": [1.2, 2.3, -1.6]},
]


def _light(view: dict[str, Any]) -> list[float]:
    """The view's point light: LIGHT_POSITION unless the view moves it."""
    return list(view.get("light", LIGHT_POSITION))


def _mi():
    try:
        import mitsuba as mi
    except ImportError:
        sys.exit(f"make_onephoto.py: needs Mitsuba 3: pip install 'mitsuba=={MITSUBA_VERSION}'")
    mi.set_variant("scalar_rgb")
    return mi


def board_texture() -> np.ndarray:
    """Linear reflectance (rows, cols) of the printed board with a margin of one square, top row first."""
    cols, rows = BOARD["squares"]
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, BOARD["dictionary"]))
    board = cv2.aruco.CharucoBoard((cols, rows), BOARD["square_m"], BOARD["marker_m"], dictionary)
    s = TEXTURE_PX_PER_SQUARE
    img = board.generateImage((cols * s, rows * s), marginSize=0, borderBits=1)
    img = np.pad(img, s, constant_values=255)  # the paper margin
    return (INK + (PAPER - INK) * img.astype(np.float32) / 255.0).astype(np.float32)


def _rgb(v: list[float]) -> dict[str, Any]:
    return {"type": "rgb", "value": [float(c) for c in v]}


def _floor_rect(mi, centre: list[float], half_x: float, half_z: float) -> Any:
    """A rectangle in a horizontal plane: local x -> world +x, local y -> world +z, normal +y."""
    flip = mi.ScalarTransform4f(np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)
                                .tolist())  # (x, y, z) -> (x, z, y): normal +z -> -y, made two-sided
    return (mi.ScalarTransform4f().translate(centre) @ flip
            @ mi.ScalarTransform4f().scale([half_x, half_z, 1.0]))


def scene_dict(view: dict[str, Any], spp: int, seed: int) -> dict[str, Any]:
    mi = _mi()
    cols, rows = BOARD["squares"]
    sq = BOARD["square_m"]
    half = [(cols + 2) * sq / 2, (rows + 2) * sq / 2]
    tex = board_texture()
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_DEPTH},
        "sensor": {
            "type": "perspective", "fov": view["vfov_deg"], "fov_axis": "y", "near_clip": 0.01,
            "far_clip": 10000.0,
            "to_world": mi.ScalarTransform4f().look_at(origin=view["position"], target=view["look_at"],
                                                       up=view["up"]),
            "film": {"type": "hdrfilm", "width": WIDTH, "height": HEIGHT, "pixel_format": "rgb",
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "stratified", "sample_count": spp, "seed": seed, "jitter": True},
        },
        "light": {"type": "point", "position": _light(view), "intensity": _rgb([LIGHT_INTENSITY] * 3)},
        "environment": {"type": "constant", "radiance": _rgb(ENVIRONMENT)},
        "ball": {"type": "sphere", "center": BALL_CENTRE, "radius": BALL_RADIUS,
                 "bsdf": {"type": "diffuse", "reflectance": _rgb(BALL_ALBEDO)}},
        "floor": {"type": "rectangle", "to_world": _floor_rect(mi, [0.0, 0.0, 0.0], 1000.0, 1000.0),
                  "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": _rgb(FLOOR_ALBEDO)}}},
        # the board (with its paper) BOARD_THICKNESS above the floor, the card 1 mm
        "board": {"type": "rectangle", "to_world": _floor_rect(mi, [0.0, BOARD_THICKNESS, 0.0], *half),
                  "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {
                      "type": "bitmap", "bitmap": mi.Bitmap(tex[:, :, None]), "raw": True,
                      "filter_type": "bilinear", "wrap_mode": "clamp"}}}},
        "card": {"type": "rectangle", "to_world": _floor_rect(mi, CARD_CENTRE, CARD_SIZE[0] / 2, CARD_SIZE[1] / 2),
                 "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse",
                                                       "reflectance": _rgb([CARD_REFLECTANCE] * 3)}}},
    }


def project(view: dict[str, Any], points: np.ndarray) -> np.ndarray:
    """Pixel coordinates (x right, y down, pixel centres at +0.5) of world points, rtloop's camera model."""
    pos = np.asarray(view["position"], float)
    fwd = np.asarray(view["look_at"], float) - pos
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, view["up"])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    t = math.tan(math.radians(view["vfov_deg"]) / 2)
    d = np.asarray(points, float) - pos
    x = (d @ right) / (d @ fwd) / (t * WIDTH / HEIGHT)
    y = (d @ up) / (d @ fwd) / t
    return np.column_stack([(x + 1) * WIDTH / 2, (1 - y) * HEIGHT / 2])


def card_rect(view: dict[str, Any]) -> list[int]:
    """An axis-aligned pixel rectangle X,Y,W,H inside the card's image, 2 px in from its edges (as a user
    would draw it): grown from the card's centre one row or column at a time while it stays on the card."""
    cx, _, cz = CARD_CENTRE
    hx, hz = CARD_SIZE[0] / 2, CARD_SIZE[1] / 2
    quad = project(view, np.array([[cx - hx, 0, cz - hz], [cx + hx, 0, cz - hz], [cx + hx, 0, cz + hz],
                                   [cx - hx, 0, cz + hz]]))
    on = np.zeros((HEIGHT, WIDTH), np.uint8)
    cv2.fillPoly(on, [np.round((quad - 0.5) * 16).astype(np.int32)], 1, cv2.LINE_8, shift=4)
    on = cv2.erode(on, np.ones((5, 5), np.uint8)).astype(bool)
    c = project(view, np.array([[cx, 0, cz]]))[0]
    x0 = x1 = int(c[0])
    y0 = y1 = int(c[1])
    grown = True
    while grown:
        grown = False
        for side in range(4):
            nx0, nx1, ny0, ny1 = x0 - (side == 0), x1 + (side == 1), y0 - (side == 2), y1 + (side == 3)
            if on[ny0:ny1 + 1, nx0:nx1 + 1].all():
                x0, x1, y0, y1, grown = nx0, nx1, ny0, ny1, True
    return [x0, y0, x1 - x0 + 1, y1 - y0 + 1]


def truth_scene(view: dict[str, Any]) -> dict[str, Any]:
    """The truth in rtloop's format at the working size rtloop-scene writes (160 x 120)."""
    camera = {k: view[k] for k in ("position", "look_at", "up", "vfov_deg")}
    return {
        "image": {"width": WORK_WIDTH, "height": WORK_WIDTH * HEIGHT // WIDTH},
        "camera": camera,
        "light": {"position": _light(view), "intensity": LIGHT_INTENSITY, "color": [1.0, 1.0, 1.0]},
        "ambient": [0.0, 0.0, 0.0], "environment": ENVIRONMENT, "background": ENVIRONMENT, "exposure": 1.0,
        "objects": [
            {"name": "ball", "shape": "sphere", "center": BALL_CENTRE, "radius": BALL_RADIUS,
             "material": {"albedo": BALL_ALBEDO}},
            {"name": "floor", "shape": "plane", "point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0],
             "material": {"albedo": FLOOR_ALBEDO}},
        ],
    }


def exif_bytes(view: dict[str, Any]) -> bytes:
    """EXIF FocalLength (mm) and FocalPlaneXResolution (pixels per cm) of the view's field of view."""
    focal_px = HEIGHT / 2 / math.tan(math.radians(view["vfov_deg"]) / 2)
    exif = Image.Exif()
    ifd = exif.get_ifd(0x8769)
    ifd[0x920A] = round(focal_px / PX_PER_MM, 4)  # FocalLength, mm
    ifd[0xA20E] = PX_PER_MM * 10.0  # FocalPlaneXResolution
    ifd[0xA20F] = PX_PER_MM * 10.0  # FocalPlaneYResolution
    ifd[0xA210] = 3  # FocalPlaneResolutionUnit: centimetre
    return exif.tobytes()


def make_view(view: dict[str, Any], out: Path, spp: int, seed: int) -> dict[str, Any]:
    mi = _mi()
    t0 = time.perf_counter()
    linear = np.array(mi.render(mi.load_dict(scene_dict(view, spp, seed))), dtype=np.float64)
    seconds = time.perf_counter() - t0
    codes = encode8(linear)
    folder = EXAMPLE_DIR if out == DEFAULT_OUT and view["name"] == EXAMPLE_VIEW else out / view["name"]
    folder.mkdir(parents=True, exist_ok=True)
    Image.fromarray(codes, "RGB").save(folder / "photo.png", optimize=True, exif=exif_bytes(view))
    (folder / "scene.json").write_text(json.dumps(truth_scene(view), indent=2) + "\n")
    ball_px = project(view, np.array([BALL_CENTRE]))[0]
    meta = {
        "name": view["name"], "description": view["description"], "set": str(folder.relative_to(REPO)) if folder.is_relative_to(REPO) else str(folder),
        "generator": "tools/make_onephoto.py",
        "renderer": {"mitsuba": mi.__version__, "variant": "scalar_rgb", "integrator": "path",
                     "max_depth": MAX_DEPTH, "spp": spp, "seed": seed, "filter": "box",
                     "seconds": round(seconds, 1)},
        "photo": {"file": "photo.png", "size": [WIDTH, HEIGHT], "encoding": "sRGB OETF of clamp(x, 0, 1), 8 bit",
                  "exif": {"FocalLength_mm": round(HEIGHT / 2 / math.tan(math.radians(view["vfov_deg"]) / 2)
                                                   / PX_PER_MM, 4),
                           "FocalPlaneXResolution_px_per_cm": PX_PER_MM * 10}},
        "camera": {k: view[k] for k in ("position", "look_at", "up", "vfov_deg")},
        "ball": {"centre": BALL_CENTRE, "radius": BALL_RADIUS, "albedo": BALL_ALBEDO,
                 "centre_px": [round(float(v), 2) for v in ball_px],
                 "distance_from_camera_m": round(float(np.linalg.norm(np.subtract(BALL_CENTRE, view["position"]))), 4)},
        "light": {"type": "point", "position": _light(view), "intensity_w_sr": LIGHT_INTENSITY,
                  "distance_to_ball_m": round(float(np.linalg.norm(np.subtract(_light(view), BALL_CENTRE))), 3)},
        "environment_radiance": ENVIRONMENT,
        "floor_albedo": FLOOR_ALBEDO,
        "board": {**BOARD, "spec": BOARD_SPEC, "paper_margin_m": BOARD["square_m"],
                  "thickness_m": BOARD_THICKNESS, "paper_reflectance": PAPER,
                  "ink_reflectance": INK, "texture": "cv2.aruco.CharucoBoard.generateImage, borderBits 1"},
        "grey_card": {"reflectance": CARD_REFLECTANCE, "centre": CARD_CENTRE, "size_xz_m": CARD_SIZE,
                      "rect_px": card_rect(view)},
    }
    (folder / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    return meta


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="make_onephoto.py", description=__doc__.split("\n\n")[0],
        epilog="Example: nice -n 10 python tools/make_onephoto.py  (into tests/fixtures/onephoto; the oblique\n"
               "view, the documented example, into examples/one-photo)\n"
               "Views: " + ", ".join(v["name"] for v in VIEWS),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", action="append", metavar="NAME", help="render only this view (repeatable)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default %(default)s)")
    parser.add_argument("--spp", type=int, default=SPP, help="samples per pixel (default %(default)s)")
    args = parser.parse_args(argv)
    views = [v for v in VIEWS if not args.only or v["name"] in args.only]
    if args.only and len(views) != len(args.only):
        parser.error(f"unknown view; views: {', '.join(v['name'] for v in VIEWS)}")
    for view in views:
        meta = make_view(view, args.out, args.spp, seed=100 + VIEWS.index(view))
        print(f"{view['name']:8s} {meta['renderer']['seconds']:6.1f} s  card rect {meta['grey_card']['rect_px']}",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
