"""``rtloop-acquire``: board, capture, calibrate, undistort, thin layers over :mod:`rtloop.acquisition`.
``acquire_main(argv)`` returns the exit status (0 done, 1 bad input or failed step, 2 bad command line)."""

from __future__ import annotations

from .._interrupt import importing

with importing:  # a Ctrl-C while a console script starts: one line, exit 130
    import argparse
    import io
    import math
    from collections.abc import Callable, Sequence
    from pathlib import Path
    from typing import Any

    import numpy as np
    from PIL import Image

    from .._files import write_bytes
    from ..acquisition import capture as capture_module
    from ..acquisition._common import AcquisitionError, write_json, write_png16_srgb
    from ..acquisition.boards import DEFAULT_DICTIONARY, board_image, parse_board
    from ..acquisition.calibration import CameraIntrinsics, calibrate_camera, undistort_to_pinhole
    from ..acquisition.response import load_photo
    from .args import (
        BOARD_HELP, RESPONSE_HELP, Parser, formatter, info, length, nonneg_int, positive_float, positive_int,
        run_subcommands, size
    )

__all__ = ["DEFAULT_BOARD", "acquire_main"]

DEFAULT_BOARD = f"7x5,40mm,30mm,{DEFAULT_DICTIONARY}"


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

BOARD_DESCRIPTION = """\
Write a ChArUco board as a PNG to print, and its description as JSON (same name,
.json) for --board of the other commands. Print at 100% scale ("actual size"),
glue it flat to something rigid, then measure a square with a ruler: if it is
not exactly the size asked for, put the measured size (in metres) into the JSON's
"square_m" and scale "marker_m" the same way."""

CAPTURE_DESCRIPTION = """\
Capture a photo through OpenCV's VideoCapture: read --warmup frames so automatic
exposure and white balance settle, lock both at the settled values (or at
--exposure / --wb-temperature), average --frames frames (noise falls as 1/sqrt(N);
keep the scene still), and write a 16-bit PNG plus OUT.json with every setting and
whether each lock took. Locking depends on the camera and backend: the JSON and the
warnings say 'locked', 'requested' (not confirmed) or 'unsupported'. The PNG keeps
the camera's encoding (load it with --response srgb, the default, for webcams)."""

CAPTURE_EPILOG = "example:\n  rtloop-acquire capture --device 0 --size 1920x1080 --frames 32 --out scene.png"

CALIBRATE_DESCRIPTION = """\
Calibrate the camera (cv2.calibrateCamera) from several photos of a ChArUco board or
a chessboard: focal lengths, principal point, radial and tangential distortion. Use
the same camera, zoom, focus and resolution as for the scene photo. Take 10 to 20
photos from different angles (tilted up to about 45 degrees), the board covering a
good part of the frame and, across the set, reaching every corner. Photos in which
the board is not found are skipped (and listed); at least 3 must remain. A good
calibration has an RMS reprojection error below about 0.5 px."""

CALIBRATE_EPILOG = (
    "example:\n  rtloop-acquire calibrate calib/*.png --board board.json --out camera.json\n"
    "  rtloop-acquire calibrate shots/*.jpg --board chess:10x7,25mm --out camera.json"
)

UNDISTORT_DESCRIPTION = """\
Remove the lens distortion, make the pixels square and move the principal point to the
centre, so the photo is what the scene format's camera sees; prints its vertical field
of view. Writes a 16-bit sRGB PNG (read by rtloop with the default --response srgb).
rtloop-scene does this itself when given --camera."""


def _command(
    sub: Any, name: str, handler: Callable[[argparse.Namespace], int], *, help: str, description: str,
    epilog: str | None = None,
) -> argparse.ArgumentParser:
    """The subcommand ``name``, run by ``handler``, with ``description`` as its help text."""
    parser = sub.add_parser(
        name, help=help, formatter_class=formatter(), description=description, epilog=epilog
    )
    parser.set_defaults(handler=handler)
    return parser


