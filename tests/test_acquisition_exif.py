"""The EXIF focal length: read on the stored image's axis whatever the orientation, and an implausible value
warned about and ignored."""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rtloop.acquisition.exif import exif_focal
from rtloop.errors import RtloopError, RtloopWarning

FOCAL, X_RES, UNIT, F35, ORIENTATION = 0x920A, 0xA20E, 0xA210, 0xA405, 0x0112


def jpeg(path: Path, tags: dict[int, object], orientation: int = 1, size: tuple[int, int] = (400, 300)) -> Path:
    """A JPEG stored ``size`` (width, height) carrying ``tags`` in its EXIF sub-IFD and the orientation."""
    exif = Image.Exif()
    exif[ORIENTATION] = orientation
    exif.get_ifd(0x8769).update(tags)
    Image.fromarray(np.full((size[1], size[0], 3), 128, np.uint8)).save(path, quality=90, exif=exif)
    return path


@pytest.mark.parametrize("orientation", range(1, 9))
def test_focal_length_is_on_the_stored_x_axis_for_every_orientation(tmp_path, orientation):
    # 4 mm at 100 pixels per mm: 400 px at the stored 400 x 300, whichever way the photo is shown.
    path = jpeg(tmp_path / "p.jpg", {FOCAL: 4.0, X_RES: 100.0, UNIT: 4}, orientation)
    shown = (300, 400) if orientation >= 5 else (400, 300)
    assert exif_focal(path, *shown).focal_px == pytest.approx(400.0)
    # At half the displayed size, half the pixels.
    assert exif_focal(path, shown[0] // 2, shown[1] // 2).focal_px == pytest.approx(200.0)


def test_an_upright_phone_photo_has_the_field_of_view_of_its_lens(tmp_path):
    """A 4:3 sensor turned upright (orientation 6): the vertical field of view spans the sensor's width."""
    path = jpeg(tmp_path / "p.jpg", {FOCAL: 4.25, X_RES: 4000 / 5.6, UNIT: 4}, 6, size=(4000, 3000))
    focal = exif_focal(path, 3000, 4000).focal_px
    vfov = math.degrees(2 * math.atan(4000 / 2 / focal))
    assert vfov == pytest.approx(math.degrees(2 * math.atan(5.6 / 2 / 4.25)))  # 66.4 deg, not 52.4


@pytest.mark.parametrize("tags, tag", [
    ({FOCAL: 1e9, X_RES: 100.0, UNIT: 4}, "FocalLength"),
    ({FOCAL: 1e-9, X_RES: 100.0, UNIT: 4}, "FocalLength"),
    ({FOCAL: 4.0, X_RES: 1e12, UNIT: 4}, "FocalPlaneXResolution"),
    ({F35: 60000}, "FocalLengthIn35mmFilm"),
])
def test_an_implausible_focal_length_warns_and_counts_as_absent(tmp_path, tags, tag):
    path = jpeg(tmp_path / "p.jpg", tags)
    with pytest.warns(RtloopWarning, match=rf"p\.jpg: EXIF {tag} .* is implausible") as caught:
        assert exif_focal(path, 400, 300) is None
    assert all("\n" not in str(w.message) for w in caught)


def test_an_implausible_focal_length_falls_back_to_the_35mm_equivalent(tmp_path):
    path = jpeg(tmp_path / "p.jpg", {FOCAL: 1e9, X_RES: 100.0, UNIT: 4, F35: 28})
    with pytest.warns(RtloopWarning, match="FocalLength 1e"):
        found = exif_focal(path, 400, 300)
    assert found.focal_px == pytest.approx(28 * 500 / math.hypot(36, 24))


def test_plausible_values_do_not_warn(tmp_path):
    path = jpeg(tmp_path / "p.jpg", {FOCAL: 4.0, X_RES: 100.0, UNIT: 4})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert exif_focal(path, 400, 300) is not None


def test_a_fifo_is_not_opened_for_its_exif(tmp_path):
    fifo = tmp_path / "p.jpg"
    os.mkfifo(fifo)
    assert exif_focal(fifo, 400, 300) is None  # returns at once: no writer is waited for
    with pytest.raises(RtloopError, match="FIFO"):
        from rtloop.acquisition.response import load_photo

        load_photo(fifo)
