"""Command lines: ``rtloop-acquire`` (board, capture, calibrate, undistort) and ``rtloop-scene``.

Both are thin layers over the functions of :mod:`rtloop.acquisition`; ``main(argv)`` functions return
the exit status (0 done, 1 bad input or failed step, 2 bad command line) so they can be called and
tested without a subprocess.
"""

from __future__ import annotations

import argparse
import io
import math
import os
import shlex
import shutil
import sys
import textwrap
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from PIL import Image

from .._files import move_into_place, staging_dir, write_bytes
from ..errors import RtloopError
from . import capture as capture_module
from ._common import AcquisitionError, write_json, write_png8, write_png16_srgb
from .boards import DEFAULT_DICTIONARY, board_image, parse_board
from .calibration import CameraIntrinsics, calibrate_camera, undistort_to_pinhole
from .response import load_photo

__all__ = ["acquire_main", "scene_main"]

DEFAULT_BOARD = f"7x5,40mm,30mm,{DEFAULT_DICTIONARY}"

BOARD_HELP = (
    "the ChArUco board: a JSON file written by 'rtloop-acquire board', or COLSxROWS,SQUARE,MARKER[,DICT] "
    "with lengths in metres or with mm/cm (e.g. 7x5,40mm,30mm,DICT_5X5_100: 7 squares across, 5 down, "
    "40 mm squares, 30 mm markers). Measure the printed square: printers scale."
)
RESPONSE_HELP = (
    "how the photo's stored values relate to light: srgb (default: camera JPEG/PNG), linear (raw sensor "
    "data, e.g. a 16-bit TIFF from dcraw -4 -T), gamma:G (linear = value^G), or a table file (CSV "
    'CODE,LINEAR or CODE,R,G,B per line, or JSON {"codes": [...], "linear": [...]})'
)


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{self.prog}: error: {message}")


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {v}")
    return v


def _nonneg_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {v}")
    return v


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text}")
    return v


def _length(text: str) -> float:
    t = text.strip().lower()
    scale = 1.0
    for suffix, s in (("mm", 1e-3), ("cm", 1e-2), ("m", 1.0)):
        if t.endswith(suffix):
            t, scale = t[: -len(suffix)], s
            break
    try:
        v = float(t) * scale
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a length such as 0.0335, 33.5mm or 3.35cm, got {text!r}"
        ) from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a length > 0, got {text!r}")
    return v


def _triple(text: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"expected X,Y,R in pixels, got {text!r}")
    return vals  # type: ignore[return-value]


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 1920x1080, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"expected a positive size, got {text!r}")
    return w, h


def _fmt(parser_class=argparse.RawDescriptionHelpFormatter):
    return lambda prog: parser_class(prog, max_help_position=32, width=100)


