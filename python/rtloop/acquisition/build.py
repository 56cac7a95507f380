"""From a photo of a ball on a floor with a ChArUco board to a scene ready for ``rtloop-fit``.

:func:`build_scene` runs the whole chain:

1. colour: a white balance from a grey card, or a colour correction from a ColorChecker, measured
   in the photo and applied in linear light (to the photo and to a separate objective photo);
2. the camera model: with a calibration (or EXIF naming a lens Lensfun has a profile of), undistort the
   photos (the scene's camera is an ideal pinhole); with only a field of view or EXIF's focal length,
   take the photo as a pinhole; with neither, estimate the focal length from the board (less accurate);
3. the board: camera pose and floor plane (the board's face is the floor, y = 0, +y up, metres);
4. the ball: its outline, searched for as a ball of the given radius resting on the floor, and its
   centre fitted to the outline;
5. the scene: camera, floor plane, sphere, a first guess of the light, and a ``fit`` section
   (light position and intensity, both albedos) with bounds scaled to the scene;
6. an overlay: the board's axes and corners, the ball's fitted outline and edge points, and the
   outline of the ball as rtloop renders the new scene (``rtloop.object_ids``), over the photo.
The fit cannot move the sphere (``objects.*.center`` is not fittable), so the overlay is the check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

import rtloop

from .._stats import median
from ._common import AcquisitionError, check_image, jsonable
from .ball import BallSilhouette, SpherePlacement, locate_ball
from .boards import BoardSpec, parse_board
from .calibration import CameraIntrinsics, PinholeRemap
from .camera import focal_from_vfov
from .colour import ColourCorrection, colorchecker_correction, grey_card_balance
from .exif import ExifFocal
from .focal import field_of_view_record, loose_view_warning, refine_field_of_view, scan_vfov_for_ball
from .lens_profile import LensProfile, LensRemap
from .overlay import OVERLAY_MAX_SIDE, _board_outline_px, draw_overlay  # noqa: F401 (re-exported)
from .pose import VFOV_TARGET_DEG, FloorPose, estimate_floor_pose

__all__ = ["AcquiredScene", "build_scene", "draw_overlay", "fit_section"]

Remap = PinholeRemap | LensRemap  # what moves the photo's pixels into the scene's pinhole camera


@dataclass
class AcquiredScene:
    """Everything :func:`build_scene` found.

    Attributes:
        scene: the scene dict (docs/scene-format.md) with a ``fit`` section and ``meta.acquisition``.
        objective: the photo to fit, linear RGB float32 at full size: colour-corrected, undistorted.
        photo: the board photo after the same steps (what the geometry was measured on).
        pose, silhouette, sphere, colour: the pieces, for inspection.
        overlay: 8-bit BGR image for checking the alignment.
        warnings: things the user should know (estimated focal length, poor fits).
    """

    scene: dict[str, Any]
    objective: np.ndarray
    photo: np.ndarray
    pose: FloorPose
    silhouette: BallSilhouette
    sphere: SpherePlacement
    colour: ColourCorrection
    overlay: np.ndarray
    warnings: list[str] = field(default_factory=list)
    #: bool (H, W) at the objective's size, True where the scene models the photo (False on the board
    #: with its paper margin and on the colour target); None when the objective is another photo.
    mask: np.ndarray | None = None
    #: bool (H, W) at the objective's size, True inside the grey card's rectangle, when its reflectance
    #: is known (``card_reflectance``): what rtloop-fit measures the absolute albedos on.
    card: np.ndarray | None = None


#: The room light's (environment radiance's) upper bound with ``room``: the radiance that alone renders an
#: unoccluded white floor at 1 (the top of the photo's range).
ROOM_LIGHT_MAX = 1.0


def fit_section(
    camera_position: np.ndarray,
    ball_centre: np.ndarray,
    ball_radius: float,
    intensity: float,
    light_range: float = 2.0,
    ball: str = "ball",
    floor: str = "floor",
) -> dict[str, Any]:
    """The ``fit`` bounds: the light within ``light_range`` x the scene's scale s (the camera's
    distance to the ball, at least 4 ball radii) of the ball horizontally and between 0.1 s and
    ``light_range`` x s above the floor; the intensity within a factor 100 of the first guess;
    albedos in [0, 1]."""
    s = max(float(np.linalg.norm(np.asarray(camera_position) - ball_centre)), 4 * ball_radius)
    reach = light_range * s
    bx, bz = float(ball_centre[0]), float(ball_centre[2])
    return {
        "light.position": {"min": [bx - reach, 0.1 * s, bz - reach], "max": [bx + reach, reach, bz + reach]},
        "light.intensity": {"min": intensity / 100.0, "max": intensity * 100.0},
        f"objects.{ball}.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]},
        f"objects.{floor}.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]},
    }


def build_scene(
    photo: np.ndarray, board: BoardSpec | str | dict, ball_radius: float, *,
    intrinsics: CameraIntrinsics | None = None, vfov_deg: float | None = None, exif: ExifFocal | None = None,
    lens: LensProfile | None = None,
    objective: np.ndarray | None = None, colour: str | tuple | ColourCorrection | None = None,
    ball_hint: tuple[float, float, float] | None = None, ball_mask: np.ndarray | None = None,
    resting: bool = True, width: int = 160, light_range: float = 2.0,
    names: tuple[str, str] = ("ball", "floor"),
    board_margin: float | None = None, board_thickness: float = 0.0, card_reflectance: float | None = None,
    room: bool = True,
    where: str = "photo", objective_where: str = "objective", strict: bool = False,
) -> AcquiredScene:
    """Build the scene from one photo (board + ball on the floor), optionally fitting another.

    Args:
        photo: linear RGB float (H, W, 3) showing the ChArUco board lying on the floor and the ball.
        board: the board (see ``boards.parse_board``).
        ball_radius: metres.
        intrinsics: a calibration of this camera (undistorts and re-centres); or ``vfov_deg``, the
            full vertical field of view of an already distortion-free photo; else ``exif``, the focal
            length the photo's EXIF gives (:func:`rtloop.acquisition.exif.exif_focal`); none: estimated
            from the board, refused when the board is seen too nearly head-on for that.
        lens: with ``exif``, the lens's profile (:func:`rtloop.acquisition.lens_profile.find_lens_profile`):
            its distortion and vignetting are removed from both photos first.
        objective: the photo to fit, from the same camera position and settings (e.g. the same view
            with the board removed); default: ``photo``.
        colour: ``None``, ``"colorchecker"``, a grey-card rectangle ``(x, y, w, h)`` / ``"x,y,w,h"``
            (pixels of ``photo`` as given), or a ready :class:`ColourCorrection`.
        ball_hint, ball_mask: help for finding the ball (pixels of ``photo`` as given).
        resting: the ball rests on the floor (recommended); False frees its height.
        width: the scene's working width in pixels (height follows the photo's aspect ratio).
        light_range: size of the light's search box in units of the scene's scale.
        names: the names of the sphere and the plane in the scene.
        board_margin: the white paper around the board's squares, metres (default: one square).
        board_thickness: metres: the board's face (y = 0) lies this far above the floor the ball rests on
            (the floor plane is then y = -board_thickness); under the ball's radius.
        room: the scene has what a photo of a room shows besides the lamp: the environment (a dim light from
            every direction, occluded by the objects) free in the fit section and one diffuse bounce between
            the objects (``"interreflection": true``); False: direct light only (rtloop-fit then adds the
            terms only where its screen finds them in the photo).
        card_reflectance: the grey card's known reflectance (e.g. 0.18): recorded in the scene
            (``meta.acquisition.grey_card``) with the card's pixels (``AcquiredScene.card``), so that the fit
            reports absolute albedos and the light's intensity. Needs the grey-card ``colour`` and the card in
            the photo to fit.
        strict: with the focal length from the board alone, refuse a board that fixes the vertical field of
            view more loosely than ``pose.VFOV_TARGET_DEG`` (0.3 deg); without it such a board is used, with a
            warning that gives its spread and what it means for the scene's distances.

    Raises:
        AcquisitionError: any step failed; the message says which and what to do.
    """
    photo, objective, spec = _check_inputs(
        photo, objective, board, width, light_range, colour, card_reflectance, where, objective_where
    )
    h, w = photo.shape[:2]
    same, notes = objective is photo, []
    correction, photo, objective = _correct_colour(photo, objective, same, colour, where)
    remap, focal, focal_source, photo, objective = _camera_model(
        photo, objective, same, intrinsics, vfov_deg, exif, lens, where
    )
    pose = _pose_camera(photo, spec, focal, focal_source, where, strict, notes, h)
    mask, hint = _ball_mask_and_hint(ball_mask, ball_hint, remap, w, h)
    silhouette, sphere, locate, scanned = _locate_ball(
        photo, pose, spec, ball_radius, hint, mask, resting, focal_source, where,
        _floor_height(board_thickness, ball_radius),
    )
    pose, silhouette, sphere, refinement = refine_field_of_view(
        photo, spec, ball_radius, pose, silhouette, sphere, locate, focal_source, where, notes, h, scanned
    )
    _ball_notes(silhouette, sphere, ball_radius, resting, notes)
    scene = _scene_dict(objective, pose, sphere.centre, ball_radius, width, light_range, names, room, w, h)
    scene["meta"] = {"acquisition": jsonable(_acquisition_report(
        photo, spec, pose, silhouette, sphere, correction, ball_radius, refinement, locate,
        focal_source, exif, intrinsics, names[0], where, notes, w, h,
    ))}
    if board_thickness:  # the floor, where the ball rests, under the board's face
        scene["objects"][1]["point"][1] = locate["floor_height"]
        scene["meta"]["acquisition"]["board_thickness_m"] = float(board_thickness)
    if isinstance(remap, LensRemap):
        scene["meta"]["acquisition"]["lens_profile"] = jsonable(remap.report())
    rtloop.load_scene(scene)  # validates: a failure here is a bug, not bad input
    overlay = draw_overlay(photo, scene, pose, silhouette)
    unmodelled, card = _masks(
        scene, pose, spec, correction, remap, photo, same, board_margin, card_reflectance, w, h
    )
    return AcquiredScene(
        scene, objective, photo, pose, silhouette, sphere, correction, overlay, notes, unmodelled, card
    )


def _masks(
    scene: dict[str, Any],
    pose: FloorPose,
    spec: BoardSpec,
    correction: ColourCorrection,
    remap: Remap | None,
    photo: np.ndarray,
    same: bool,
    board_margin: float | None,
    card_reflectance: float | None,
    w: int,
    h: int,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Step 6, the masks: what the scene models of the photo to fit, when that is the board photo
    (``same``), and the grey card's pixels, when its reflectance is known (then recorded in the scene's
    ``meta.acquisition.grey_card``). Returns both, None where not made."""
    unmodelled = None
    if same:  # the board is in the photo to fit: leave it (and the colour target) out of the fit
        margin = spec.square_m if board_margin is None else float(board_margin)
        if not (math.isfinite(margin) and margin >= 0):
            raise AcquisitionError(f"board margin must be 0 or more metres (got {board_margin})")
        unmodelled = unmodelled_mask(pose, margin, correction, remap, w, h, photo)
    card = None
    if card_reflectance is not None:
        card = card_pixels(correction.details["rect"], remap, w, h)
        scene["meta"]["acquisition"]["grey_card"] = {
            "reflectance": float(card_reflectance),
            "rect_px": list(correction.details["rect"]),
        }
    return unmodelled, card


