"""Calibration targets: ChArUco boards (calibration and floor pose) and plain chessboards (calibration).

A ChArUco board is a chessboard whose white squares hold ArUco markers, so every corner found can be
named even when part of the board is hidden. It is described by :class:`BoardSpec`:

* ``squares``: squares across and down (columns x rows) as printed, e.g. 7 x 5;
* ``square_m``: the side of one chessboard square in metres, *as printed* (measure it!);
* ``marker_m``: the side of one marker in metres (smaller than the square);
* ``dictionary``: the ArUco dictionary, e.g. ``DICT_5X5_100``;
* ``legacy``: the pre-OpenCV-4.6 layout (only differs for boards with an even number of rows).

Board coordinates (OpenCV's): origin at the top-left outer corner of the printed board, x to the
right along the columns, y down along the rows, z into the paper. ``rtloop-acquire board`` writes a
printable image and a JSON file with the spec, which every other command accepts as ``--board FILE``.

A spec is also written inline as ``COLSxROWS,SQUARE,MARKER[,DICT]`` with lengths in metres, or with
an ``mm`` suffix (``7x5,40mm,30mm,DICT_5X5_100``), and a chessboard (calibration only) as
``chess:COLSxROWS,SQUARE`` (squares, not inner corners: a 10x7 chessboard has 9x6 inner corners).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ._common import AcquisitionError, read_json

__all__ = [
    "DEFAULT_DICTIONARY",
    "MIN_CORNERS",
    "BoardDetection",
    "BoardSpec",
    "board_image",
    "detect_board",
    "parse_board",
]

DEFAULT_DICTIONARY = "DICT_5X5_100"

#: Fewest board corners accepted for a pose or a calibration view (and they must not lie on one line).
MIN_CORNERS = 6
#: Where a ChArUco board's corners are not all found, detection is tried again on a copy this many times
#: the photo's size (:func:`_detect_charuco`).
UPSAMPLE = 2

_SPEC_HELP = (
    "write it as COLSxROWS,SQUARE,MARKER[,DICT] (lengths in metres or with 'mm', e.g. "
    "7x5,40mm,30mm,DICT_5X5_100), chess:COLSxROWS,SQUARE for a plain chessboard, or a JSON file "
    "written by 'rtloop-acquire board'"
)


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board (``kind="charuco"``) or a plain chessboard (``kind="chessboard"``)."""

    squares: tuple[int, int]
    square_m: float
    marker_m: float = 0.0
    dictionary: str = DEFAULT_DICTIONARY
    legacy: bool = False
    kind: str = "charuco"
    _cache: dict = field(default_factory=dict, compare=False, repr=False, hash=False)

    def __post_init__(self) -> None:
        cols, rows = self.squares
        if self.kind not in ("charuco", "chessboard"):
            raise AcquisitionError(f"board: unknown kind {self.kind!r} (charuco or chessboard)")
        if cols < 2 or rows < 2 or (self.kind == "chessboard" and (cols < 3 or rows < 3)):
            raise AcquisitionError(f"board: {cols}x{rows} squares is too small; {_SPEC_HELP}")
        if not (math.isfinite(self.square_m) and self.square_m > 0):
            raise AcquisitionError(f"board: square size must be > 0 metres (got {self.square_m})")
        if self.square_m > 5:
            raise AcquisitionError(
                f"board: a {self.square_m} m square is implausible; sizes are in metres (write 40mm or 0.04)"
            )
        if self.kind == "charuco":
            if not (0 < self.marker_m < self.square_m):
                raise AcquisitionError(
                    f"board: the marker ({self.marker_m} m) must be smaller than the square "
                    f"({self.square_m} m); {_SPEC_HELP}"
                )
            if not hasattr(cv2.aruco, self.dictionary) or not self.dictionary.startswith("DICT_"):
                raise AcquisitionError(
                    f"board: unknown ArUco dictionary {self.dictionary!r}; use one of cv2.aruco's "
                    "DICT_* names, e.g. DICT_4X4_50, DICT_5X5_100, DICT_6X6_250"
                )
            need = (cols * rows) // 2
            have = _dictionary_size(self.dictionary)
            if have and need > have:
                raise AcquisitionError(
                    f"board: {cols}x{rows} squares need {need} markers but {self.dictionary} has only {have}"
                )

    # --- OpenCV objects ---------------------------------------------------------------------------------

    @property
    def size_m(self) -> tuple[float, float]:
        """The board's printed width and height in metres."""
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    @property
    def centre(self) -> np.ndarray:
        """The board's centre in board coordinates (metres)."""
        w, h = self.size_m
        return np.array([w / 2.0, h / 2.0, 0.0])

    def charuco(self) -> cv2.aruco.CharucoBoard:
        if self.kind != "charuco":
            raise AcquisitionError("board: a plain chessboard cannot be used here; it needs a ChArUco board")
        if "board" not in self._cache:
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
            board = cv2.aruco.CharucoBoard(tuple(self.squares), self.square_m, self.marker_m, dictionary)
            board.setLegacyPattern(bool(self.legacy))
            self._cache["board"] = board
        return self._cache["board"]

    def inner_corners(self) -> np.ndarray:
        """Board coordinates (N, 3) of the inner chessboard corners, in OpenCV's id order."""
        cols, rows = self.squares
        ys, xs = np.mgrid[1:rows, 1:cols]
        return np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)]) * self.square_m

    # --- (de)serialisation ------------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"kind": self.kind, "squares": list(self.squares), "square_m": self.square_m}
        if self.kind == "charuco":
            d.update(marker_m=self.marker_m, dictionary=self.dictionary, legacy=self.legacy)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any], where: str = "board") -> BoardSpec:
        try:
            kind = d.get("kind", "charuco")
            squares = tuple(int(v) for v in d["squares"])
            if len(squares) != 2:
                raise ValueError("squares must be [columns, rows]")
            return cls(
                squares=squares,  # type: ignore[arg-type]
                square_m=float(d["square_m"]),
                marker_m=float(d.get("marker_m", 0.0)),
                dictionary=str(d.get("dictionary", DEFAULT_DICTIONARY)),
                legacy=bool(d.get("legacy", False)),
                kind=kind,
            )
        except AcquisitionError as exc:
            raise AcquisitionError(f"{where}: {exc}") from None
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise AcquisitionError(
                f"{where}: not a board description ({exc}); expected keys kind, squares, square_m, "
                "marker_m, dictionary as written by 'rtloop-acquire board'"
            ) from None

    def describe(self) -> str:
        cols, rows = self.squares
        if self.kind == "chessboard":
            return f"chessboard {cols}x{rows} squares of {self.square_m * 1000:g} mm"
        legacy = ", legacy layout" if self.legacy else ""
        return (
            f"ChArUco {cols}x{rows} squares of {self.square_m * 1000:g} mm, markers "
            f"{self.marker_m * 1000:g} mm, {self.dictionary}{legacy}"
        )


