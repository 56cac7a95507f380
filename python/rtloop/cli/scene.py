"""``rtloop-scene``: a scene from a photo of a ball on a board, over :mod:`rtloop.acquisition`.
``scene_main(argv)`` returns the exit status (0 done, 1 bad input or failed step, 2 bad command line)."""

from __future__ import annotations

from .._interrupt import importing

with importing:  # a Ctrl-C while a console script starts: one line, exit 130
    import argparse
    import json
    import math
    import os
    import shlex
    import shutil
    import warnings
    from collections.abc import Sequence
    from pathlib import Path
    from typing import Any

    import numpy as np

    from .._files import OutputDirError, check_out_dir, move_into_place, recover_leftovers, staging_dir
    from ..acquisition._common import AcquisitionError, write_json, write_png8, write_png16_srgb
    from ..acquisition.boards import parse_board
    from ..acquisition.calibration import CameraIntrinsics
    from ..acquisition.exif import exif_exposure, exif_focal
    from ..errors import RtloopWarning
    from ..acquisition.response import load_photo
    from .acquire import DEFAULT_BOARD
    from .args import (
        BOARD_HELP, RESPONSE_HELP, Parser, choice, flag, float_in, formatter, info, length, length_or_zero,
        positive_float, positive_int, run_subcommands, triple
    )

__all__ = ["scene_main"]

SCENE_DESCRIPTION = """\
Build an rtloop scene from a photo of a ball on the floor with a ChArUco board lying
flat beside it, ready for 'rtloop-fit'.

From PHOTO it finds the board (camera position and orientation, and the floor: the
board's face is the plane y = 0; metres, +y up, origin at the board's centre), then the
ball (searched as a ball of --ball-radius resting on that floor, its outline fitted to
a fraction of a pixel), and writes the scene: camera, floor plane, sphere, a first guess
of the light, and a "fit" section (light position and intensity, the two albedos) with
bounds scaled to the scene.

The camera: --camera (a calibration: the photo is undistorted and its principal point
re-centred, since the scene's camera is an ideal pinhole) is best; --vfov (the vertical
field of view of a photo without noticeable distortion) is next; with neither, the
photo's EXIF focal length, else the board's estimate (less accurate: looser than
+-0.3 deg in the field of view it is refined from the ball resting on the floor, the
field of view at which a resting ball's outline fits the photo best, and used with a
warning giving the board's spread and the distances', or refused with --strict).

Colour: --grey-card X,Y,W,H (a neutral card's rectangle in PHOTO) white-balances, and
--colorchecker finds a ColorChecker Classic (needs OpenCV contrib's cv2.mcc) for a full
colour correction; either is measured in PHOTO and applied in linear light.

Put the ball beside the board, not on it (the board's pattern is full of edges, and the
ball is searched for off the board), lit so that its outline stands out from the floor;
if it is not found, give --ball X,Y,R or --ball-mask. The board (with its paper) and the
card are part of the floor in the photo but not in the scene: with no --objective they
are left out of the fit (mask.png), so one photo serves for both; or pass a second photo
with them removed, camera and light untouched, as --objective. The fit does not move the
sphere (centres are not fittable): check overlay.png that it lines up.

With --grey-card-reflectance R (the card's known reflectance) rtloop-fit reports
absolute albedos and the light's intensity in W/sr. The scene has a room's dim light
from every direction (the environment, fitted) and the bounce between the ball and the
floor (--direct-only: neither).
"""