def _floor_height(board_thickness: float, ball_radius: float) -> float:
    """The floor's height under a board of ``board_thickness`` (metres) whose face is y = 0."""
    t = board_thickness
    if not (isinstance(t, (int, float)) and math.isfinite(t) and 0 <= t < ball_radius):
        raise AcquisitionError(
            f"board thickness must be 0 or more metres and under the ball's radius (got {t})")
    return -float(t)


def _check_inputs(
    photo: np.ndarray,
    objective: np.ndarray | None,
    board: BoardSpec | str | dict,
    width: int,
    light_range: float,
    colour: str | tuple | ColourCorrection | None,
    card_reflectance: float | None,
    where: str,
    objective_where: str,
) -> tuple[np.ndarray, np.ndarray, BoardSpec]:
    """Check :func:`build_scene`'s arguments: the photos (the objective defaults to the photo itself, the
    same object), the scene's width, the light's range, the board and the grey card's reflectance. Returns
    the checked photo, objective and board."""
    photo = check_image(photo, where)
    h, w = photo.shape[:2]
    if objective is None:
        objective = photo
    else:
        objective = check_image(objective, objective_where)
        if objective.shape != photo.shape:
            raise AcquisitionError(
                f"{objective_where}: is {objective.shape[1]}x{objective.shape[0]} but the board photo "
                f"{where} is "
                f"{w}x{h}; both must come from the same camera, position and resolution"
            )
    if not (isinstance(width, int) and 8 <= width <= 4096):
        raise AcquisitionError(f"scene width must be a whole number from 8 to 4096 pixels (got {width})")
    if not (math.isfinite(light_range) and 0.25 <= light_range <= 100):
        raise AcquisitionError(f"light range must be between 0.25 and 100 (got {light_range}); 2 is typical")
    spec = parse_board(board)
    if card_reflectance is not None:
        if not (math.isfinite(card_reflectance) and 0 < card_reflectance <= 1):
            raise AcquisitionError(
                f"grey card reflectance must be in (0, 1] (got {card_reflectance}); 0.18 for an 18 % grey card"
            )
        if colour is None or isinstance(colour, ColourCorrection) or (
            isinstance(colour, str) and colour.lower() in ("colorchecker", "colourchecker", "mcc")
        ):
            raise AcquisitionError("a grey card reflectance needs the card's rectangle: give --grey-card X,Y,W,H")
        if objective is not photo:
            raise AcquisitionError(
                "a grey card reflectance needs the card in the photo to fit: leave out --objective (the board "
                "and the card are masked out of the fit), or leave the card in the second photo and fit that"
            )
    return photo, objective, spec