def _dictionary_size(name: str) -> int:
    m = re.search(r"_(\d+)$", name)
    return int(m.group(1)) if m and name.count("X") == 1 else 0


def length_m(text: str) -> float:
    """A length in metres from 0.0335, 33.5mm or 3.35cm (ValueError if it is no number; not checked
    for being finite or positive)."""
    t = text.strip().lower()
    scale = 1.0
    for suffix, s in (("mm", 1e-3), ("cm", 1e-2), ("m", 1.0)):
        if t.endswith(suffix):
            t, scale = t[: -len(suffix)], s
            break
    return float(t) * scale


def _length(text: str) -> float:
    value = length_m(text)
    if not math.isfinite(value):
        raise ValueError(text)
    return value


def parse_board(text: str | os.PathLike[str] | dict | BoardSpec) -> BoardSpec:
    """A :class:`BoardSpec` from an inline spec, a JSON file, a dict or a spec (returned as is)."""
    if isinstance(text, BoardSpec):
        return text
    if isinstance(text, dict):
        return BoardSpec.from_dict(text)
    s = os.fspath(text).strip()
    if s.lower().endswith(".json") or os.path.isfile(s):
        data = read_json(s, "a board description written by 'rtloop-acquire board'")
        if isinstance(data, dict) and isinstance(data.get("board"), dict):
            data = data["board"]
        if not isinstance(data, dict):
            raise AcquisitionError(f"{s}: not a board description")
        return BoardSpec.from_dict(data, where=s)
    kind = "charuco"
    body = s
    if s.lower().startswith("chess:"):
        kind, body = "chessboard", s[6:]
    elif s.lower().startswith("charuco:"):
        body = s[8:]
    parts = [p.strip() for p in body.split(",")]
    try:
        m = re.fullmatch(r"(\d+)\s*[xX]\s*(\d+)", parts[0])
        if not m:
            raise ValueError
        squares = (int(m.group(1)), int(m.group(2)))
        if kind == "chessboard":
            if len(parts) != 2:
                raise ValueError
            return BoardSpec(squares, _length(parts[1]), kind=kind)
        if len(parts) not in (3, 4):
            raise ValueError
        dictionary = parts[3].upper() if len(parts) == 4 else DEFAULT_DICTIONARY
        if not dictionary.startswith("DICT_"):
            dictionary = "DICT_" + dictionary
        return BoardSpec(squares, _length(parts[1]), _length(parts[2]), dictionary)
    except (ValueError, IndexError):
        raise AcquisitionError(f"board {s!r}: cannot read it; {_SPEC_HELP}") from None


