"""The photo's framing against the scene's camera (rtloop.fit.framing): photos turned, shifted or cropped
and enlarged (made here from the Mitsuba fixtures, as an image editor would: the 8-bit photo resampled
bilinearly) are told apart from the photos framed as their scene's camera frames them, with the warp
that made them as the truth; framing="correct" resamples them back and the light comes out as from the
photo as taken."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

import rtloop
from conftest import BALL_ON_FLOOR, shared_case, shared_case_names
from rtloop import cli as fit_cli
from rtloop.fit import framing

PHOTOS = Path(__file__).resolve().parent / "fixtures" / "photos"
CASES = sorted(p.name for p in PHOTOS.iterdir() if (p / "scene.json").is_file())


def _quiet_fit(scene, photo, **kw):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        return rtloop.fit(scene, photo, uncertainty=False, **kw)


def reframed_photo(case: str, tmp: Path, turn_deg: float = 0.0, shift=(0.0, 0.0), crop=None) -> Path:
    """The case's 8-bit photo turned by ``turn_deg`` (counter-clockwise as displayed) about its centre and
    shifted by ``shift`` px (right, down), bilinear with the border mirrored, then its centred ``crop``
    (w, h) kept: a PNG, which load_image enlarges back to the scene's size."""
    img = np.asarray(Image.open(PHOTOS / case / "objective.png").convert("RGB"), np.float32)
    h, w = img.shape[:2]
    m = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), turn_deg, 1.0)
    m[:, 2] += shift
    out = cv2.warpAffine(img, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    if crop is not None:
        x0, y0 = (w - crop[0]) // 2, (h - crop[1]) // 2
        out = out[y0:y0 + crop[1], x0:x0 + crop[0]]
    path = tmp / f"{case}-reframed.png"
    Image.fromarray(np.clip(out + 0.5, 0, 255).astype(np.uint8)).save(path)
    return path


def _load(case: str, photo: Path):
    import warnings

    scene = rtloop.load_scene(PHOTOS / case / "scene_input.json")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the crop's enlargement
        return scene, rtloop.load_image(photo, scene)


def _light_error(result, case: str) -> float:
    truth = json.loads((PHOTOS / case / "scene.json").read_text())["light"]["position"]
    return float(np.linalg.norm(np.subtract(result.scene.to_dict()["light"]["position"], truth)))


def test_registration_recovers_a_known_warp():
    """Two balls rendered with supersampled edges, the render warped by a known roll, zoom and shift
    (cv2.warpAffine): the registration against the render gives them back."""
    d = json.loads(json.dumps(BALL_ON_FLOOR))
    d["image"] = {"width": 128, "height": 96}
    d["objects"].insert(1, {"name": "small", "shape": "sphere", "center": [1.7, 0.5, 0.4], "radius": 0.5,
                            "material": {"albedo": [0.2, 0.3, 0.9]}})
    scene = rtloop.load_scene(d)
    render = rtloop.render(scene, spp=16)
    roll, zoom, shift = math.radians(1.5), 1.03, (0.8, -0.6)
    c = np.array([(128 - 1) / 2, (96 - 1) / 2])
    a = zoom * np.array([[math.cos(roll), -math.sin(roll)], [math.sin(roll), math.cos(roll)]])
    m = np.hstack([a, (c - a @ c + shift)[:, None]]).astype(np.float64)
    photo = cv2.warpAffine(render, m, (128, 96), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    out, _ = framing.measure(scene, photo, None, render)
    assert out["checked"] and out["mismatch"]
    assert out["roll_deg"] == pytest.approx(1.5, abs=0.2)
    assert out["zoom_percent"] == pytest.approx(3.0, abs=0.4)
    assert out["shift_px"] == pytest.approx(list(shift), abs=0.2)
    same, _ = framing.measure(scene, render, None, render)
    assert same["checked"] and not same["mismatch"] and same["outline_rms_px"] < 0.01


@pytest.mark.parametrize("case", CASES)
def test_photos_framed_as_their_scene_are_not_flagged(case):
    """Every Mitsuba fixture (gloss, environment, bounce, lamps, JPEG) with its scene: the outlines are
    registered in place (forced, whatever the residual) and the fit's verdict does not speak of framing."""
    scene, photo = _load(case, PHOTOS / case / "objective.png")
    result = _quiet_fit(scene, photo)
    assert not result.goodness["framing"]["mismatch"]
    assert "framing" not in result.goodness["verdict"]
    out, _ = framing.measure(result.scene, photo, None, framing._compared(result))
    assert out["checked"] and not out["mismatch"], out


@pytest.mark.parametrize("name", shared_case_names())
@pytest.mark.parametrize("protocol", ["rtloop", "paper"])
def test_reference_scenes_are_not_flagged(name, protocol):
    """The reference scenes (noise included), fitted with either protocol: outlines in place."""
    case = shared_case(name)
    scene = rtloop.load_scene(case / "scene_input.json")
    photo = rtloop.load_image(case / "objective.png", scene)
    result = _quiet_fit(scene, photo, protocol=protocol, seed=1)
    out, _ = framing.measure(result.scene, photo, None, framing._compared(result))
    assert out["checked"] and not out["mismatch"], out


#: (case, turn deg, shift px, crop): what was done to the photo, and the roll, zoom and shift the
#: registration must find (the roll only where two balls fix it; one ball turning about the centre moves
#: as a shift does).
REFRAMED = [
    ("direct-side", 2.0, (0, 0), (120, 90)),
    ("direct-two-balls", 2.0, (0, 0), (120, 90)),
    ("direct-overhead", 0.0, (0, 0), (120, 90)),
    ("env-overhead", 0.0, (0, 0), (120, 90)),
    ("gloss-a010", 0.0, (0, 0), (120, 90)),
    ("lamp-desk", 2.0, (0, 0), (120, 90)),
    ("bounce-two-balls", 0.0, (0, 0), (120, 90)),
    ("direct-side", 0.0, (2, 0), None),
    ("env-overhead", 0.0, (2, 0), None),
    ("gloss-a010", 0.0, (0, 2), None),
    ("lamp-desk", 0.0, (2, 0), None),
    ("direct-two-balls", 2.0, (0, 0), None),
    ("direct-three-balls", -2.0, (0, 0), None),
    ("direct-two-balls", 3.0, (0, 0), None),
]


@pytest.mark.parametrize(("case", "turn", "shift", "crop"), REFRAMED)
def test_a_reframed_photo_is_flagged_with_its_warp(tmp_path, case, turn, shift, crop):
    scene, photo = _load(case, reframed_photo(case, tmp_path, turn, shift, crop))
    result = _quiet_fit(scene, photo)
    f = result.goodness["framing"]
    assert f["checked"] and f["mismatch"], f
    assert result.goodness["verdict"].startswith("the photo's framing does not match the scene's camera")
    zoom = 100 * (128 / crop[0] - 1) if crop else 0.0
    assert f["zoom_percent"] == pytest.approx(zoom, abs=1.5)
    if not turn:  # a pure shift or crop: no roll, the shift as made
        assert f["shift_px"] == pytest.approx([shift[0] * (128 / crop[0] if crop else 1),
                                               shift[1] * (128 / crop[0] if crop else 1)], abs=0.5)
    elif "balls" in case:  # two or three balls fix the roll: clockwise as displayed is positive
        assert f["roll_deg"] == pytest.approx(-turn, abs=0.6)


@pytest.mark.parametrize(("case", "turn", "crop"), [("direct-side", 2.0, (120, 90)), ("direct-two-balls", 2.0, None),
                                                    ("direct-overhead", 0.0, (120, 90))])
def test_framing_correct_gives_the_light_back(tmp_path, case, turn, crop):
    """The light from the reframed photo: 15 cm or more off as given; within 3 cm with framing='correct',
    whose correction is the warp that was made (the roll within 0.5 deg, the zoom within 0.5 %)."""
    scene, photo = _load(case, reframed_photo(case, tmp_path, turn, (0, 0), crop))
    assert _light_error(_quiet_fit(scene, photo), case) > 0.15
    result = _quiet_fit(scene, photo, framing="correct")
    assert _light_error(result, case) < 0.03
    f = result.goodness["framing"]
    assert f["corrected"] and f["as_given"]["mismatch"] and not f["mismatch"]
    assert f["correction"]["roll_deg"] == pytest.approx(-turn, abs=0.5)
    assert f["correction"]["zoom_percent"] == pytest.approx(100 * (128 / crop[0] - 1) if crop else 0.0, abs=0.5)
    moved, inside = result.reframed
    assert moved.shape == photo.shape and inside.shape == photo.shape[:2] and 0 < (~inside).sum() < inside.size / 4


def test_framing_correct_leaves_a_framed_photo_as_it_is():
    scene, photo = _load("direct-side", PHOTOS / "direct-side" / "objective.png")
    plain = _quiet_fit(scene, photo)
    corrected = _quiet_fit(scene, photo, framing="correct")
    assert corrected.goodness["framing"]["corrected"] is False and corrected.reframed is None
    assert corrected.x == plain.x


def test_framing_argument_is_checked():
    scene, photo = _load("direct-side", PHOTOS / "direct-side" / "objective.png")
    for bad in ("bogus", None, 1, "CHECK"):
        with pytest.raises(rtloop.RtloopError, match="^framing: must be"):
            _quiet_fit(scene, photo, framing=bad)
    off = _quiet_fit(scene, photo, framing="off")
    assert off.goodness["framing"] == {"checked": False, "mismatch": False, "why": "framing='off'"}


def test_cli_says_so_and_corrects(tmp_path, capsys):
    """rtloop-fit on the photo turned 2 deg and cropped to 120x90: a warning naming the framing, and
    result.json's fit_report.goodness.framing; --framing correct fits the resampled photo (objective.png)
    and the summary says what it corrected."""
    case = "direct-side"
    photo = reframed_photo(case, tmp_path, 2.0, (0, 0), (120, 90))
    args = [str(PHOTOS / case / "scene_input.json"), str(photo), "--final-scale", "1", "--final-spp", "1",
            "--snapshot-every", "0", "--uncertainty", "off"]
    assert fit_cli.main([*args, "--out", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    assert "warning: the photo's framing does not match the scene's camera" in err
    report = json.loads((tmp_path / "a" / "result.json").read_text())["fit_report"]
    assert report["goodness"]["framing"]["mismatch"] is True
    assert fit_cli.main([*args, "--out", str(tmp_path / "b"), "--framing", "correct"]) == 0
    out = capsys.readouterr().out
    assert "framing corrected: the photo resampled into the scene's framing" in out
    result = json.loads((tmp_path / "b" / "result.json").read_text())
    assert result["fit_report"]["goodness"]["framing"]["corrected"] is True
    truth = json.loads((PHOTOS / case / "scene.json").read_text())["light"]["position"]
    assert np.linalg.norm(np.subtract(result["light"]["position"], truth)) < 0.03
    written = rtloop.load_image(tmp_path / "b" / "objective.png", rtloop.load_scene(PHOTOS / case / "scene_input.json"))
    as_given = rtloop.load_image(tmp_path / "a" / "objective.png", rtloop.load_scene(PHOTOS / case / "scene_input.json"))
    assert not np.array_equal(written, as_given)