def _correct_colour(
    photo: np.ndarray,
    objective: np.ndarray,
    same: bool,
    colour: str | tuple | ColourCorrection | None,
    where: str,
) -> tuple[ColourCorrection, np.ndarray, np.ndarray]:
    """Step 1, colour: measured on the photo as given, applied in linear light to the photo and the
    objective (``same``: the objective is the photo). Returns the correction and both photos."""
    if colour is None:
        correction = ColourCorrection.identity()
    elif isinstance(colour, ColourCorrection):
        correction = colour
    elif isinstance(colour, str) and colour.lower() in ("colorchecker", "colourchecker", "mcc"):
        correction = colorchecker_correction(photo, where=where)
    else:
        correction = grey_card_balance(photo, colour, where=where)
    if correction.source != "none":
        photo = correction.apply(photo)
        objective = photo if same else correction.apply(objective)
    return correction, photo, objective


def _camera_model(
    photo: np.ndarray,
    objective: np.ndarray,
    same: bool,
    intrinsics: CameraIntrinsics | None,
    vfov_deg: float | None,
    exif: ExifFocal | None,
    lens: LensProfile | None,
    where: str,
) -> tuple[Remap | None, float | None, str, np.ndarray, np.ndarray]:
    """Step 2, the camera model: with a calibration (or EXIF and the lens's profile), both photos moved into a
    pinhole; else the focal length from the given field of view, from EXIF, or none (the board estimates
    it). Returns the remap (or None), the focal length in pixels, where it came from, and both photos."""
    h, w = photo.shape[:2]
    remap = None
    if intrinsics is not None:
        remap = PinholeRemap(intrinsics, w, h, where)
        photo = remap.image(photo).astype(np.float32)
        objective = photo if same else remap.image(objective).astype(np.float32)
        focal, focal_source = remap.focal_px, "calibration"
    elif vfov_deg is not None:
        if not (math.isfinite(vfov_deg) and 1.0 <= vfov_deg <= 170.0):
            raise AcquisitionError(
                f"vertical field of view must be between 1 and 170 degrees (got {vfov_deg})"
            )
        focal, focal_source = focal_from_vfov(vfov_deg, h), "given"
    elif exif is not None and lens is not None:
        remap = lens.remap(w, h, exif.focal_px)
        photo = remap.correct(photo)
        objective = photo if same else remap.correct(objective)
        focal, focal_source = remap.focal_px, "exif"
    elif exif is not None:
        focal, focal_source = exif.focal_px, "exif"
    else:
        focal, focal_source = None, "board"
    return remap, focal, focal_source, photo, objective