SCENE_EPILOG = """\
files written into DIR:
  scene.json      the scene (README format) with a "fit" section, and "meta.acquisition":
                  the board's reprojection error, the ball's fit, the colour correction,
                  warnings
  objective.png   the photo to fit (--objective, else PHOTO) after colour correction and
                  undistortion, as a 16-bit sRGB PNG (rtloop-fit reads it as it is)
  overlay.png     PHOTO with the board's corners, outline and axes (x red, y up green,
                  z blue), the ball's edge points (red) and fitted outline (cyan), and
                  the ball as rtloop renders the new scene (dashed magenta): check that
                  they line up
  photo.png       PHOTO after the same corrections (what the geometry was measured on)
  mask.png        with no --objective: black on the board, its paper and the colour target
                  (rtloop-fit leaves them out)
  card.png        with --grey-card-reflectance: white inside the card (rtloop-fit measures
                  the absolute albedos there)

example:
  rtloop-scene scene.png --board board.json --camera camera.json --ball-radius 33.5mm \\
      --objective scene-without-board.png --grey-card 1200,800,60,40 --out myscene
  rtloop-fit myscene/scene.json myscene/objective.png --out myscene/fit

exit status: 0 done, 1 bad input or a step failed (the message says what to do),
2 bad command line.
"""


def _build_scene_parser() -> Parser:
    p = Parser(
        prog="rtloop-scene", description=SCENE_DESCRIPTION, epilog=SCENE_EPILOG, formatter_class=formatter()
    )
    p.add_argument("photo", metavar="PHOTO", help="the photo: the board flat on the floor, and the ball")
    p.add_argument("--board", default=DEFAULT_BOARD, help=BOARD_HELP + f" (default {DEFAULT_BOARD})")
    p.add_argument(
        "--ball-radius",
        type=length,
        required=True,
        metavar="LENGTH",
        help="the ball's radius: metres, or with mm/cm (measure the circumference and divide by 2 pi)",
    )
    p.add_argument("--out", "-o", required=True, metavar="DIR", help="output directory (created)")
    flag(p, "--force", "replace DIR if it exists and is not empty")
    _add_camera_args(p)
    _add_photos_args(p)
    _add_colour_args(p)
    _add_ball_args(p)
    _add_scene_args(p)
    p.add_argument(
        "--truth",
        metavar="SCENE.json",
        help="the true scene (a rendered example's scene.json): print the errors of the camera, the field "
        "of view and the ball against it",
    )
    p.set_defaults(handler=_cmd_scene)
    return p


def _add_camera_args(p: Parser) -> None:
    """The camera's options: a calibration or the field of view, and how strictly the board may fix it."""
    g = p.add_argument_group("camera")
    cam = g.add_mutually_exclusive_group()
    cam.add_argument("--camera", metavar="CAMERA.json", help="calibration from 'rtloop-acquire calibrate'")
    cam.add_argument(
        "--vfov",
        type=positive_float,
        metavar="DEG",
        help="vertical field of view of a distortion-free photo, in degrees (default: from the photo's EXIF focal "
        "length, else from the board when it is seen at enough of an angle)",
    )
    choice(g, "--lens-profile", ("auto", "off"),
           "'auto' (default): where the photo's EXIF names its camera, lens and focal length and Lensfun's "
           "database has that lens, remove its distortion and vignetting before the board and the ball are "
           "measured (not with --camera or --vfov); 'off': take the photo as a pinhole's")
    flag(g, "--strict",
         "without EXIF, --vfov or --camera: refuse a board that fixes the vertical field of view more "
         "loosely than +-0.3 deg (default: use it and warn with its spread)")


def _add_photos_args(p: Parser) -> None:
    """The photos' options: the photo to fit, and how to read the photos."""
    g = p.add_argument_group("photos")
    g.add_argument(
        "--objective",
        metavar="PHOTO2",
        help="the photo to fit, from the same camera position and settings (e.g. the board removed); "
        "default PHOTO",
    )
    g.add_argument("--response", default="srgb", help=RESPONSE_HELP)
    g.add_argument(
        "--black-level",
        type=float,
        default=0.0,
        metavar="CODE",
        help="raw data: the code value of black (in the file's integer scale)",
    )
    g.add_argument(
        "--white-level",
        type=float,
        metavar="CODE",
        help="raw data: the code value of saturation (e.g. 4095 for 12-bit data in a 16-bit TIFF)",
    )


