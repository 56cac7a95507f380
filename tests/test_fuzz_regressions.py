"""Defects fuzz/fuzz.py found, kept as regression cases."""

import pytest

import rtloop
from test_scene_errors import valid_scene


def test_a_scene_dict_that_contains_itself_is_a_scene_error():
    # It raised RecursionError from the NaN search (fuzz seed 0: a list put inside itself).
    scene = valid_scene()
    loop: list = [1]
    loop.append(loop)
    scene["camera"]["position"] = loop
    with pytest.raises(rtloop.SceneError, match="JSON"):
        rtloop.load_scene(scene)


def test_a_scene_dict_nested_past_the_recursion_limit_is_a_scene_error():
    scene = valid_scene()
    deep: list = []
    for _ in range(100_000):
        deep = [deep]
    scene["ambient"] = deep
    with pytest.raises(rtloop.SceneError):
        rtloop.load_scene(scene)


def test_an_exif_resolution_unit_that_is_not_a_number_counts_as_absent(tmp_path):
    # It raised TypeError from int() (the property test of EXIF tags: FocalPlaneResolutionUnit (1, 0)).
    from PIL import Image

    from rtloop.acquisition.exif import exif_focal

    exif = Image.Exif()
    exif.get_ifd(0x8769).update({0x920A: 4.0, 0xA20E: 100.0, 0xA210: (1, 0)})
    Image.new("RGB", (8, 6)).save(tmp_path / "p.jpg", exif=exif)
    assert exif_focal(tmp_path / "p.jpg", 8, 6) is None