def _pose_camera(
    photo: np.ndarray,
    spec: BoardSpec,
    focal: float | None,
    focal_source: str,
    where: str,
    strict: bool,
    notes: list[str],
    h: int,
) -> FloorPose:
    """Step 3, the board: the camera's pose and the floor, with notes on a focal length from the board
    alone and on a poor reprojection appended to ``notes`` (``h``: the photo's height)."""
    pose = estimate_floor_pose(photo, spec, focal_px=focal, focal_source=focal_source, where=where, strict=strict)
    camera = pose.camera
    if focal_source == "board" and pose.vfov_std_deg is not None and pose.vfov_std_deg > VFOV_TARGET_DEG:
        notes.append(loose_view_warning(where, camera.vfov_deg, pose.vfov_std_deg, camera.focal_px, h))
    elif focal_source == "board":
        notes.append(
            f"{where} has no EXIF focal length: it was estimated from the board alone (vertical field of "
            f"view {camera.vfov_deg:.2f} +- {pose.vfov_std_deg:.2f} deg); "
            "a calibration (rtloop-acquire calibrate) or --vfov is more accurate"
        )
    if pose.reprojection_rms_px > 1.0:
        notes.append(
            f"the board's corners are reprojected with {pose.reprojection_rms_px:.2f} px RMS error (more "
            "than 1 px): "
            "is the lens distortion calibrated, and does the board lie flat?"
        )
    return pose