def _add_colour_args(p: Parser) -> None:
    """The colour options: a grey card (and its reflectance) or a ColorChecker."""
    g = p.add_argument_group("colour")
    col = g.add_mutually_exclusive_group()
    col.add_argument(
        "--grey-card", metavar="X,Y,W,H", help="white balance from a neutral card at this rectangle of PHOTO"
    )
    flag(col, "--colorchecker",
         "colour correction from a ColorChecker Classic in PHOTO (OpenCV contrib's cv2.mcc)")
    g.add_argument(
        "--grey-card-reflectance",
        type=float_in(0.0, 1.0, True, "a reflectance in (0, 1], e.g. 0.18"),
        metavar="R",
        help="the grey card's known reflectance (0.18 for an 18 %% card): with the card in the photo to fit, "
        "rtloop-fit then reports absolute albedos and the light's intensity in W/sr (card.png, "
        "meta.acquisition.grey_card)",
    )


def _add_ball_args(p: Parser) -> None:
    """The ball's options: where to look for it, whether it rests on the floor, the board's margin, the names."""
    g = p.add_argument_group("ball")
    g.add_argument(
        "--ball",
        type=triple,
        metavar="X,Y,R",
        help="where the ball is in PHOTO (centre and radius in pixels, roughly), if it is not found",
    )
    g.add_argument(
        "--ball-mask", metavar="MASK.png", help="an image of PHOTO's size, white on the ball, black elsewhere"
    )
    flag(g, "--ball-free",
         "do not assume the ball rests on the floor: fit its centre's height too (less precise)")
    g.add_argument(
        "--board-margin",
        type=float,
        default=None,
        metavar="M",
        help="the white paper around the board's squares, metres (default one square); with no --objective "
        "the board, this margin and the colour target are written to mask.png and left out of the fit",
    )
    g.add_argument(
        "--board-thickness",
        type=length_or_zero,
        default=0.0,
        metavar="LENGTH",
        help="how far the board's face lies above the floor the ball rests on: metres, or with mm/cm "
        "(default 0; a board on card or foam: its thickness; without EXIF a millimetre moves the field of "
        "view refined from the ball by up to half a degree)",
    )
    g.add_argument("--ball-name", default="ball", help="the sphere's name in the scene (default ball)")
    g.add_argument("--floor-name", default="floor", help="the plane's name in the scene (default floor)")


def _add_scene_args(p: Parser) -> None:
    """The scene's options: its width, the light's search box, and the room's light."""
    g = p.add_argument_group("scene")
    g.add_argument(
        "--width",
        type=positive_int,
        default=160,
        help="the scene's working width in pixels, the height following the photo (default 160)",
    )
    g.add_argument(
        "--light-range",
        type=positive_float,
        default=2.0,
        metavar="FACTOR",
        help="the light's search box, in units of the camera's distance to the ball (default 2)",
    )
    flag(g, "--direct-only",
         "a scene of direct light only; by default it also has what a room shows: a dim light from "
         "every direction (the environment, free in the fit section) and light bouncing between the ball "
         "and the floor (\"interreflection\": true)")


def scene_main(argv: Sequence[str] | None = None) -> int:
    """``rtloop-scene``: build a scene JSON (and objective, overlay) from a photo. Returns the exit status."""
    return run_subcommands(_build_scene_parser, argv, "rtloop-scene")


def _cmd_scene(args: argparse.Namespace) -> int:
    from ..acquisition.build import build_scene

    out = Path(args.out)
    inputs = [Path(p) for p in (args.photo, args.objective, args.camera, args.truth) if p]
    try:  # never the working directory or one above it, nor with --force a DIR holding an input
        check_out_dir(out, args.force, inputs)
    except OutputDirError as e:
        raise AcquisitionError(str(e)) from None
    photo, objective, intrinsics, exif, mask = _load_inputs(args)
    lens = _lens_profile(args) if exif is not None and args.lens_profile == "auto" else None
    colour: Any = "colorchecker" if args.colorchecker else args.grey_card
    acq = build_scene(
        photo,
        args.board,
        args.ball_radius,
        intrinsics=intrinsics,
        vfov_deg=args.vfov,
        exif=exif,
        lens=lens,
        objective=objective,
        colour=colour,
        ball_hint=args.ball,
        ball_mask=mask,
        resting=not args.ball_free,
        width=args.width,
        light_range=args.light_range,
        room=not args.direct_only,
        names=(args.ball_name, args.floor_name),
        board_margin=args.board_margin,
        board_thickness=args.board_thickness,
        card_reflectance=args.grey_card_reflectance,
        where=args.photo,
        objective_where=args.objective or args.photo,
        strict=args.strict,
    )
    _record_inputs(acq, args)
    _write_outputs(out, acq)
    _print_summary(out, acq, args)
    return 0