def _run(build, argv: Sequence[str] | None, prog: str) -> int:
    parser = build()
    try:
        args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    except _UsageError as exc:
        print(exc, file=sys.stderr)
        print(f"run '{prog} --help' for the options", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    if getattr(args, "handler", None) is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # e.g. enlarging a small photo: reported otherwise
            return int(args.handler(args) or 0)
    except (RtloopError, ValueError) as exc:
        message = " ".join(str(exc).split())
        print(f"{prog}: error: {message}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130


def _info(text: str) -> None:
    print(text, file=sys.stderr)


# --- rtloop-acquire -------------------------------------------------------------------------------------

ACQUIRE_DESCRIPTION = """\
Acquisition for rtloop: get a real scene's photo and camera ready for 'rtloop-scene'
and 'rtloop-fit'.

  board      write a printable ChArUco board (PNG at a given DPI, plus board.json)
  capture    take a low-noise photo from a camera: warm up, lock exposure and white
             balance where the camera allows (and say when it does not), average N
             frames, save a 16-bit PNG and a JSON of the settings
  calibrate  measure the camera (focal length, principal point, lens distortion)
             from 10-20 photos of the board from different angles
  undistort  write a photo as the ideal pinhole camera the scene format describes

A session:
  rtloop-acquire board --board 7x5,40mm,30mm --out board.png      # print it at 100%
  rtloop-acquire capture --device 0 --out calib/01.png            # ... 15 views of the board
  rtloop-acquire calibrate calib/*.png --board board.json --out camera.json
  rtloop-acquire capture --device 0 --out scene.png               # board on the floor + ball
  rtloop-scene scene.png --board board.json --camera camera.json --ball-radius 0.033 --out scene
  rtloop-fit scene/scene.json scene/objective.png --out scene/fit

Run 'rtloop-acquire COMMAND --help' for each command's options.
"""


def _build_acquire_parser() -> _Parser:
    p = _Parser(prog="rtloop-acquire", description=ACQUIRE_DESCRIPTION, formatter_class=_fmt())
    sub = p.add_subparsers(title="commands", metavar="COMMAND")

    b = sub.add_parser(
        "board",
        help="write a printable ChArUco board",
        formatter_class=_fmt(),
        description=textwrap.dedent("""\
            Write a ChArUco board as a PNG to print, and its description as JSON (same name,
            .json) for --board of the other commands. Print at 100% scale ("actual size"),
            glue it flat to something rigid, then measure a square with a ruler: if it is
            not exactly the size asked for, put the measured size (in metres) into the JSON's
            "square_m" and scale "marker_m" the same way."""),
    )
    b.add_argument("--board", default=DEFAULT_BOARD, help=BOARD_HELP + f" (default {DEFAULT_BOARD})")
    b.add_argument("--dpi", type=_positive_int, default=300, help="printer resolution (default 300)")
    b.add_argument(
        "--margin",
        type=_length,
        default=0.01,
        metavar="LENGTH",
        help="white margin around the board (default 10mm)",
    )
    b.add_argument("--out", "-o", required=True, metavar="BOARD.png", help="the image to write")
    b.set_defaults(handler=_cmd_board)

    c = sub.add_parser(
        "capture",
        help="take an averaged 16-bit photo from a camera",
        formatter_class=_fmt(),
        description=textwrap.dedent("""\
            Capture a photo through OpenCV's VideoCapture: read --warmup frames so automatic
            exposure and white balance settle, lock both at the settled values (or at
            --exposure / --wb-temperature), average --frames frames (noise falls as 1/sqrt(N);
            keep the scene still), and write a 16-bit PNG plus OUT.json with every setting and
            whether each lock took. Locking depends on the camera and backend: the JSON and the
            warnings say 'locked', 'requested' (not confirmed) or 'unsupported'. The PNG keeps
            the camera's encoding (load it with --response srgb, the default, for webcams)."""),
        epilog="example:\n  rtloop-acquire capture --device 0 --size 1920x1080 --frames 32 --out scene.png",
    )
    c.add_argument(
        "--device",
        default="0",
        help="camera index (0 = first camera) or a video file / stream URL (default 0)",
    )
    c.add_argument(
        "--backend",
        choices=sorted(capture_module.BACKENDS),
        default="any",
        help="OpenCV capture backend (default any)",
    )
    c.add_argument("--size", type=_size, metavar="WxH", help="ask the camera for this resolution")
    c.add_argument("--frames", type=_positive_int, default=16, help="frames to average (default 16)")
    c.add_argument("--warmup", type=_nonneg_int, default=10, help="frames dropped first (default 10)")
    c.add_argument(
        "--exposure",
        type=float,
        metavar="VALUE",
        help="manual exposure in the backend's units (V4L2: 100 us steps; DirectShow/MSMF: log2 "
        "seconds, e.g. -6 = 1/64 s); default: keep the settled automatic exposure",
    )
    c.add_argument(
        "--no-lock-exposure", dest="lock_exposure", action="store_false", help="leave automatic exposure on"
    )
    c.add_argument(
        "--wb-temperature",
        type=_positive_float,
        metavar="KELVIN",
        help="manual white balance temperature; default: keep the settled automatic balance",
    )
    c.add_argument(
        "--no-lock-white-balance",
        dest="lock_wb",
        action="store_false",
        help="leave automatic white balance on",
    )
    c.add_argument("--out", "-o", required=True, metavar="PHOTO.png", help="the 16-bit PNG to write")
    c.set_defaults(handler=_cmd_capture)

    k = sub.add_parser(
        "calibrate",
        help="measure the camera from photos of a board",
        formatter_class=_fmt(),
        description=textwrap.dedent("""\
            Calibrate the camera (cv2.calibrateCamera) from several photos of a ChArUco board or
            a chessboard: focal lengths, principal point, radial and tangential distortion. Use
            the same camera, zoom, focus and resolution as for the scene photo. Take 10 to 20
            photos from different angles (tilted up to about 45 degrees), the board covering a
            good part of the frame and, across the set, reaching every corner. Photos in which
            the board is not found are skipped (and listed); at least 3 must remain. A good
            calibration has an RMS reprojection error below about 0.5 px."""),
        epilog=(
            "example:\n  rtloop-acquire calibrate calib/*.png --board board.json --out camera.json\n"
            "  rtloop-acquire calibrate shots/*.jpg --board chess:10x7,25mm --out camera.json"
        ),
    )
    k.add_argument("photos", nargs="+", metavar="PHOTO", help="photos of the board")
    k.add_argument(
        "--board",
        default=DEFAULT_BOARD,
        help=BOARD_HELP + " A plain chessboard: chess:COLSxROWS,SQUARE (squares, not inner corners).",
    )
    k.add_argument("--response", default="srgb", help=RESPONSE_HELP)
    k.add_argument(
        "--k3", action="store_true", help="also fit the third radial coefficient (wide-angle lenses)"
    )
    k.add_argument(
        "--zero-tangent", action="store_true", help="assume no tangential distortion (p1 = p2 = 0)"
    )
    k.add_argument("--out", "-o", required=True, metavar="CAMERA.json", help="the calibration to write")
    k.set_defaults(handler=_cmd_calibrate)

    u = sub.add_parser(
        "undistort",
        help="resample a photo into the scene's ideal pinhole camera",
        formatter_class=_fmt(),
        description=textwrap.dedent("""\
            Remove the lens distortion, make the pixels square and move the principal point to the
            centre, so the photo is what the scene format's camera sees; prints its vertical field
            of view. Writes a 16-bit sRGB PNG (read by rtloop with the default --response srgb).
            rtloop-scene does this itself when given --camera."""),
    )
    u.add_argument("photo", metavar="PHOTO")
    u.add_argument("--camera", required=True, metavar="CAMERA.json", help="from 'rtloop-acquire calibrate'")
    u.add_argument("--response", default="srgb", help=RESPONSE_HELP)
    u.add_argument("--out", "-o", required=True, metavar="OUT.png")
    u.set_defaults(handler=_cmd_undistort)
    return p


def acquire_main(argv: Sequence[str] | None = None) -> int:
    """``rtloop-acquire``: board, capture, calibrate, undistort. Returns the exit status."""
    return _run(_build_acquire_parser, argv, "rtloop-acquire")


def _cmd_board(args: argparse.Namespace) -> int:
    spec = parse_board(args.board)
    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise AcquisitionError(f"{out}: the board is written as PNG; give a name ending in .png")
    px_per_square = max(20, round(spec.square_m / 0.0254 * args.dpi))
    margin_px = round(args.margin / 0.0254 * args.dpi)
    image = board_image(spec, px_per_square, margin_px)
    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="PNG", dpi=(args.dpi, args.dpi))
    write_bytes(out, buf.getvalue(), parents=True)
    spec_path = out.with_suffix(".json")
    actual_square = px_per_square / args.dpi * 0.0254
    write_json(
        spec_path,
        {"board": spec.to_dict(), "image": out.name, "dpi": args.dpi, "printed_square_m": actual_square},
    )
    w_mm = image.shape[1] / args.dpi * 25.4
    h_mm = image.shape[0] / args.dpi * 25.4
    print(
        f"wrote {out} ({image.shape[1]}x{image.shape[0]} px = {w_mm:.0f} x {h_mm:.0f} mm at {args.dpi} dpi) "
        f"and {spec_path}"
    )
    print(f"board: {spec.describe()}")
    if abs(actual_square - spec.square_m) > 1e-4:
        print(f"note: at {args.dpi} dpi a square prints as {actual_square * 1000:.2f} mm; measure the print")
    print("print at 100% ('actual size'), measure a square, and correct square_m in the JSON if it differs")
    return 0


def _cmd_capture(args: argparse.Namespace) -> int:
    device: int | str = int(args.device) if args.device.isdigit() else args.device
    width, height = args.size if args.size else (None, None)
    source = capture_module.open_camera(device, args.backend, width, height)
    try:
        result = capture_module.capture_photo(
            source,
            frames=args.frames,
            warmup=args.warmup,
            lock_exposure=args.lock_exposure,
            exposure=args.exposure,
            lock_white_balance=args.lock_wb,
            wb_temperature=args.wb_temperature,
            log=_info,
            device=device,
        )
    finally:
        source.release()
    png, report = capture_module.save_capture(result, args.out)
    s = result.settings
    locks = ", ".join(f"{k.replace('_', ' ')} {v['state']}" for k, v in s["locks"].items())
    print(
        f"wrote {png} ({s['frame']['width']}x{s['frame']['height']}, mean of {s['frames_averaged']} frames, "
        f"16-bit) and {report}"
    )
    print(f"locks: {locks}")
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    spec = parse_board(args.board)
    images = (load_photo(p, response=args.response) for p in args.photos)
    skipped: list[str] = []
    intr = calibrate_camera(
        images,
        spec,
        names=args.photos,
        fix_k3=not args.k3,
        zero_tangent=args.zero_tangent,
        on_skip=lambda name, msg: (skipped.append(name), _info(f"skipped: {msg}")),
    )
    intr.save(args.out)
    fx, fy = intr.focal_px
    cx, cy = intr.principal_point
    d = intr.to_dict()
    print(
        f"wrote {args.out}: {len(intr.views)} of {len(args.photos)} photos used, RMS reprojection error "
        f"{intr.rms_px:.3f} px"
    )
    print(f"  focal length fx {fx:.2f} px, fy {fy:.2f} px (vertical field of view {d['vfov_deg']:.2f} deg)")
    print(
        f"  principal point ({cx:.1f}, {cy:.1f}); image centre ({(intr.image_size[0] - 1) / 2:.1f}, "
        f"{(intr.image_size[1] - 1) / 2:.1f})"
    )
    print("  distortion k1 k2 p1 p2 k3: " + " ".join(f"{v:.5f}" for v in d["dist_coeffs"][:5]))
    worst = int(np.argmax(intr.per_view_rms_px))
    print(f"  worst photo: {intr.views[worst]} ({intr.per_view_rms_px[worst]:.3f} px)")
    if intr.rms_px > 1.0:
        _info(
            "warning: the RMS error is above 1 px: drop blurred photos (see the per-photo errors in the "
            "JSON), "
            "check --board, and make sure the board is flat"
        )
    if len(intr.views) < 8:
        _info(
            f"warning: only {len(intr.views)} photos used; 10 to 20 from varied angles give a steadier "
            "calibration"
        )
    return 0


def _cmd_undistort(args: argparse.Namespace) -> int:
    intr = CameraIntrinsics.load(args.camera)
    photo = load_photo(args.photo, response=args.response)
    out, focal = undistort_to_pinhole(photo, intr, where=args.photo)
    write_png16_srgb(args.out, out)
    h = out.shape[0]
    vfov = math.degrees(2 * math.atan(h / 2 / focal))
    print(
        f"wrote {args.out}: pinhole camera, focal length {focal:.2f} px, vertical field of view {vfov:.3f} "
        "deg"
    )
    return 0


# --- rtloop-scene ---------------------------------------------------------------------------------------

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
field of view of a photo without noticeable distortion) is next; with neither the focal
length is estimated from the board (less accurate).