def _ball_mask_and_hint(
    ball_mask: np.ndarray | None,
    ball_hint: tuple[float, float, float] | None,
    remap: Remap | None,
    w: int,
    h: int,
) -> tuple[np.ndarray | None, tuple[float, float, float] | None]:
    """The ball's mask and hint (pixels of the photo as given) moved into the undistorted photo; the mask
    must have the photo's size."""
    hint = ball_hint
    if hint is not None and remap is not None:
        p = remap.points(np.array([[hint[0], hint[1]]]))[0]
        hint = (float(p[0]), float(p[1]), float(hint[2]) * remap.focal_px / float(remap.source_matrix[1, 1]))
    mask = None if ball_mask is None else np.asarray(ball_mask)
    if mask is not None:
        if mask.shape[:2] != (h, w):
            raise AcquisitionError(
                f"ball mask: is {mask.shape[1]}x{mask.shape[0]} but the photo is {w}x{h}; draw it on the "
                "photo itself"
            )
        if remap is not None:
            mask = remap.mask(mask if mask.ndim == 2 else mask.max(axis=2))
    return mask, hint


def _locate_ball(
    photo: np.ndarray,
    pose: FloorPose,
    spec: BoardSpec,
    ball_radius: float,
    hint: tuple[float, float, float] | None,
    mask: np.ndarray | None,
    resting: bool,
    focal_source: str,
    where: str,
    floor_height: float = 0.0,
) -> tuple[BallSilhouette | None, SpherePlacement | None, dict[str, Any], tuple[float, Any] | None]:
    """Step 4, the ball: its outline and the sphere, looked for beside the board. Returns them, the
    search's settings (mask, resting, the floor's height, the board's outline to exclude, the board's area
    to keep off) and,
    where a loose board's estimate shows no ball, the field of view and outline where it was found instead
    (:func:`scan_vfov_for_ball`; the outline and sphere are then None)."""
    camera = pose.camera
    bw, bh = spec.size_m
    locate = {"mask": mask, "resting": resting, "floor_height": floor_height,
              "exclude": _board_outline_px(pose),
              "keep_off": (-bw / 2, bw / 2, -bh / 2, bh / 2)}
    loose = focal_source == "board" and (pose.vfov_std_deg or 0.0) > VFOV_TARGET_DEG
    try:
        silhouette, sphere = locate_ball(photo, camera, ball_radius, hint=hint, where=where, **locate)
    except AcquisitionError as exc:
        # a loose board's estimate can be far off (a board seen face-on): the ball tried at other fields of view
        scanned = scan_vfov_for_ball(photo, spec, ball_radius, locate=locate, where=where) if loose else None
        if scanned is None:
            why = "" if focal_source != "board" else (
                f"; the field of view is the board's alone, {camera.vfov_deg:.1f} +- {pose.vfov_std_deg:.2f} deg"
                f"{' (nor at any from 8 to 100 deg)' if loose else ''}: give "
                "--vfov or --camera, or use a photo whose EXIF has the focal length")
            raise AcquisitionError(f"{exc} (the ball is looked for beside the board, not on it{why})") from None
        return None, None, locate, scanned
    return silhouette, sphere, locate, None