def _load_inputs(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray | None, CameraIntrinsics | None, Any,
                                                   np.ndarray | None]:
    """The photo, the objective, the calibration, the photo's EXIF focal length (without --camera or --vfov;
    its warnings printed) and the ball's mask, as the arguments give them."""
    load = {"response": args.response, "black_level": args.black_level, "white_level": args.white_level}
    photo = load_photo(args.photo, **load)
    objective = load_photo(args.objective, **load) if args.objective else None
    intrinsics = CameraIntrinsics.load(args.camera) if args.camera else None
    exif = None
    if intrinsics is None and args.vfov is None:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RtloopWarning)
            exif = exif_focal(args.photo, photo.shape[1], photo.shape[0])
        for w in caught:
            info(f"rtloop-scene: warning: {' '.join(str(w.message).split())}")
    mask = None
    if args.ball_mask:
        m = load_photo(args.ball_mask, response="linear")
        mask = m.max(axis=2) > 0.5
    return photo, objective, intrinsics, exif, mask


def _lens_profile(args: argparse.Namespace) -> Any:
    """The profile of the lens the photo's EXIF names (:mod:`rtloop.acquisition.lens_profile`), or None,
    with a line saying why not when the EXIF names a camera."""
    from ..acquisition.lens_profile import find_lens_profile, read_lens_exif

    named = read_lens_exif(args.photo)
    lens, why = find_lens_profile(named)
    if lens is None and named is not None:
        info(f"rtloop-scene: no lens profile ({why}): the photo is taken as a pinhole's; give --camera "
             "(rtloop-acquire calibrate) if its lens distorts")
    return lens


def _record_inputs(acq: Any, args: argparse.Namespace) -> None:
    """Record the inputs (and the photo's EXIF exposure) in the scene's ``meta.acquisition``, and the mask
    files beside it."""
    acq.scene["meta"]["acquisition"]["inputs"] = {
        "photo": os.path.abspath(args.photo),
        "objective": os.path.abspath(args.objective) if args.objective else None,
        "camera": os.path.abspath(args.camera) if args.camera else None,
        "board": parse_board(args.board).to_dict(),
        "response": args.response,
        # the photo's EXIF exposure (time, f-number, ISO, EV at ISO 100), to compare photos' linear values
        "exposure": exif_exposure(args.photo),
    }
    if acq.mask is not None:  # rtloop-fit finds it beside scene.json and uses it unless given --mask
        acq.scene["meta"]["acquisition"]["mask"] = "mask.png"
    if acq.card is not None:  # and the card's pixels, where it measures the absolute albedos
        acq.scene["meta"]["acquisition"]["grey_card"]["mask"] = "card.png"