Colour: --grey-card X,Y,W,H (a neutral card's rectangle in PHOTO) white-balances, and
--colorchecker finds a ColorChecker Classic (needs OpenCV contrib's cv2.mcc) for a full
colour correction; either is measured in PHOTO and applied in linear light.

Put the ball beside the board, not on it (the board's pattern is full of edges, and the
ball is searched for off the board), lit so that its outline stands out from the floor;
if it is not found, give --ball X,Y,R or --ball-mask. The board is part of the floor in
the photo but not in the scene; for the fit, take a second photo with the board (and
card) removed, camera and light untouched, and pass it as --objective. The fit does not
move the sphere (centres are not fittable): check overlay.png that it lines up.
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

example:
  rtloop-scene scene.png --board board.json --camera camera.json --ball-radius 33.5mm \\
      --objective scene-without-board.png --grey-card 1200,800,60,40 --out myscene
  rtloop-fit myscene/scene.json myscene/objective.png --out myscene/fit

exit status: 0 done, 1 bad input or a step failed (the message says what to do),
2 bad command line.
"""


def _build_scene_parser() -> _Parser:
    p = _Parser(
        prog="rtloop-scene", description=SCENE_DESCRIPTION, epilog=SCENE_EPILOG, formatter_class=_fmt()
    )
    p.add_argument("photo", metavar="PHOTO", help="the photo: the board flat on the floor, and the ball")
    p.add_argument("--board", default=DEFAULT_BOARD, help=BOARD_HELP + f" (default {DEFAULT_BOARD})")
    p.add_argument(
        "--ball-radius",
        type=_length,
        required=True,
        metavar="LENGTH",
        help="the ball's radius: metres, or with mm/cm (measure the circumference and divide by 2 pi)",
    )
    p.add_argument("--out", "-o", required=True, metavar="DIR", help="output directory (created)")
    p.add_argument("--force", action="store_true", help="replace DIR if it exists and is not empty")
    g = p.add_argument_group("camera")
    cam = g.add_mutually_exclusive_group()
    cam.add_argument("--camera", metavar="CAMERA.json", help="calibration from 'rtloop-acquire calibrate'")
    cam.add_argument(
        "--vfov",
        type=_positive_float,
        metavar="DEG",
        help="vertical field of view of a distortion-free photo, in degrees",
    )
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
    g = p.add_argument_group("colour")
    col = g.add_mutually_exclusive_group()
    col.add_argument(
        "--grey-card", metavar="X,Y,W,H", help="white balance from a neutral card at this rectangle of PHOTO"
    )
    col.add_argument(
        "--colorchecker",
        action="store_true",
        help="colour correction from a ColorChecker Classic in PHOTO (OpenCV contrib's cv2.mcc)",
    )
    g = p.add_argument_group("ball")
    g.add_argument(
        "--ball",
        type=_triple,
        metavar="X,Y,R",
        help="where the ball is in PHOTO (centre and radius in pixels, roughly), if it is not found",
    )
    g.add_argument(
        "--ball-mask", metavar="MASK.png", help="an image of PHOTO's size, white on the ball, black elsewhere"
    )
    g.add_argument(
        "--ball-free",
        action="store_true",
        help="do not assume the ball rests on the floor: fit its centre's height too (less precise)",
    )
    g.add_argument("--ball-name", default="ball", help="the sphere's name in the scene (default ball)")
    g.add_argument("--floor-name", default="floor", help="the plane's name in the scene (default floor)")
    g = p.add_argument_group("scene")
    g.add_argument(
        "--width",
        type=_positive_int,
        default=160,
        help="the scene's working width in pixels, the height following the photo (default 160)",
    )
    g.add_argument(
        "--light-range",
        type=_positive_float,
        default=2.0,
        metavar="FACTOR",
        help="the light's search box, in units of the camera's distance to the ball (default 2)",
    )
    p.set_defaults(handler=_cmd_scene)
    return p


def scene_main(argv: Sequence[str] | None = None) -> int:
    """``rtloop-scene``: build a scene JSON (and objective, overlay) from a photo. Returns the exit status."""
    return _run(_build_scene_parser, argv, "rtloop-scene")


def _cmd_scene(args: argparse.Namespace) -> int:
    from .build import build_scene

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise AcquisitionError(f"{out}: exists and is not a directory")
    if out.is_dir() and any(out.iterdir()) and not args.force:
        raise AcquisitionError(
            f"{out}: exists and is not empty; pass --force to replace it, or choose another --out"
        )
    load = {"response": args.response, "black_level": args.black_level, "white_level": args.white_level}
    photo = load_photo(args.photo, **load)
    objective = load_photo(args.objective, **load) if args.objective else None
    intrinsics = CameraIntrinsics.load(args.camera) if args.camera else None
    mask = None
    if args.ball_mask:
        m = load_photo(args.ball_mask, response="linear")
        mask = m.max(axis=2) > 0.5
    colour: Any = "colorchecker" if args.colorchecker else args.grey_card
    acq = build_scene(
        photo,
        args.board,
        args.ball_radius,
        intrinsics=intrinsics,
        vfov_deg=args.vfov,
        objective=objective,
        colour=colour,
        ball_hint=args.ball,
        ball_mask=mask,
        resting=not args.ball_free,
        width=args.width,
        light_range=args.light_range,
        names=(args.ball_name, args.floor_name),
        where=args.photo,
        objective_where=args.objective or args.photo,
    )
    acq.scene["meta"]["acquisition"]["inputs"] = {
        "photo": os.path.abspath(args.photo),
        "objective": os.path.abspath(args.objective) if args.objective else None,
        "camera": os.path.abspath(args.camera) if args.camera else None,
        "board": parse_board(args.board).to_dict(),
        "response": args.response,
    }
    tmp = staging_dir(out, "rtloop-scene")
    try:
        write_json(tmp / "scene.json", acq.scene)
        write_png16_srgb(tmp / "objective.png", acq.objective)
        write_png16_srgb(tmp / "photo.png", acq.photo)
        write_png8(tmp / "overlay.png", acq.overlay)
        move_into_place(tmp, out, out.exists(), "rtloop-scene")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    cam = acq.scene["camera"]
    ball = acq.scene["objects"][0]
    rep = acq.scene["meta"]["acquisition"]
    for note in acq.warnings:
        _info(f"warning: {note}")
    print(f"wrote {out}/scene.json, objective.png, overlay.png, photo.png")
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
    print(f"  colour: {rep['colour']['source']}")
    print("check overlay.png, then fit:")
    print(
        f"  rtloop-fit {shlex.quote(str(out / 'scene.json'))} {shlex.quote(str(out / 'objective.png'))} "
        f"--out {shlex.quote(str(out / 'fit'))}"
    )
    return 0