def _ball_notes(
    silhouette: BallSilhouette, sphere: SpherePlacement, ball_radius: float, resting: bool, notes: list[str]
) -> None:
    """Notes on a poorly fitted or poorly seen outline, and on a free ball that does not rest on the
    floor, appended to ``notes``."""
    if silhouette.rms_px > 1.0:
        notes.append(
            f"the ball's outline fits its edge points with {silhouette.rms_px:.2f} px RMS (more than 1 px); "
            "check the overlay"
        )
    if silhouette.coverage < 0.5:
        notes.append(
            f"only {silhouette.coverage:.0%} of the ball's outline shows a clear edge; check the overlay"
        )
    if not resting and abs(sphere.height_above_floor - ball_radius) > 0.1 * ball_radius:
        notes.append(
            f"the ball's centre is {sphere.height_above_floor:.3f} m above the floor but its radius is "
            f"{ball_radius:g} m: "
            "it does not rest on the floor, or the radius or the board is off"
        )


def _scene_dict(
    objective: np.ndarray,
    pose: FloorPose,
    centre: np.ndarray,
    ball_radius: float,
    width: int,
    light_range: float,
    names: tuple[str, str],
    room: bool,
    w: int,
    h: int,
) -> dict[str, Any]:
    """Step 5, the scene (``names``: the ball's and the floor's, which must differ): camera, floor,
    sphere, a first guess of the light (above the ball, at an intensity that renders a white surface facing
    it as bright as the objective's brightest pixels) and the ``fit`` section; with ``room``, the
    environment and the interreflection too."""
    ball_name, floor_name = names
    if ball_name == floor_name:
        raise AcquisitionError("the ball and the floor need different names")
    camera = pose.camera
    height = max(1, round(width * h / w))
    s = max(float(np.linalg.norm(camera.position - centre)), 4 * ball_radius)
    light_pos = np.array([centre[0], min(s, light_range * s), centre[2]])
    lum = objective @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    bright = max(float(np.percentile(lum, 99.0)), 0.05)
    d = float(np.linalg.norm(light_pos - centre)) - ball_radius
    intensity = (
        math.pi * d * d * bright
    )  # white Lambertian surface facing the lamp at d: the brightest pixels
    scene: dict[str, Any] = {
        "image": {"width": width, "height": int(height)},
        "camera": camera.to_scene_camera(),
        "light": {
            "position": [float(v) for v in light_pos],
            "intensity": intensity,
            "color": [1.0, 1.0, 1.0],
        },
        "ambient": [0.0, 0.0, 0.0],
        "background": [0.0, 0.0, 0.0],
        "exposure": 1.0,
        "objects": [
            {
                "name": ball_name,
                "shape": "sphere",
                "center": [float(v) for v in centre],
                "radius": float(ball_radius),
                "material": {"albedo": [0.5, 0.5, 0.5]},
            },
            {
                "name": floor_name,
                "shape": "plane",
                **pose.floor_plane,
                "material": {"albedo": [0.5, 0.5, 0.5]},
            },
        ],
        "fit": fit_section(
            camera.position, centre, ball_radius, intensity, light_range, ball_name, floor_name
        ),
    }
    if room:
        scene["interreflection"] = True
        scene["fit"]["environment"] = {"min": [0.0, 0.0, 0.0], "max": [ROOM_LIGHT_MAX] * 3}
    return scene