def _write_outputs(out: Path, acq: Any) -> None:
    """Write scene.json, the photos, the overlay and the masks into a staging folder, then move it to
    ``out``; the staging folder is removed on any failure."""
    recover_leftovers(out)  # what killed runs left beside OUT
    tmp = staging_dir(out, "rtloop-scene")
    try:
        write_json(tmp / "scene.json", acq.scene)
        write_png16_srgb(tmp / "objective.png", acq.objective)
        write_png16_srgb(tmp / "photo.png", acq.photo)
        write_png8(tmp / "overlay.png", acq.overlay)
        if acq.mask is not None:
            write_png8(tmp / "mask.png", np.where(acq.mask, 255, 0).astype(np.uint8))
        if acq.card is not None:
            write_png8(tmp / "card.png", np.where(acq.card, 255, 0).astype(np.uint8))
        move_into_place(tmp, out, out.exists(), "rtloop-scene")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _print_summary(out: Path, acq: Any, args: argparse.Namespace) -> None:
    """Print the warnings, what was written, the camera, the ball, the colour, the errors against
    --truth, and the command to fit."""
    cam = acq.scene["camera"]
    ball = acq.scene["objects"][0]
    rep = acq.scene["meta"]["acquisition"]
    for note in acq.warnings:
        info(f"warning: {note}")
    extra = (", mask.png" if acq.mask is not None else "") + (", card.png" if acq.card is not None else "")
    print(f"wrote {out}/scene.json, objective.png, overlay.png, photo.png{extra}")
    if acq.mask is not None:
        print(f"  mask.png leaves the board and colour target ({1 - acq.mask.mean():.1%} of the photo) out of the fit")
    print(
        f"  camera at ({', '.join(f'{v:.3f}' for v in cam['position'])}) m, vertical field of view "
        f"{cam['vfov_deg']:.2f} deg ({rep['camera_model']}); board reprojection "
        f"{rep['pose']['reprojection_rms_px']:.2f} px RMS over {rep['pose']['corners']} corners"
    )
    print(
        f"  ball '{ball['name']}' at ({', '.join(f'{v:.3f}' for v in ball['center'])}) m, radius "
        f"{ball['radius']:g} m; "
        f"outline fit {rep['ball']['rms_px']:.2f} px RMS over {rep['ball']['edge_points']} edge points"
    )
    if "lens_profile" in rep:
        lp = rep["lens_profile"]
        done = " and ".join(k for k in ("distortion", "vignetting") if lp[k]) or "nothing"
        print(f"  lens: {lp['lens']} at {lp['focal_mm']:g} mm; its profile ({lp['source']}) removed {done}")
    print(f"  colour: {rep['colour']['source']}")
    if args.truth:
        for line in truth_lines(acq.scene, args.truth):
            print(f"  {line}")
    print("check overlay.png, then fit:")
    print(
        f"  rtloop-fit {shlex.quote(str(out / 'scene.json'))} {shlex.quote(str(out / 'objective.png'))} "
        f"--out {shlex.quote(str(out / 'fit'))}"
    )


def truth_lines(scene: dict[str, Any], truth_path: str) -> list[str]:
    """The scene's errors against the true scene at ``truth_path``: camera position, viewing direction,
    field of view, and each sphere's centre (also as a fraction of its distance from the camera)."""
    try:
        truth = json.loads(Path(truth_path).read_text())
        cam_t = truth["camera"]
        spheres_t = {o.get("name"): o for o in truth["objects"] if o.get("shape") == "sphere"}
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        raise AcquisitionError(f"--truth {truth_path}: not a scene JSON with a camera and objects ({e})") from None
    cam = scene["camera"]
    pos, pos_t = np.array(cam["position"], float), np.array(cam_t["position"], float)
    fwd = np.array(cam["look_at"], float) - pos
    fwd_t = np.array(cam_t["look_at"], float) - pos_t
    angle = math.degrees(math.acos(float(np.clip(fwd @ fwd_t / np.linalg.norm(fwd) / np.linalg.norm(fwd_t), -1, 1))))
    head = (f"against {truth_path}: camera {1000 * np.linalg.norm(pos - pos_t):.1f} mm and {angle:.3f} deg off, "
            f"field of view {cam['vfov_deg'] - cam_t['vfov_deg']:+.3f} deg")
    lines = [head]
    for o in scene["objects"]:
        t = spheres_t.get(o["name"])
        if o["shape"] == "sphere" and t is not None:
            err = float(np.linalg.norm(np.subtract(o["center"], t["center"])))
            dist = float(np.linalg.norm(np.subtract(t["center"], pos_t)))
            lines.append(f"{o['name']} {1000 * err:.1f} mm off ({100 * err / dist:.2f} % of its {dist:.2f} m distance)")
    return lines
