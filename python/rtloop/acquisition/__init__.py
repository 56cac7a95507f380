"""Acquisition from real cameras and photos: everything between a real scene and ``rtloop-fit``
(the command lines ``rtloop-acquire`` and ``rtloop-scene`` are in :mod:`rtloop.cli`).

rtloop fits a hand-described scene to a photo. This subpackage measures that scene instead of
asking for it by hand, from a photo of a ball lying on the floor beside a ChArUco board:

=====================  ================================================================================
module                 what it does
=====================  ================================================================================
``capture``            take a photo from a camera (OpenCV VideoCapture): lock exposure and white balance
                       where the backend allows (and say when not), average N frames, save a 16-bit PNG
                       and a JSON of the settings
``response``           load photos through any camera response: sRGB, linear, gamma, a measured table;
                       RAW-like 16-bit TIFF with black and white levels
``boards``             ChArUco boards and chessboards: describe, print, detect
``calibration``        camera intrinsics from several board photos (cv2.calibrateCamera); undistortion
                       to the scene's ideal pinhole camera (square pixels, centred principal point)
``camera``             the scene format's camera and its exact relation to OpenCV's camera model
``pose``               camera pose and floor plane from one board lying on the floor
``ball``               the ball's outline (exact sphere-outline fit) and its centre in 3-D
``colour``             white balance from a grey card, colour correction from a ColorChecker (cv2.mcc)
``build``              the whole chain: scene JSON with a ``fit`` section, objective image, overlay
``synthetic``          synthetic photos with known geometry (tests, and checking a setup)
``objective``          the image a fit compares with, from a file at the scene's size (``load_image``,
                       ``rtloop.load_image``) and a mask of the pixels the scene models (``load_mask``)
=====================  ================================================================================

Conventions are the scene format's (docs/scene-format.md): metres, right-handed, +y up; the board's face is
the floor plane y = 0 with the origin at the board's centre. Every failure raises
:class:`rtloop.errors.AcquisitionError` with a message that says what to do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..errors import AcquisitionError

if TYPE_CHECKING:
    from .ball import BallSilhouette, SpherePlacement, find_ball, locate_ball, place_sphere
    from .boards import BoardDetection, BoardSpec, board_image, detect_board, parse_board
    from .build import AcquiredScene, build_scene, draw_overlay, fit_section
    from .calibration import CameraIntrinsics, PinholeRemap, calibrate_camera, undistort_to_pinhole
    from .camera import PinholeCamera, focal_from_vfov, vfov_from_focal
    from .capture import CaptureResult, FrameSource, capture_photo, open_camera, save_capture
    from .colour import ColourCorrection, colorchecker_correction, grey_card_balance, mcc_available
    from .objective import load_image, load_mask
    from .pose import WORLD_FROM_BOARD, FloorPose, estimate_floor_pose
    from .response import CameraResponse, load_photo, parse_response, photo_info

#: Where each public name lives: imported on first use, so ``import rtloop`` loads no OpenCV.
_WHERE = {
    "BallSilhouette": "ball",
    "SpherePlacement": "ball",
    "find_ball": "ball",
    "locate_ball": "ball",
    "place_sphere": "ball",
    "BoardDetection": "boards",
    "BoardSpec": "boards",
    "board_image": "boards",
    "detect_board": "boards",
    "parse_board": "boards",
    "AcquiredScene": "build",
    "build_scene": "build",
    "draw_overlay": "build",
    "fit_section": "build",
    "CameraIntrinsics": "calibration",
    "PinholeRemap": "calibration",
    "calibrate_camera": "calibration",
    "undistort_to_pinhole": "calibration",
    "PinholeCamera": "camera",
    "focal_from_vfov": "camera",
    "vfov_from_focal": "camera",
    "CaptureResult": "capture",
    "FrameSource": "capture",
    "capture_photo": "capture",
    "open_camera": "capture",
    "save_capture": "capture",
    "ColourCorrection": "colour",
    "colorchecker_correction": "colour",
    "grey_card_balance": "colour",
    "mcc_available": "colour",
    "load_image": "objective",
    "load_mask": "objective",
    "WORLD_FROM_BOARD": "pose",
    "FloorPose": "pose",
    "estimate_floor_pose": "pose",
    "CameraResponse": "response",
    "load_photo": "response",
    "parse_response": "response",
    "photo_info": "response",
}


__all__ = [
    "WORLD_FROM_BOARD",
    "AcquiredScene",
    "AcquisitionError",
    "BallSilhouette",
    "BoardDetection",
    "BoardSpec",
    "CameraIntrinsics",
    "CameraResponse",
    "CaptureResult",
    "ColourCorrection",
    "FloorPose",
    "FrameSource",
    "PinholeCamera",
    "PinholeRemap",
    "SpherePlacement",
    "board_image",
    "build_scene",
    "calibrate_camera",
    "capture_photo",
    "colorchecker_correction",
    "detect_board",
    "draw_overlay",
    "estimate_floor_pose",
    "find_ball",
    "fit_section",
    "focal_from_vfov",
    "grey_card_balance",
    "load_image",
    "load_mask",
    "load_photo",
    "locate_ball",
    "mcc_available",
    "open_camera",
    "parse_board",
    "parse_response",
    "photo_info",
    "place_sphere",
    "save_capture",
    "undistort_to_pinhole",
    "vfov_from_focal",
]


def __getattr__(name: str) -> Any:
    """The submodule's object on first use (PEP 562): OpenCV is imported only by what needs it."""
    if name in _WHERE:
        import importlib

        value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
