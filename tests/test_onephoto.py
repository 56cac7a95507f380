"""One photo is enough: rtloop-scene then rtloop-fit on one photo each, the board and a grey card in
it, no --vfov, against the truth of an independent renderer: the Mitsuba 3 views of tests/fixtures/onephoto
(tools/make_onephoto.py: a ChArUco board as a bitmap texture on the floor, a ball, an 18 % grey card, a point
light 2.7 m from the ball, a dim room light, path traced). The tests need no Mitsuba."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import rtloop
from rtloop import _native
from rtloop import cli as fit_cli
from rtloop.cli.scene import scene_main
from rtloop.fit.reference import pin_to_reference

FIXTURES = Path(__file__).parent / "fixtures" / "onephoto"
EXAMPLE = Path(__file__).parents[1] / "examples" / "one-photo"  # docs/acquisition.md's example: oblique
FOLDERS = {p.name: p for p in FIXTURES.iterdir() if (p / "photo.png").exists()} | {"oblique": EXAMPLE}
VIEWS = sorted(FOLDERS)


def _meta(view: str) -> dict:
    return json.loads((FOLDERS[view] / "meta.json").read_text())


def _scene_args(view: str, photo: Path, out: Path, *extra: str) -> list[str]:
    meta = _meta(view)
    return [str(photo), "--board", meta["board"]["spec"], "--ball-radius", str(meta["ball"]["radius"]),
            "--board-thickness", str(meta["board"]["thickness_m"]),
            "--grey-card", ",".join(map(str, meta["grey_card"]["rect_px"])),
            "--grey-card-reflectance", str(meta["grey_card"]["reflectance"]), "--out", str(out), *extra]


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, tuple[int, Path]]:
    """rtloop-scene on every view as a user runs it: the photo, the board, the ball's radius, the card."""
    root = tmp_path_factory.mktemp("onephoto")
    return {v: (scene_main(_scene_args(v, FOLDERS[v] / "photo.png", root / v)), root / v) for v in VIEWS}


def _errors(scene: dict, meta: dict) -> tuple[float, float, float]:
    """Field of view (deg), camera position and ball centre (m) errors."""
    cam = scene["camera"]
    ball = next(o for o in scene["objects"] if o["shape"] == "sphere")
    return (abs(cam["vfov_deg"] - meta["camera"]["vfov_deg"]),
            float(np.linalg.norm(np.subtract(cam["position"], meta["camera"]["position"]))),
            float(np.linalg.norm(np.subtract(ball["center"], meta["ball"]["centre"]))))


@pytest.mark.parametrize("view", VIEWS)
def test_scene_from_one_photo_with_exif(built, view):
    """The photo's EXIF focal length gives the field of view; the board the camera; the ball is within 1 %
    of its distance (the target), the camera within 1 % of its distance to the board."""
    code, out = built[view]
    assert code == 0
    meta = _meta(view)
    scene = json.loads((out / "scene.json").read_text())
    assert scene["meta"]["acquisition"]["camera_model"] == "exif"
    fov, cam, ball = _errors(scene, meta)
    assert fov < 0.3, fov
    assert cam < 0.01 * np.linalg.norm(meta["camera"]["position"]), cam
    assert ball < 0.01 * meta["ball"]["distance_from_camera_m"], ball
    card = scene["meta"]["acquisition"]["grey_card"]
    assert card == {"reflectance": 0.18, "rect_px": meta["grey_card"]["rect_px"], "mask": "card.png"}
    assert (out / "card.png").is_file() and (out / "mask.png").is_file()


@pytest.fixture(scope="module")
def fits(built, tmp_path_factory) -> dict[str, dict]:
    """rtloop-fit on the folder rtloop-scene wrote, with no flag: result.json per view."""
    root = tmp_path_factory.mktemp("onephoto-fit")
    out = {}
    for view in VIEWS:
        code, scene_dir = built[view]
        assert code == 0
        fit_dir = root / view
        assert fit_cli.main([str(scene_dir / "scene.json"), str(scene_dir / "objective.png"), "--out", str(fit_dir),
                             "--snapshot-every", "0", "--final-scale", "1", "--final-spp", "1"]) == 0
        out[view] = json.loads((fit_dir / "result.json").read_text())
    return out