def _out(parser: argparse.ArgumentParser, metavar: str, help: str | None = None) -> None:
    """The subcommand's required ``--out``/``-o``: the file it writes."""
    parser.add_argument("--out", "-o", required=True, metavar=metavar, help=help)


def _build_acquire_parser() -> Parser:
    p = Parser(prog="rtloop-acquire", description=ACQUIRE_DESCRIPTION, formatter_class=formatter())
    sub = p.add_subparsers(title="commands", metavar="COMMAND")
    # name, handler, options, help (in the list of commands), description, epilog
    for name, handler, options, help, description, epilog in (
        ("board", _cmd_board, _board_options, "write a printable ChArUco board", BOARD_DESCRIPTION, None),
        ("capture", _cmd_capture, _capture_options, "take an averaged 16-bit photo from a camera",
         CAPTURE_DESCRIPTION, CAPTURE_EPILOG),
        ("calibrate", _cmd_calibrate, _calibrate_options, "measure the camera from photos of a board",
         CALIBRATE_DESCRIPTION, CALIBRATE_EPILOG),
        ("undistort", _cmd_undistort, _undistort_options,
         "resample a photo into the scene's ideal pinhole camera", UNDISTORT_DESCRIPTION, None),
    ):
        options(_command(sub, name, handler, help=help, description=description, epilog=epilog))
    return p


def _board_options(b: argparse.ArgumentParser) -> None:
    """The options of ``board``: write a printable ChArUco board."""
    b.add_argument("--board", default=DEFAULT_BOARD, help=BOARD_HELP + f" (default {DEFAULT_BOARD})")
    b.add_argument("--dpi", type=positive_int, default=300, help="printer resolution (default 300)")
    b.add_argument(
        "--margin",
        type=length,
        default=0.01,
        metavar="LENGTH",
        help="white margin around the board (default 10mm)",
    )
    _out(b, "BOARD.png", "the image to write")


def _capture_options(c: argparse.ArgumentParser) -> None:
    """The options of ``capture``: an averaged 16-bit photo from a camera."""
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
    c.add_argument("--size", type=size, metavar="WxH", help="ask the camera for this resolution")
    c.add_argument("--frames", type=positive_int, default=16, help="frames to average (default 16)")
    c.add_argument("--warmup", type=nonneg_int, default=10, help="frames dropped first (default 10)")
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
        type=positive_float,
        metavar="KELVIN",
        help="manual white balance temperature; default: keep the settled automatic balance",
    )
    c.add_argument(
        "--no-lock-white-balance",
        dest="lock_wb",
        action="store_false",
        help="leave automatic white balance on",
    )
    _out(c, "PHOTO.png", "the 16-bit PNG to write")


def _calibrate_options(k: argparse.ArgumentParser) -> None:
    """The options of ``calibrate``: measure the camera from photos of a board."""
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
    _out(k, "CAMERA.json", "the calibration to write")


def _undistort_options(u: argparse.ArgumentParser) -> None:
    """The options of ``undistort``: resample a photo into the scene's ideal pinhole camera."""
    u.add_argument("photo", metavar="PHOTO")
    u.add_argument("--camera", required=True, metavar="CAMERA.json", help="from 'rtloop-acquire calibrate'")
    u.add_argument("--response", default="srgb", help=RESPONSE_HELP)
    _out(u, "OUT.png")


def acquire_main(argv: Sequence[str] | None = None) -> int:
    """``rtloop-acquire``: board, capture, calibrate, undistort. Returns the exit status."""
    return run_subcommands(_build_acquire_parser, argv, "rtloop-acquire")


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
            log=info,
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
        on_skip=lambda name, msg: (skipped.append(name), info(f"skipped: {msg}")),
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
        info(
            "warning: the RMS error is above 1 px: drop blurred photos (see the per-photo errors in the "
            "JSON), "
            "check --board, and make sure the board is flat"
        )
    if len(intr.views) < 8:
        info(
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
