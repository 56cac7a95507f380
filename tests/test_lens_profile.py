"""A photo through a lens Lensfun has a profile of: its distortion and vignetting removed by rtloop-scene.

The photo is a Mitsuba render with truth (tests/fixtures/onephoto/side, a pinhole camera) taken through a
real lens as Lensfun describes it: Canon's EF-S 18-55 mm IS II at 18 mm and f/3.5 on an EOS 600D, barrel
distortion (the centre magnified 2.9 % against the corners) and its vignetting (the corners at 46 % of the
centre), in linear light, then sRGB 8-bit with the EXIF a camera writes (make, model, lens, focal length,
f-number). The scene and the fit are judged against the render's truth, which the pipeline does not see."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from rtloop import cli as fit_cli
from rtloop._srgb import encode
from rtloop.acquisition.lens_profile import LensExif, find_lens_profile, read_lens_exif
from rtloop.cli.scene import scene_main

lensfunpy = pytest.importorskip("lensfunpy")

VIEW = Path(__file__).parent / "fixtures" / "onephoto" / "side"
CAMERA = ("Canon", "Canon EOS 600D")
LENS = "EF-S18-55mm f/3.5-5.6 IS II"  # as Canon writes it in EXIF's LensModel
FOCAL_MM, F_NUMBER = 18.0, 3.5


def _meta() -> dict:
    return json.loads((VIEW / "meta.json").read_text())


def _linear(path: Path) -> np.ndarray:
    c = np.asarray(Image.open(path).convert("RGB"), np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _lens_modifier(w: int, h: int, flags: int, reverse: bool = False):
    db = lensfunpy.Database()
    camera = db.find_cameras(*CAMERA)[0]
    lens = db.find_lenses(camera, None, LENS)[0]
    m = lensfunpy.Modifier(lens, camera.crop_factor, w, h)
    m.initialize(FOCAL_MM, F_NUMBER, 1000.0, scale=1.0, pixel_format=np.float32, flags=flags, reverse=reverse)
    return m


def through_the_lens(pinhole: np.ndarray, vfov_deg: float, path: Path) -> None:
    """Write what the lens makes of a pinhole's linear image of vertical field of view ``vfov_deg``: the
    distortion (Lensfun's reverse map), the falloff on the sensor, sRGB 8-bit, and the camera's EXIF (its
    focal length the paraxial one: the pinhole's, scaled by the distortion's centre derivative)."""
    h, w = pinhole.shape[:2]
    back = _lens_modifier(w, h, lensfunpy.ModifyFlags.DISTORTION, reverse=True).apply_geometry_distortion()
    photo = cv2.remap(pinhole, back, None, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    gain = np.ones_like(photo)
    _lens_modifier(w, h, lensfunpy.ModifyFlags.VIGNETTING).apply_color_modification(gain)
    photo = np.clip(photo / gain, 0.0, 1.0)
    centre = float(np.hypot(*(back[h // 2, w // 2 + 1] - back[h // 2, w // 2 - 1]))) / 2.0
    focal_px = (h / 2.0) / math.tan(math.radians(vfov_deg) / 2.0) / centre
    exif = Image.Exif()
    exif[0x010F], exif[0x0110] = CAMERA
    exif.get_ifd(0x8769).update({0xA434: LENS, 0x920A: FOCAL_MM, 0x829D: F_NUMBER, 0xA20E: focal_px / FOCAL_MM,
                                 0xA210: 4})
    Image.fromarray((encode(photo) * 255.0 + 0.5).astype(np.uint8)).save(path, exif=exif)


@pytest.fixture(scope="module")
def lens_photo(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("lens") / "photo.png"
    through_the_lens(_linear(VIEW / "photo.png"), _meta()["camera"]["vfov_deg"], path)
    return path


def _scene_args(photo: Path, out: Path, *extra: str) -> list[str]:
    meta = _meta()
    return [str(photo), "--board", meta["board"]["spec"], "--ball-radius", str(meta["ball"]["radius"]),
            "--grey-card", ",".join(map(str, meta["grey_card"]["rect_px"])),
            "--grey-card-reflectance", str(meta["grey_card"]["reflectance"]), "--out", str(out), *extra]


def _scene_and_fit(photo: Path, out: Path, *extra: str) -> tuple[dict, dict]:
    assert scene_main(_scene_args(photo, out / "scene", *extra)) == 0
    assert fit_cli.main([str(out / "scene" / "scene.json"), str(out / "scene" / "objective.png"), "--out",
                         str(out / "fit"), "--snapshot-every", "0", "--final-scale", "1", "--final-spp", "1",
                         "--uncertainty", "off", "--quiet"]) == 0
    return (json.loads((out / "scene" / "scene.json").read_text()),
            json.loads((out / "fit" / "result.json").read_text()))


def test_the_lens_is_found_from_the_exif(lens_photo):
    named = read_lens_exif(lens_photo)
    assert named is not None and (named.make, named.model, named.lens_model) == (*CAMERA, LENS)
    profile, why = find_lens_profile(named)
    assert profile is not None and why == ""
    assert "18-55mm f/3.5-5.6 IS II" in profile.name


def test_the_corrected_photo_is_the_pinhole_render(lens_photo):
    """Distortion and falloff removed, the photo is the Mitsuba pinhole render again: inside a margin the
    resampling blurs, within 2 % of the render's mean level (8-bit rounding and interpolation), against
    11 % for the photo as taken."""
    named = read_lens_exif(lens_photo)
    profile, _ = find_lens_profile(named)
    truth = _linear(VIEW / "photo.png")
    h, w = truth.shape[:2]
    focal_px = (h / 2.0) / math.tan(math.radians(_meta()["camera"]["vfov_deg"]) / 2.0)
    remap = profile.remap(w, h, focal_px)
    taken = _linear(lens_photo)
    fixed = remap.correct(taken)
    inner = (slice(24, h - 24), slice(24, w - 24))
    level = float(truth[inner].mean())
    assert float(np.abs(fixed[inner] - truth[inner]).mean()) < 0.02 * level
    assert float(np.abs(taken[inner] - truth[inner]).mean()) > 0.05 * level


def test_points_move_with_the_image(lens_photo):
    """A pixel position on the photo as taken lands where the resampled photo shows it: a bright dot drawn
    on the photo is found where ``points`` puts it, to a tenth of a pixel."""
    profile, _ = find_lens_profile(read_lens_exif(lens_photo))
    w, h = 640, 480
    remap = profile.remap(w, h, 500.0)
    for x, y in [(40.0, 30.0), (600.5, 440.25), (320.0, 240.0), (100.0, 400.0)]:
        dot = np.zeros((h, w), np.float32)
        yy, xx = np.mgrid[0:h, 0:w]
        dot[:] = np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * 2.0**2))
        moved = remap.image(dot)
        m = moved > 0.05 * moved.max()
        centroid = np.array([(xx * moved)[m].sum(), (yy * moved)[m].sum()]) / moved[m].sum()
        assert np.linalg.norm(centroid - remap.points(np.array([[x, y]]))[0]) < 0.1, (x, y, centroid)


def test_scene_and_light_through_the_lens_match_the_truth(lens_photo, tmp_path):
    """With the profile: the field of view within 0.3 deg, the camera and the ball within 1 % of their
    distances, the light within 5 cm and both albedos within 3 % (the one-photo targets); the scene records
    the profile. The same photo taken as a pinhole's (--lens-profile off) misses the light's target: the
    profile is what makes the difference."""
    meta = _meta()
    scene, result = _scene_and_fit(lens_photo, tmp_path / "on")
    record = scene["meta"]["acquisition"]["lens_profile"]
    assert record["distortion"] and record["vignetting"] and record["focal_mm"] == FOCAL_MM
    assert abs(scene["camera"]["vfov_deg"] - meta["camera"]["vfov_deg"]) < 0.3
    cam_err = np.linalg.norm(np.subtract(scene["camera"]["position"], meta["camera"]["position"]))
    assert cam_err < 0.01 * np.linalg.norm(meta["camera"]["position"])
    ball = next(o for o in scene["objects"] if o["shape"] == "sphere")
    assert np.linalg.norm(np.subtract(ball["center"], meta["ball"]["centre"])) < 0.01 * meta["ball"]["distance_from_camera_m"]
    light = float(np.linalg.norm(np.subtract(result["light"]["position"], meta["light"]["position"])))
    assert light < 0.05, f"light {1000 * light:.1f} mm off"
    albedos = {o["name"]: o["material"]["albedo"] for o in result["objects"]}
    for name, true in (("ball", meta["ball"]["albedo"]), ("floor", meta["floor_albedo"])):
        assert np.all(np.abs(np.subtract(albedos[name], true)) / np.asarray(true) < 0.03), (name, albedos[name])
    scene_off, result_off = _scene_and_fit(lens_photo, tmp_path / "off", "--lens-profile", "off")
    assert "lens_profile" not in scene_off["meta"]["acquisition"]
    assert float(np.linalg.norm(np.subtract(result_off["light"]["position"], meta["light"]["position"]))) > 0.05


@pytest.mark.parametrize("named, reason", [
    (None, "names no camera"),
    (LensExif("Canon", "Canon EOS 600D", None, LENS, None, 3.5, None), "no focal length"),
    (LensExif("Nobody", "Pinhole 1", None, LENS, 18.0, 3.5, None), "not in Lensfun's database"),
    (LensExif("Canon", "Canon EOS 600D", None, "EF-S 1-2mm f/9 Imaginary", 18.0, 3.5, None),
     "not in Lensfun's database"),
    (LensExif("Canon", "Canon EOS 600D", None, None, 18.0, 3.5, None), "names no lens"),
    (LensExif("Canon", "Canon EOS 600D", None, LENS, 200.0, 3.5, None), "outside"),
])
def test_no_profile_says_why(named, reason):
    profile, why = find_lens_profile(named)
    assert profile is None and reason in why, why


def test_an_unknown_lens_is_one_line_and_the_photo_a_pinholes(tmp_path, capsys):
    """A lens Lensfun does not know: rtloop-scene says so in one line and builds the scene as before."""
    photo = tmp_path / "photo.png"
    shutil.copy(VIEW / "photo.png", photo)
    with Image.open(photo) as im:
        exif = im.getexif()
        exif[0x010F], exif[0x0110] = CAMERA
        exif.get_ifd(0x8769)[0xA434] = "EF-S 1-2mm f/9 Imaginary"
        im.save(tmp_path / "named.png", exif=exif)
    assert scene_main(_scene_args(tmp_path / "named.png", tmp_path / "out")) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "lens profile" in line]
    assert len(err) == 1 and "not in Lensfun's database" in err[0], err
    scene = json.loads((tmp_path / "out" / "scene.json").read_text())
    assert "lens_profile" not in scene["meta"]["acquisition"]


EXIF_TEXT = st.one_of(st.none(), st.text(max_size=40), st.binary(max_size=40),
                      st.sampled_from(["Canon", "Canon EOS 600D", LENS, "NIKON CORPORATION", "\x00\x00", "x" * 300]))


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(make=EXIF_TEXT, model=EXIF_TEXT, lens=EXIF_TEXT,
       focal=st.one_of(st.none(), st.sampled_from([18.0, 0.0, -5.0, 1e9, 55.0, 24.0, (1, 0)])),
       f_number=st.one_of(st.none(), st.sampled_from([3.5, 0.0, 1e6, 8.0])))
def test_any_exif_gives_a_profile_with_finite_maps_or_a_reason(tmp_path_factory, make, model, lens, focal, f_number):
    """Whatever the EXIF's strings and numbers: a profile whose resampling and points are finite, or None
    and a reason; never an exception."""
    path = tmp_path_factory.mktemp("lensexif") / "p.png"
    exif = Image.Exif()
    try:
        for tag, value in ((0x010F, make), (0x0110, model)):
            if value is not None:
                exif[tag] = value
        sub = exif.get_ifd(0x8769)
        for tag, value in ((0xA434, lens), (0x920A, focal), (0x829D, f_number)):
            if value is not None:
                sub[tag] = value
        Image.new("RGB", (32, 24), (90, 90, 90)).save(path, exif=exif)
    except Exception:  # noqa: BLE001 - a value Pillow cannot write: nothing to read back
        return
    profile, why = find_lens_profile(read_lens_exif(path))
    if profile is None:
        assert why and "\n" not in why
        return
    remap = profile.remap(32, 24, 30.0)
    out = remap.correct(np.full((24, 32, 3), 0.5, np.float32))
    assert np.isfinite(out).all() and (out >= 0).all()
    assert math.isfinite(remap.focal_px) and remap.focal_px > 0
    assert np.isfinite(remap.points(np.array([[0.0, 0.0], [31.0, 23.0]]))).all()