def _acquisition_report(
    photo: np.ndarray,
    spec: BoardSpec,
    pose: FloorPose,
    silhouette: BallSilhouette,
    sphere: SpherePlacement,
    correction: ColourCorrection,
    ball_radius: float,
    refinement: Any,
    locate: dict[str, Any],
    focal_source: str,
    exif: ExifFocal | None,
    intrinsics: CameraIntrinsics | None,
    ball_name: str,
    where: str,
    notes: list[str],
    w: int,
    h: int,
) -> dict[str, Any]:
    """The scene's ``meta.acquisition``: the photo's size, the camera model and where its focal length
    came from, the colour correction, the pose, the ball, notes on the world and the fit, the warnings
    (``notes`` itself) and the calibration used."""
    camera = pose.camera
    report = {
        "photo_size": [w, h],
        "camera_model": focal_source,
        **({"focal_refinement": refinement.to_dict()} if refinement is not None else {}),
        **({"field_of_view": field_of_view_record(
            photo, spec, ball_radius, camera.vfov_deg, float(pose.vfov_std_deg), (
                float(silhouette.centre_px[0]), float(silhouette.centre_px[1]), float(silhouette.radius_px)),
            ball_name, locate=locate, where=where)} if focal_source == "board" and pose.vfov_std_deg else {}),
        **({"focal_from": exif.source} if focal_source == "exif" and exif is not None else {}),
        "colour": {k: v for k, v in correction.report().items() if k != "patch_corners_px"},
        "pose": pose.report(),
        "ball": {**silhouette.report(), **sphere.report()},
        "notes": [
            (
                "world: metres, +y up, the board's face is the floor (y = 0), origin at the board's centre, "
                "x along the board's columns, z along its rows"
            ),
            (
                "light.position and light.intensity are first guesses; the photo fixes only intensity x "
                "albedo "
                "(see rtloop-fit's identifiability note): put in the lamp's real intensity if you know it"
            ),
            "the sphere's centre is measured here and not refined by the fit (centres are not fittable)",
        ],
        "warnings": notes,
    }
    if intrinsics is not None:
        report["calibration"] = {"rms_px": intrinsics.rms_px, "image_size": list(intrinsics.image_size)}
    return report


def card_pixels(rect: Any, remap: Remap | None, w: int, h: int) -> np.ndarray:
    """True inside the grey card's rectangle (x, y, w, h in the photo as given), 1 px in from its edges, at
    the objective's size."""
    x, y, rw, rh = rect
    corners = np.array([[x + 1, y + 1], [x + rw - 1, y + 1], [x + rw - 1, y + rh - 1], [x + 1, y + rh - 1]], float)
    if remap is not None:
        corners = remap.points(corners)
    inside = np.zeros((h, w), np.uint8)
    cv2.fillPoly(inside, [np.round((corners - 0.5) * 16).astype(np.int32)], 1, cv2.LINE_8, shift=4)
    return inside.astype(bool)