def board_image(spec: BoardSpec, px_per_square: int = 100, margin_px: int = 0) -> np.ndarray:
    """The board as an 8-bit grey image (for printing, or for synthetic views).

    Board point (X, Y) in metres is at OpenCV pixel ``(X / square_m * px_per_square + margin_px - 0.5,
    Y / square_m * px_per_square + margin_px - 0.5)``.
    """
    cols, rows = spec.squares
    size = (cols * px_per_square + 2 * margin_px, rows * px_per_square + 2 * margin_px)
    if spec.kind == "chessboard":
        ys, xs = np.mgrid[0:rows, 0:cols]
        tile = np.where((xs + ys) % 2 == 0, 0, 255).astype(np.uint8)
        img = np.kron(tile, np.ones((px_per_square, px_per_square), np.uint8))
        return cv2.copyMakeBorder(
            img, margin_px, margin_px, margin_px, margin_px, cv2.BORDER_CONSTANT, value=255
        )
    return spec.charuco().generateImage(size, marginSize=margin_px, borderBits=1)


@dataclass
class BoardDetection:
    """Board corners found in one image.

    Attributes:
        image_points: (N, 2) float32 OpenCV pixel coordinates of the corners.
        object_points: (N, 3) float32 board coordinates (metres) of the same corners.
        ids: (N,) corner ids (ChArUco corner ids, or the chessboard corner index).
        marker_corners, marker_ids: the ArUco markers found (ChArUco only), for drawing.
    """

    image_points: np.ndarray
    object_points: np.ndarray
    ids: np.ndarray
    marker_corners: tuple = ()
    marker_ids: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.ids)


def detect_board(
    grey: np.ndarray, spec: BoardSpec, *, where: str = "photo", min_corners: int = MIN_CORNERS
) -> BoardDetection:
    """Find the board's corners in an 8-bit grey image.

    Raises:
        AcquisitionError: no board (no markers of the board's dictionary, or no chessboard), or too
            few corners, or all corners on one line. The message says what to try.
    """
    if grey.dtype != np.uint8 or grey.ndim != 2:
        raise AcquisitionError(f"{where}: detection needs an 8-bit grey image, got {grey.dtype} {grey.shape}")
    if spec.kind == "chessboard":
        return _detect_chessboard(grey, spec, where)
    board = spec.charuco()
    corners, ids, marker_corners, marker_ids = _detect_charuco(grey, spec)
    n_markers = 0 if marker_ids is None else len(marker_ids)
    n = 0 if ids is None else len(ids)
    if n_markers == 0:
        raise AcquisitionError(
            f"{where}: no ChArUco board found (no {spec.dictionary} markers seen). Check that the whole "
            f"board is in view, sharp, not overexposed, and that --board matches the printed board "
            f"({spec.describe()})"
        )
    if n_markers:
        seen, twice = set(), set()
        for marker in np.asarray(marker_ids).ravel().tolist():
            (twice if marker in seen else seen).add(marker)
        if twice:
            listed = ", ".join(map(str, sorted(twice)[:8])) + (", ..." if len(twice) > 8 else "")
            raise AcquisitionError(
                f"{where}: the board's marker{'s' if len(twice) > 1 else ''} {listed} "
                f"{'are' if len(twice) > 1 else 'is'} seen twice: two copies of the board are in view; show one "
                "board (cover or remove the other)"
            )
    if n == 0 and n_markers < 3:
        raise AcquisitionError(
            f"{where}: only {n_markers} ArUco marker(s) of the board seen, too few to place its corners; "
            "show more of the board (the whole board, sharp and evenly lit)"
        )
    if n == 0:
        raise AcquisitionError(
            f"{where}: {n_markers} ArUco markers seen but no corner of the board could be placed; "
            f"--board ({spec.describe()}) probably does not match the printed board (number of squares, "
            'dictionary, or "legacy": true in the board JSON for boards printed with OpenCV before 4.6)'
        )
    if n < min_corners:
        raise AcquisitionError(
            f"{where}: only {n} board corner(s) found (need at least {min_corners}); move the camera so "
            "more of "
            "the board is visible, closer and sharper, and light it evenly"
        )
    if board.checkCharucoCornersCollinear(ids):
        raise AcquisitionError(
            f"{where}: the {n} board corners found all lie on one line, which fixes no pose; show more of "
            "the board"
        )
    obj, img = board.matchImagePoints(corners, ids)
    return BoardDetection(
        image_points=np.asarray(img, np.float32).reshape(-1, 2),
        object_points=np.asarray(obj, np.float32).reshape(-1, 3),
        ids=np.asarray(ids).reshape(-1),
        marker_corners=marker_corners,
        marker_ids=marker_ids,
    )