@pytest.mark.parametrize("view", VIEWS)
def test_light_from_one_photo(fits, view):
    """The light, 2.5-2.8 m from the ball, within 5 cm (the target), from the photo with the board
    and the card in it (masked) and the room light and the bounce in the scene rtloop-scene wrote."""
    meta = _meta(view)
    result = fits[view]
    err = float(np.linalg.norm(np.subtract(result["light"]["position"], meta["light"]["position"])))
    assert err < 0.05, f"{view}: light {1000 * err:.1f} mm off"


@pytest.mark.parametrize("view", VIEWS)
def test_grey_card_gives_absolute_albedos(fits, view):
    """With the card's reflectance known, result.json holds absolute albedos (within 3 % of Mitsuba's, the
    target) and the light's intensity in W/sr (within 3 %)."""
    meta = _meta(view)
    result = fits[view]
    ref = result["fit_report"]["reference"]
    assert ref["reflectance"] == 0.18 and ref["pixels"] >= 20
    albedos = {o["name"]: o["material"]["albedo"] for o in result["objects"]}
    assert albedos == ref["albedos"]
    for name, true in (("ball", meta["ball"]["albedo"]), ("floor", meta["floor_albedo"])):
        rel = np.abs(np.subtract(albedos[name], true)) / np.asarray(true)
        assert rel.max() < 0.03, (view, name, albedos[name], true)
    assert abs(ref["light_intensity_w_sr"] / meta["light"]["intensity_w_sr"] - 1) < 0.03
    assert result["light"]["intensity"] == ref["light_intensity_w_sr"]
    assert not result["fit_report"]["identifiability"]["degenerate"]