#: A pixel near the grey card's rectangle belongs to the card when its brightness is within this fraction of
#: the card's (the card is uniform; the floor around it is not the same grey).
CARD_TOLERANCE = 0.25


def card_region(photo: np.ndarray, rect: Any) -> np.ndarray:
    """bool (H, W): the grey card around its rectangle (x, y, w, h): the connected pixels within
    CARD_TOLERANCE of the rectangle's median brightness, looked for within one rectangle size of it; just
    the rectangle when that region reaches the search window's edge (a floor of the card's grey)."""
    h, w = photo.shape[:2]
    x, y, rw, rh = (int(v) for v in rect)
    lum = photo @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    ref = float(median(lum[y : y + rh, x : x + rw]))
    x0, y0, x1, y1 = max(0, x - rw), max(0, y - rh), min(w, x + 2 * rw), min(h, y + 2 * rh)
    near = (np.abs(lum[y0:y1, x0:x1] / max(ref, 1e-6) - 1) < CARD_TOLERANCE).astype(np.uint8)
    near[y - y0 : y - y0 + rh, x - x0 : x - x0 + rw] = 1
    _, labels = cv2.connectedComponents(near, connectivity=4)
    region = labels == labels[y - y0, x - x0]
    out = np.zeros((h, w), bool)
    edge = region[0].any() or region[-1].any() or region[:, 0].any() or region[:, -1].any()
    if edge and (x0, y0, x1, y1) != (0, 0, w, h):
        out[y : y + rh, x : x + rw] = True
    else:
        out[y0:y1, x0:x1] = region
    return out


def unmodelled_mask(
    pose: FloorPose,
    margin_m: float,
    correction: ColourCorrection,
    remap: Remap | None,
    w: int,
    h: int,
    photo: np.ndarray | None = None,
) -> np.ndarray:
    """True where the scene models the photo: False on the board grown by ``margin_m`` on each side
    (its paper) and on the grey card (the rectangle, grown to the whole card in ``photo``, the corrected
    board photo, by :func:`card_region`) or the ColorChecker's box, grown by 2 px."""
    bw, bh = pose.board.size_m
    m = margin_m
    paper = np.array([[-m, -m, 0], [bw + m, -m, 0], [bw + m, bh + m, 0], [-m, bh + m, 0]], dtype=float)
    polygons = [pose.camera.project(pose.board_to_world(paper))]
    details = correction.details
    if "rect" in details:
        x, y, rw, rh = details["rect"]
        target = np.array([[x, y], [x + rw, y], [x + rw, y + rh], [x, y + rh]], dtype=float)
    elif "chart_corners_px" in details:
        target = np.asarray(details["chart_corners_px"], dtype=float).reshape(-1, 2)
    else:
        target = None
    if target is not None:
        polygons.append(target if remap is None else remap.points(target))
    drop = np.zeros((h, w), np.uint8)
    if "rect" in details and photo is not None:
        drop[card_region(photo, details["rect"] if remap is None else _remapped_rect(details["rect"], remap))] = 1
    for poly in polygons:
        if np.isfinite(poly).all():
            cv2.fillPoly(drop, [np.round(poly * 16).astype(np.int32)], 1, cv2.LINE_8, shift=4)
    drop = cv2.dilate(drop, np.ones((5, 5), np.uint8))
    return drop == 0


def _remapped_rect(rect: Any, remap: Remap) -> list[int]:
    """The axis-aligned box, in the undistorted photo, of a rectangle of the photo as given."""
    x, y, rw, rh = rect
    p = remap.points(np.array([[x, y], [x + rw, y], [x + rw, y + rh], [x, y + rh]], float))
    x0, y0 = np.floor(p.min(axis=0)).astype(int)
    x1, y1 = np.ceil(p.max(axis=0)).astype(int)
    return [int(x0), int(y0), int(x1 - x0), int(y1 - y0)]