def _charuco_detector(spec: BoardSpec) -> cv2.aruco.CharucoDetector:
    detector = spec._cache.get("detector")
    if detector is None:
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = (
            cv2.aruco.CORNER_REFINE_NONE
        )  # ChArUco corners get subpixel refinement
        detector = cv2.aruco.CharucoDetector(spec.charuco(), cv2.aruco.CharucoParameters(), params)
        spec._cache["detector"] = detector
    return detector


def _detect_charuco(grey: np.ndarray, spec: BoardSpec) -> tuple[Any, Any, Any, Any]:
    """The ChArUco detector's corners, ids, marker corners and marker ids. Where it places fewer than all
    of the board's inner corners (markers foreshortened or small: a board seen at a grazing angle), it is
    run again on the region around the markers found (their bounding box widened by its own size each way)
    enlarged UPSAMPLE times (bicubic), and the detection with more corners kept, its pixel coordinates taken
    back to the photo's (pixel centres at integers)."""
    detector = _charuco_detector(spec)
    found = detector.detectBoard(grey)
    cols, rows = spec.squares
    n = 0 if found[1] is None else len(found[1])
    if n >= (cols - 1) * (rows - 1) or found[3] is None or len(found[3]) == 0:
        return found
    pts = np.concatenate([np.asarray(m, np.float64).reshape(-1, 2) for m in found[2]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    h, w = grey.shape
    x0, y0 = (int(max(0, math.floor(v))) for v in lo - (hi - lo))
    x1, y1 = (int(min(size, math.ceil(v) + 1)) for size, v in zip((w, h), hi + (hi - lo)))
    big = cv2.resize(grey[y0:y1, x0:x1], None, fx=UPSAMPLE, fy=UPSAMPLE, interpolation=cv2.INTER_CUBIC)
    corners, ids, marker_corners, marker_ids = detector.detectBoard(big)
    if ids is None or len(ids) <= n:
        return found
    offset = np.array([x0, y0], np.float64)

    def back(p: Any) -> np.ndarray:
        return ((np.asarray(p, np.float64) + 0.5) / UPSAMPLE - 0.5 + offset).astype(np.float32)

    return back(corners), ids, tuple(back(m) for m in marker_corners), marker_ids


def _detect_chessboard(grey: np.ndarray, spec: BoardSpec, where: str) -> BoardDetection:
    cols, rows = spec.squares
    pattern = (cols - 1, rows - 1)
    ok, corners = cv2.findChessboardCornersSB(grey, pattern, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok or corners is None:
        raise AcquisitionError(
            f"{where}: no {cols}x{rows}-square chessboard ({pattern[0]}x{pattern[1]} inner corners) found; "
            "the whole board must be in view and sharp, and --board must give the number of squares"
        )
    pts = np.asarray(corners, np.float32).reshape(-1, 2)
    obj = spec.inner_corners().astype(np.float32)
    return BoardDetection(pts, obj, np.arange(len(pts)))