def test_pin_to_reference_closed_form():
    """A fit that split the products with the light 2.5x too bright (albedos 2.5x too dark): a card of known
    reflectance on the floor, in a photo rendered with the true scene, gives back the true intensity, colour
    and albedos, and the render is unchanged."""
    truth = json.loads((FOLDERS[VIEWS[0]] / "scene.json").read_text())
    truth.pop("environment")
    truth["ambient"] = [0.0, 0.0, 0.0]
    true_scene = rtloop.Scene(json.dumps(truth))
    w, h = true_scene.width, true_scene.height
    card = np.zeros((h, w), bool)
    ids = _native.object_ids(true_scene)
    rows, cols = np.nonzero(ids == 1)
    r0, c0 = rows[len(rows) // 2], cols[len(cols) // 2]
    card[r0:r0 + 6, c0:c0 + 8] = True
    card &= ids == 1
    photo = _native.render(true_scene, None, None, 16)
    on_card = {**truth, "objects": [truth["objects"][0], {**truth["objects"][1], "material": {"albedo": [0.2] * 3}}]}
    photo[card] = _native.render(rtloop.Scene(json.dumps(on_card)), None, None, 16)[card]
    fitted = json.loads(json.dumps(truth))
    fitted["light"]["intensity"] *= 2.5
    fitted["light"]["color"] = [1.0, 0.9, 1.1]
    for o in fitted["objects"]:
        o["material"]["albedo"] = [a / 2.5 / c for a, c in zip(o["material"]["albedo"], [1.0, 0.9, 1.1])]
    pinned, record = pin_to_reference(rtloop.Scene(json.dumps(fitted)), photo, card, 0.2)
    d = pinned.to_dict()
    assert math.isclose(d["light"]["intensity"], truth["light"]["intensity"], rel_tol=1e-4)
    assert np.allclose(d["light"]["color"], [1, 1, 1], rtol=1e-4)
    for o, t in zip(d["objects"], truth["objects"]):
        assert np.allclose(o["material"]["albedo"], t["material"]["albedo"], rtol=1e-4)
    assert np.allclose(_native.render(pinned, None, None, 4), _native.render(true_scene, None, None, 4), atol=1e-6)
    assert record["pixels"] == int(card.sum())
    with pytest.raises(rtloop.RtloopError, match="not on one of the scene's planes"):
        pin_to_reference(true_scene, photo, ids == 0, 0.2)
    with pytest.raises(rtloop.RtloopError, match="reflectance must be in"):
        pin_to_reference(true_scene, photo, card, 1.5)
    with pytest.raises(rtloop.RtloopError, match="the card's mask is 2x2, the scene"):  # before any fit
        rtloop.fit(true_scene, photo, reference=(np.zeros((2, 2), bool), 0.18))


def test_grey_card_reflectance_needs_the_card(tmp_path, capsys):
    """--grey-card-reflectance without the card's rectangle, or with a second photo to fit: one line each."""
    view = VIEWS[0]
    photo = FOLDERS[view] / "photo.png"
    args = _scene_args(view, photo, tmp_path / "a")
    i = args.index("--grey-card")
    assert scene_main(args[:i] + args[i + 2:]) == 1
    assert "--grey-card X,Y,W,H" in capsys.readouterr().err
    assert scene_main(_scene_args(view, photo, tmp_path / "b", "--objective", str(photo))) == 1
    assert "leave out --objective" in capsys.readouterr().err


def _without_exif(view: str, folder: Path) -> Path:
    path = folder / f"{view}.png"
    with Image.open(FOLDERS[view] / "photo.png") as im:
        im.save(path)  # Pillow writes no EXIF unless asked
    return path


def test_without_exif_the_target_a_warning_or_one_line(tmp_path, capsys):
    """With no EXIF, every view the detector accepts: the field of view within 0.3 deg and the ball within 1 %
    where the board alone fixes it that well; else a scene with one warning giving the board's spread and
    the field of view refined from the ball resting on the floor (the truth within 3 of the board's spreads,
    the ball within 3 of the distances' spread): a scene on every view, the overhead one too, whose board
    seen face-on puts the field of view 20 deg (3 of its spreads) off and the ball's best outline out of its
    reach there. With --strict every view is the target or one line: on each of these the board's 14-15
    corners (of a 6x4 board) fix the field of view no better than +-0.69 deg, so each is refused."""
    built = 0
    for view in VIEWS:
        photo = _without_exif(view, tmp_path)
        code = scene_main(_scene_args(view, photo, tmp_path / view))
        captured = capsys.readouterr()
        err = captured.err.strip()
        if code == 0:
            scene = json.loads((tmp_path / view / "scene.json").read_text())
            acq = scene["meta"]["acquisition"]
            assert acq["camera_model"] == "board"
            fov, cam, ball = _errors(scene, _meta(view))
            std = acq["pose"]["vfov_std_deg"]
            built += 1
            if std <= 0.3:
                assert fov < 0.3, (view, fov)
                assert ball < 0.01 * _meta(view)["ball"]["distance_from_camera_m"], (view, ball)
                continue
            lines = [line for line in (captured.out + captured.err).splitlines() if "no EXIF focal length" in line]
            assert len(lines) == 1 and f"+- {std:.2f} deg (0.3 wanted)" in lines[0], (view, lines)
            assert "refined from the ball resting on the floor to" in lines[0], (view, lines)
            percent = float(re.search(r"about \+-([\d.]+) %", lines[0]).group(1))
            assert fov <= 3 * std, (view, fov, std)
            assert ball <= 3 * percent / 100 * _meta(view)["ball"]["distance_from_camera_m"], (view, ball, percent)
        else:
            assert code == 1 and len(err.splitlines()) == 1, (view, err)
            assert "--vfov" in err and "EXIF" in err, (view, err)
            assert not (tmp_path / view).exists()
        strict = tmp_path / f"{view}-strict"
        assert scene_main(_scene_args(view, photo, strict, "--strict")) == 1
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--vfov" in err and not strict.exists(), (view, err)
    assert built == len(VIEWS)


#: Without EXIF, the light from rtloop-scene's refined field of view and rtloop-fit: the target is 5 cm.
NO_EXIF_LIGHT_M = 0.05


@pytest.mark.parametrize("view", VIEWS)
def test_without_exif_the_light_from_the_refined_field_of_view(tmp_path, view):
    """The field of view refined from the ball is nearer the truth than the board's own estimate (or within
    0.3 deg), and the light from rtloop-fit within NO_EXIF_LIGHT_M. Truth: the Mitsuba renders'."""
    photo = _without_exif(view, tmp_path)
    assert scene_main(_scene_args(view, photo, tmp_path / "scene")) == 0
    scene = json.loads((tmp_path / "scene" / "scene.json").read_text())
    meta = _meta(view)
    refined = scene["meta"]["acquisition"]["focal_refinement"]
    truth = meta["camera"]["vfov_deg"]
    assert abs(refined["vfov_deg"] - truth) <= max(abs(refined["board_vfov_deg"] - truth), 0.3), (view, refined)
    assert fit_cli.main([str(tmp_path / "scene" / "scene.json"), str(tmp_path / "scene" / "objective.png"), "--out",
                         str(tmp_path / "fit"), "--snapshot-every", "0", "--final-scale", "1", "--final-spp", "1",
                         "--uncertainty", "off"]) == 0
    result = json.loads((tmp_path / "fit" / "result.json").read_text())
    err = float(np.linalg.norm(np.subtract(result["light"]["position"], meta["light"]["position"])))
    assert err < NO_EXIF_LIGHT_M, f"{view}: light {1000 * err:.1f} mm off"


def _fit_no_exif(scene_dir: Path, out: Path, *extra: str) -> dict:
    assert fit_cli.main([str(scene_dir / "scene.json"), str(scene_dir / "objective.png"), "--out", str(out),
                         "--snapshot-every", "0", "--final-scale", "1", "--final-spp", "1", "-q", *extra]) == 0
    return json.loads((out / "result.json").read_text())


@pytest.mark.parametrize("view", VIEWS)
def test_without_exif_the_field_of_view_is_in_the_light_bars(tmp_path, view):
    """Without EXIF, rtloop-scene records the scene at one board standard deviation of the field of view
    either side, and rtloop-fit adds the light's shift between them to its bars: the true light within 3 of
    them on every axis the bars determine (an axis they do not, the bars say why)."""
    photo = _without_exif(view, tmp_path)
    assert scene_main(_scene_args(view, photo, tmp_path / "scene")) == 0
    record = json.loads((tmp_path / "scene" / "scene.json").read_text())["meta"]["acquisition"]["field_of_view"]
    assert len(record["alternates"]) == 2 and record["std_deg"] > 0
    result = _fit_no_exif(tmp_path / "scene", tmp_path / "fit")
    bars = result["fit_report"]["uncertainty"]["bars"]
    carried = bars["field_of_view"]
    assert carried["std_deg"] == record["std_deg"] and carried["light_shift_m"] > 0
    err = np.abs(np.subtract(result["light"]["position"], _meta(view)["light"]["position"]))
    for c, e in zip("xyz", err):  # each axis within 3 of its sigma, or said not to be determined
        sigma = bars["sigma"][f"light.position.{c}"]
        assert bars["not_determined"][f"light.position.{c}"] if sigma is None else e <= 3 * sigma, (view, c, e, sigma)


def test_the_carried_field_of_view_shift_matches_scenes_built_at_it(tmp_path):
    """The light shift rtloop-fit carries from the recorded alternates agrees (within 25 %) with the light
    moved by building the scene again with --vfov at one standard deviation either side and fitting each: the
    alternates stand for what the field of view's error does to the whole acquisition. The long-lens view,
    where the light moves most per degree."""
    view = "low"
    photo = _without_exif(view, tmp_path)
    assert scene_main(_scene_args(view, photo, tmp_path / "scene")) == 0
    scene = json.loads((tmp_path / "scene" / "scene.json").read_text())
    vfov, std = scene["camera"]["vfov_deg"], scene["meta"]["acquisition"]["field_of_view"]["std_deg"]
    carried = _fit_no_exif(tmp_path / "scene", tmp_path / "fit")["fit_report"]["uncertainty"]["bars"]["field_of_view"]
    lights = []
    for sign in (-1, 1):
        folder = tmp_path / f"at{sign}"
        assert scene_main(_scene_args(view, photo, folder, "--vfov", repr(vfov + sign * std))) == 0
        lights.append(_fit_no_exif(folder, tmp_path / f"fit{sign}", "--uncertainty", "off")["light"]["position"])
    rebuilt = 0.5 * float(np.linalg.norm(np.subtract(lights[1], lights[0])))
    assert abs(carried["light_shift_m"] - rebuilt) <= 0.25 * rebuilt, (carried["light_shift_m"], rebuilt)


def test_the_board_corners_at_a_grazing_angle():
    """Every view's board gives all but at most one of its 15 inner corners, to 0.25 px RMS of their true
    projections (none a pixel off), the low view's foreshortened markers too (found in the photo enlarged
    where the photo itself places fewer corners). Truth: the renders' cameras, the board lying
    board.thickness_m above their floor."""
    from rtloop.acquisition.camera import PinholeCamera
    from rtloop.acquisition.pose import estimate_floor_pose
    from rtloop.acquisition.response import load_photo

    for view in VIEWS:
        meta = _meta(view)
        photo = load_photo(FOLDERS[view] / "photo.png", response="srgb")
        h, w = photo.shape[:2]
        camera = PinholeCamera.from_scene_camera(meta["camera"], w, h)
        pose = estimate_floor_pose(photo, meta["board"]["spec"], focal_px=camera.focal_px)
        lift = [0.0, meta["board"]["thickness_m"], 0.0]
        corners = pose.board_to_world(pose.detection.object_points.astype(float)) + lift
        off = np.linalg.norm(pose.detection.image_points - camera.project(corners), axis=1)
        rms = float(np.sqrt(np.mean(off**2)))
        assert len(off) >= 14 and rms < 0.25 and off.max() < 1.0, (view, len(off), rms, off.max())


def test_board_alone_uncertainty_covers_its_error(monkeypatch):
    """The refusals are warranted: with the 0.3 deg gate lifted, the board's own standard deviation of the
    field of view (from the calibration's covariance and reprojection residual) exceeds the target on every
    view, and where it is under 2 deg the estimate is off by less than 3 of them. Independent truth: the
    Mitsuba renders' cameras."""
    from rtloop.acquisition import pose as pose_module
    from rtloop.acquisition._common import to_detection_grey
    from rtloop.acquisition.boards import detect_board, parse_board
    from rtloop.acquisition.response import load_photo

    target = pose_module.VFOV_TARGET_DEG
    monkeypatch.setattr(pose_module, "VFOV_TARGET_DEG", 90.0)
    estimated = 0
    for view in VIEWS:
        photo = load_photo(FOLDERS[view] / "photo.png", response="srgb")
        h, w = photo.shape[:2]
        detection = detect_board(to_detection_grey(photo), parse_board(_meta(view)["board"]["spec"]))
        try:
            f, std = pose_module.estimate_focal_from_board(detection, w, h, strict=True)
        except rtloop.RtloopError:
            continue  # seen straight down: no estimate at all
        assert std > target, (view, std)
        if std < 2.0:  # nearer degenerate (overhead: 7 deg) the linearised spread is only an order of size
            estimated += 1
            vfov = math.degrees(2 * math.atan(h / 2 / f))
            assert abs(vfov - _meta(view)["camera"]["vfov_deg"]) <= 3 * std, (view, vfov, std)
    assert estimated >= 5


def test_readme_one_photo_example(tmp_path, capsys):
    """The "One photo, end to end" commands (docs/acquisition.md) on examples/one-photo: each step prints its
    errors against the truth, the report is written, and the numbers are the targets."""
    ex = "examples/one-photo"
    root = Path(__file__).parents[1]
    out = tmp_path / "one-photo"
    assert scene_main([str(root / ex / "photo.png"), "--board", "6x4,100mm,75mm,DICT_5X5_100", "--ball-radius",
                       "0.1", "--grey-card", "405,301,40,36", "--grey-card-reflectance", "0.18", "--out", str(out),
                       "--truth", str(root / ex / "scene.json")]) == 0
    printed = capsys.readouterr().out
    assert "field of view +0.000 deg" in printed and "% of its 1.73 m distance" in printed
    assert fit_cli.main([str(out / "scene.json"), str(out / "objective.png"), "--out", str(out / "fit"),
                         "--report", "--truth", str(root / ex / "scene.json")]) == 0
    printed = capsys.readouterr().out
    assert "light position error:" in printed and "absolute, from the grey card of reflectance 0.18" in printed
    assert "(split)" not in printed  # the card fixes each albedo, not only the products
    page = (out / "fit" / "report.html").read_text()
    assert "Absolute, from the grey card" in page and "light intensity (W/sr)" in page
    result = json.loads((out / "fit" / "result.json").read_text())
    meta = _meta("oblique")
    assert np.linalg.norm(np.subtract(result["light"]["position"], meta["light"]["position"])) < 0.05
    assert abs(result["light"]["intensity"] / meta["light"]["intensity_w_sr"] - 1) < 0.03

    (out / "card.png").unlink()  # a scene naming a card mask that is gone: one line naming it
    assert fit_cli.main([str(out / "scene.json"), str(out / "objective.png"), "--out", str(tmp_path / "f2")]) != 0
    err = capsys.readouterr().err
    assert "meta.acquisition.grey_card.mask names card.png" in err and len(err.strip().splitlines()) == 1


def test_raw_photo_in_rtloop_fit(tmp_path, capsys):
    """rtloop-fit reads a camera RAW (DNG) photo through rawpy: linear (a flat DNG of code c at 12 bits is
    c / 4095 everywhere, the closed form), and result.json records the white balance LibRaw applied."""
    pytest.importorskip("rawpy")
    from test_acquisition_response import _flat_dng

    dng = _flat_dng(tmp_path / "flat.dng", 1200, w=64, h=48)
    scene = {"image": {"width": 32, "height": 24},
             "camera": {"position": [0, 1, -4], "look_at": [0, 0.5, 0], "vfov_deg": 40},
             "light": {"position": [1, 3, -1], "intensity": 20},
             "objects": [{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0]}],
             "fit": {"objects.floor.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]}}}
    assert np.allclose(rtloop.load_image(dng, (32, 24)), 1200 / 4095, atol=2e-4)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))
    assert fit_cli.main([str(path), str(dng), "--out", str(tmp_path / "fit"), "--snapshot-every", "0",
                         "--final-scale", "1", "--final-spp", "1"]) == 0
    inputs = json.loads((tmp_path / "fit" / "result.json").read_text())["fit_report"]["inputs"]
    assert inputs["response"] == "raw" and len(inputs["raw"]["white_balance"]) == 4
    assert inputs["raw"]["white_level"] == 4095
    capsys.readouterr()


@pytest.mark.parametrize("view", VIEWS)
def test_the_views_are_framed_as_their_scene(built, view):
    """The scene rtloop-scene wrote frames the photo as it is (the ChArUco board's texture on the floor and
    the card left out by the mask): the outlines registered in place, forced whatever the residual."""
    from rtloop.fit import framing
    from rtloop.fit.files import fit_inputs, load_inputs

    code, out = built[view]
    assert code == 0
    inputs = load_inputs(out / "scene.json", out / "objective.png")
    result = fit_inputs(inputs, uncertainty=False, framing="off")
    use = None if inputs.mask is None else np.flatnonzero(inputs.mask.ravel())
    check, _ = framing.measure(result.scene, inputs.image, use, framing._compared(result))
    assert check["checked"] and not check["mismatch"], check
