"""Hard inputs: every out-of-range argument or scene number is an RtloopError naming it, doubtful
images are refused or warned about, resources are capped (docs/scene-format.md: "Input limits")."""

from __future__ import annotations

import copy
import math
import os
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import rtloop
from conftest import BALL_ON_FLOOR, shared_case, shared_case_names
from rtloop.fit.protocol import max_threads


@pytest.fixture
def photo(ball_scene) -> np.ndarray:
    return rtloop.render(ball_scene)


def _fit(scene, image, **kw):
    kw.setdefault("generations", 1)
    kw.setdefault("population", 4)
    kw.setdefault("uncertainty", False)
    return rtloop.fit(scene, image, **kw)


@pytest.mark.parametrize(
    ("kw", "name"),
    [
        ({"generations": (1,)}, "generations"),
        ({"generations": (1, 2, 3)}, "generations"),
        ({"generations": 1.5}, "generations"),
        ({"generations": -1}, "generations"),
        ({"generations": (1, -1)}, "generations[1]"),
        ({"threads": 0}, "threads"),
        ({"threads": -1}, "threads"),
        ({"threads": 2**40}, "threads"),
        ({"threads": 2.0}, "threads"),
        ({"polish": -5}, "polish"),
        ({"polish": 10**7}, "polish"),
        ({"seed": -1}, "seed"),
        ({"seed": 2**64}, "seed"),
        ({"seed": "1"}, "seed"),
        ({"f": math.nan}, "f"),
        ({"f": 0.0}, "f"),
        ({"f": math.inf}, "f"),
        ({"cr": -1}, "cr"),
        ({"cr": math.nan}, "cr"),
        ({"population": 3}, "population"),
        ({"population": 10**9}, "population"),
        ({"population": True}, "population"),
        ({"pixels_per_object": 0}, "pixels_per_object"),
    ],
)
def test_fit_arguments_out_of_range_name_the_argument(ball_scene, photo, kw, name):
    with pytest.raises(rtloop.RtloopError, match=rf"^{name.replace('[', '.').replace(']', '.')}: "):
        _fit(ball_scene, photo, **kw)


def test_threads_limit_follows_the_cores(ball_scene, photo):
    assert max_threads() == min(1024, 64 * (os.cpu_count() or 1))
    with pytest.raises(rtloop.RtloopError, match="^threads: must be between 1 and"):
        _fit(ball_scene, photo, threads=max_threads() + 1)
    _fit(ball_scene, photo, threads=max_threads())  # the limit itself is accepted


def test_population_times_pixels_is_capped_before_allocating(ball_scene):
    big = copy.deepcopy(ball_scene)
    big["image"] = {"width": 16384, "height": 16384}
    image = np.zeros((1, 1, 3), np.float32)  # never reached: the cap is checked first
    with pytest.raises(rtloop.RtloopError, match=r"^population: 100 individuals x 268435456 pixels"):
        _fit(big, image, population=100)


@pytest.mark.parametrize(
    ("args", "name"),
    [((-1, 12), "width"), ((12, 0), "height"), ((2**40, 12), "width"), ((12.5, 12), "width")],
)
def test_render_size_out_of_range_names_the_argument(ball_scene, args, name):
    with pytest.raises(rtloop.RtloopError, match=f"^{name}: "):
        rtloop.render(ball_scene, *args)
    with pytest.raises(rtloop.RtloopError, match=f"^{name}: "):
        rtloop.object_ids(ball_scene, *args)


@pytest.mark.parametrize("spp", [0, -1, 4097, 2**40])
def test_render_spp_out_of_range(ball_scene, spp):
    with pytest.raises(rtloop.RtloopError, match="^spp: must be between 1 and 4096"):
        rtloop.render(ball_scene, 8, 6, spp)


# ---------------------------------------------------------------- scene numbers


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda s: s["light"].__setitem__("color", [1e308, 1, 1]), "light.color"),
        (lambda s: s.__setitem__("exposure", 1e308), "exposure"),
        (lambda s: s["light"].__setitem__("position", [0, 1e200, 0]), "light.position"),
        (lambda s: s["objects"][0].__setitem__("radius", 1e300), "objects[0].radius"),
        (lambda s: s["fit"].__setitem__("objects.ball.albedo", {"min": 1e307, "max": 1e308}),
         'fit["objects.ball.albedo"].min'),
        (lambda s: s["fit"].__setitem__("light.position", {"min": [-1e308, 0, 0], "max": [1e308, 1, 1]}),
         'fit["light.position"].min'),
    ],
)
def test_huge_finite_scene_numbers_are_refused_at_load(ball_scene, edit, field):
    edit(ball_scene)
    with pytest.raises(rtloop.SceneError, match=f"^{field.replace('[', '.').replace(']', '.')}: "
                                                 r".*within \+-1e8"):
        rtloop.load_scene(ball_scene)


@pytest.mark.parametrize("where", ["value", "bound"])
def test_light_intensity_has_its_own_larger_limit(ball_scene, where):
    # intensity grows with distance squared: a kilometre-sized scene needs 1e8 and more
    ball_scene["light"]["intensity"] = 1e20
    ball_scene["fit"]["light.intensity"] = {"min": 1, "max": 1e20}
    rtloop.load_scene(ball_scene)
    if where == "value":
        ball_scene["light"]["intensity"] = 1.1e20
    else:
        ball_scene["fit"]["light.intensity"]["max"] = 1.1e20
    with pytest.raises(rtloop.SceneError, match=r"light\.intensity.*within \+-1e20"):
        rtloop.load_scene(ball_scene)


def test_the_magnitude_limit_itself_is_accepted(ball_scene):
    ball_scene["fit"]["light.intensity"] = {"min": 1, "max": 1e8}
    ball_scene["light"]["intensity"] = 1e8
    ball_scene["light"]["color"] = [1e8, 1, 1]
    ball_scene["exposure"] = 1e-8
    img = rtloop.render(ball_scene)
    assert np.isfinite(img).all()


@pytest.mark.parametrize("huge", [1e300, 1e-300])
def test_directions_of_any_finite_size_are_valid(ball_scene, huge):
    ref = rtloop.render(ball_scene)
    ball_scene["objects"][1]["normal"] = [0, huge, 0]
    ball_scene["camera"]["up"] = [0, huge, 0]
    np.testing.assert_array_equal(rtloop.render(ball_scene), ref)
    d = copy.deepcopy(ball_scene)
    d["light"] = {"type": "directional", "direction": [huge, huge, 0], "intensity": 3}
    del d["fit"]["light.position"]
    s = rtloop.load_scene(d)
    np.testing.assert_allclose(rtloop.scene_to_dict(s)["light"]["direction"], [0.5**0.5, 0.5**0.5, 0], rtol=1e-15)


@pytest.mark.parametrize("lo", [0, -1])
def test_exposure_bounds_containing_zero_are_refused_at_load(ball_scene, lo):
    ball_scene["fit"]["exposure"] = {"min": lo, "max": 2}
    with pytest.raises(rtloop.SceneError, match=r'^fit."exposure".\.min: must be > 0 for exposure'):
        rtloop.load_scene(ball_scene)


# ---------------------------------------------------------------- images and masks


def test_uint8_image_is_refused_with_the_way_to_load_it(ball_scene, photo):
    code = (np.clip(photo, 0, 1) * 255).astype(np.uint8)
    with pytest.raises(rtloop.RtloopError, match=r"^image: a uint8 array .*rtloop\.load_image"):
        _fit(ball_scene, code)


@pytest.mark.parametrize("dtype", [np.complex64, np.uint16, np.int32, bool, object])
def test_non_float_images_are_refused(ball_scene, photo, dtype):
    with pytest.raises(rtloop.RtloopError, match="^image: "):
        _fit(ball_scene, photo.astype(dtype))


def test_negative_image_values_warn(ball_scene, photo):
    photo = photo.copy()
    photo[0, 0, 1] = -0.25
    with pytest.warns(rtloop.RtloopWarning, match=r"^image: 0.01% of the values are negative \(min -0.25\)"):
        _fit(ball_scene, photo)


# A photo 255 times too bright pins the light's intensity at its bound: expected here.
@pytest.mark.filterwarnings("ignore:fitted values at their fit bounds:rtloop.errors.RtloopWarning")
def test_image_mostly_above_one_warns_in_python_and_in_the_report(ball_scene, photo):
    with pytest.warns(rtloop.RtloopWarning, match="above 1"):
        result = _fit(ball_scene, photo * 255 + 2)
    assert any("above 1" in w for w in result.report()["warnings"])


def test_an_ordinary_image_gives_no_input_warning(ball_scene, photo):
    result = _fit(ball_scene, photo)
    assert not [w for w in result.warnings if w.startswith("image:")]


# The sRGB-encoded floats, fitted as if linear, can pin the light at a bound: expected here.
@pytest.mark.filterwarnings("ignore:fitted values at their fit bounds:rtloop.errors.RtloopWarning")
@pytest.mark.parametrize("name", shared_case_names())
def test_an_srgb_encoded_float_image_is_doubted_and_a_linear_one_is_not(name):
    """Floats are taken as linear radiance; an sRGB encoding passed as floats (a PNG's codes / 255) is told
    apart by the fit itself: its decoding fits markedly better. Checked on the independent reference scenes
    (Mitsuba), whose linear objectives must raise no such doubt."""
    case = shared_case(name)
    scene = rtloop.load_scene(case / "scene_input.json")
    linear = rtloop.load_image(case / "objective.png", scene)
    encoded = np.asarray(Image.open(case / "objective.png").convert("RGB"), np.float32) / 255
    assert not [w for w in rtloop.fit(scene, linear, uncertainty=False).warnings if "sRGB-encoded" in w]
    with pytest.warns(rtloop.RtloopWarning, match=r"^image: it looks sRGB-encoded.*rtloop\.srgb_to_linear"):
        result = rtloop.fit(scene, encoded, uncertainty=False)
    assert result.model["encoding"]["suspect"]
    assert any("sRGB-encoded" in w for w in result.report()["warnings"])


@pytest.mark.filterwarnings("ignore:fitted values at their fit bounds:rtloop.errors.RtloopWarning")
def test_an_image_declared_linear_is_not_doubted():
    """``tone="linear"`` (what rtloop-fit passes for a file read with --response linear) declares the values
    linear radiance: the sRGB codes / 255 that the check above doubts raise no doubt and no extra fit."""
    case = shared_case(shared_case_names()[0])
    scene = rtloop.load_scene(case / "scene_input.json")
    encoded = np.asarray(Image.open(case / "objective.png").convert("RGB"), np.float32) / 255
    result = rtloop.fit(scene, encoded, uncertainty=False, tone="linear")
    assert not [w for w in result.warnings if "sRGB-encoded" in w]
    assert result.model["encoding"] == {"suspect": False, "why": result.model["encoding"]["why"]}
    assert "declared linear" in result.model["encoding"]["why"]
    assert "tone" not in result.model.get("camera", {}).get("terms", [])


def test_a_photo_of_decoded_8_bit_codes_is_not_checked_for_an_encoding():
    """An image every value of which is an 8-bit sRGB code's linear value (a PNG as load_image reads it) was
    decoded, so it is linear: the encoding check's extra base fit is skipped (2.5 ms on a photo the base
    model does not explain). The same photo nudged off the codes is checked, and found linear."""
    case = Path(__file__).parent / "fixtures" / "photos" / "env-overhead"
    scene = rtloop.load_scene(case / "scene_input.json")
    photo = rtloop.load_image(case / "objective.png", scene)
    decoded = rtloop.fit(scene, photo, uncertainty=False).model["encoding"]
    assert decoded["suspect"] is False and "ratio_decoded" not in decoded and "8-bit" in decoded["why"]
    nudged = np.nextafter(photo, np.float32(0.5))  # one float step towards mid-grey: no longer a code's value
    checked = rtloop.fit(scene, nudged, uncertainty=False).model["encoding"]
    assert checked["suspect"] is False and checked["ratio_decoded"] > checked["ratio_as_given"]


def test_srgb_to_linear_matches_published_values():
    """IEC 61966-2-1 anchors: codes 0 and 255 are 0 and 1; 8-bit 128 is 0.21586 (mid-grey 119 is 0.18447);
    uint16 and [0, 1] floats read the same encoding."""
    codes = np.array([[[0, 128, 255]], [[119, 10, 1]]], np.uint8)
    out = rtloop.srgb_to_linear(codes)
    assert out.dtype == np.float32
    assert np.allclose(out[0, 0], [0.0, 0.215861, 1.0], atol=2e-6)
    assert np.allclose(out[1, 0], [0.184475, 0.003035, 0.000304], atol=2e-6)
    assert np.allclose(rtloop.srgb_to_linear(codes.astype(np.uint16) * 257), out, atol=1e-7)
    assert np.allclose(rtloop.srgb_to_linear(codes / 255.0), out, atol=1e-7)
    for bad in (np.array([1.5]), np.array([np.nan]), np.array([-0.1]), np.array([1 + 1j])):
        with pytest.raises(rtloop.RtloopError, match="^srgb_to_linear: "):
            rtloop.srgb_to_linear(bad)


def test_fitted_values_at_their_bounds_warn(ball_scene, photo):
    # the photo is far brighter than any intensity in [1, 2] can make it: the fit ends at the bound
    ball_scene["fit"]["light.intensity"] = {"min": 1, "max": 2}
    with pytest.warns(rtloop.RtloopWarning, match=r"at their fit bounds: .*light\.intensity = 2\b"):
        result = _fit(ball_scene, np.minimum(photo * 8, 1))
    assert any("light.intensity = 2" in w for w in result.warnings)


@pytest.mark.parametrize(
    ("mask", "why"),
    [(np.full((48, 64), np.nan), "NaN"), (np.full((48, 64), 0.5), "other than 0 and 1"),
     (np.full((48, 64), "x"), "dtype")],
)
def test_bad_masks_are_refused(ball_scene, photo, mask, why):
    with pytest.raises(rtloop.RtloopError, match=f"^mask: .*{why}"):
        _fit(ball_scene, photo, mask=mask)


def test_python_magnitude_limit_is_the_cores(ball_scene):
    from rtloop.scene import MAX_MAGNITUDE

    ball_scene["light"]["color"] = [MAX_MAGNITUDE, 1, 1]
    rtloop.load_scene(ball_scene)
    ball_scene["light"]["color"] = [np.nextafter(MAX_MAGNITUDE, math.inf), 1, 1]
    with pytest.raises(rtloop.SceneError, match="within"):
        rtloop.load_scene(ball_scene)



# ---------------------------------------------------------------- files and imports


def _png_claiming(path, width: int, height: int) -> None:
    """A tiny valid-looking PNG whose header claims width x height (a decompression bomb's header)."""
    import io
    import struct
    import zlib

    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (1, 1)).save(buf, "PNG")
    data = bytearray(buf.getvalue())
    ihdr = data.index(b"IHDR")
    data[ihdr + 4:ihdr + 12] = struct.pack(">II", width, height)
    data[ihdr + 17:ihdr + 21] = struct.pack(">I", zlib.crc32(bytes(data[ihdr:ihdr + 17])))
    path.write_bytes(bytes(data))


@pytest.mark.parametrize(("w", "h", "said"), [(16384, 12288, "more than 179"), (12000, 11000, "12000x11000 = 132")])
def test_load_image_refuses_a_huge_claimed_size_before_decoding(tmp_path, w, h, said):
    from rtloop.acquisition.objective import MAX_DECODED_PIXELS

    bomb = tmp_path / "bomb.png"
    _png_claiming(bomb, w, h)
    with pytest.raises(rtloop.AcquisitionError, match=rf"bomb\.png: image claims {said} megapixels"):
        rtloop.load_image(bomb, (64, 48))
    assert w * h > MAX_DECODED_PIXELS >= 100_000_000  # a 100-megapixel photo still loads


def test_aspect_ratio_error_names_the_python_argument(tmp_path):
    """From Python the error names ``crop=True``; rtloop-fit says ``--crop`` (tests/test_cli.py)."""
    from PIL import Image

    path = tmp_path / "square.png"
    Image.new("RGB", (32, 32)).save(path)
    with pytest.raises(rtloop.AcquisitionError, match=r"pass crop=True$") as info:
        rtloop.load_image(path, (64, 48))
    assert "--crop" not in str(info.value)


@pytest.mark.parametrize("module", ["rtloop", "rtloop.cli"])
def test_import_does_not_load_opencv(module):
    import subprocess
    import sys

    code = f"import sys, {module}; print('cv2' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize(("ci", "outcome"), [("true", pytest.fail.Exception), ("", pytest.skip.Exception),
                                             ("false", pytest.skip.Exception)])
def test_absent_shared_inputs_fail_under_ci(monkeypatch, ci, outcome):
    from conftest import shared_case

    monkeypatch.setenv("CI", ci)
    with pytest.raises(outcome, match="no-such-case"):
        shared_case("no-such-case")


# ---------------------------------------------------------------- fitted values inside their bounds


def _inside(result) -> list[str]:
    s = result.scene
    return [f"{n} = {v} not in [{lo}, {hi}]" for n, v, (lo, hi) in zip(s.param_names(), s.get_params(), s.bounds())
            if not lo <= v <= hi]


# Bounds deliberately narrower than the truth: values at them are the point.
@pytest.mark.filterwarnings("ignore:fitted values at their fit bounds:rtloop.errors.RtloopWarning")
@pytest.mark.parametrize(
    ("ball_albedo", "imax", "seed"),
    [((1, 1), 400, 0), ((1, 1), 75, 1), ((0.9, 1), 72, 2), ((0, 1), 71, 3), ((0.95, 1), 400, 4)],
)
def test_two_stage_fits_stay_inside_the_scenes_bounds(ball_scene, ball_albedo, imax, seed):
    truth = copy.deepcopy(ball_scene)
    truth["objects"][0]["material"]["albedo"] = [0.95, 0.9, 0.85]
    truth["objects"][1]["material"]["albedo"] = [0.9, 0.9, 0.9]
    photo = rtloop.render(truth)
    ball_scene["fit"]["light.intensity"] = {"min": 1, "max": imax}
    ball_scene["fit"]["objects.ball.albedo"] = {"min": [ball_albedo[0]] * 3, "max": [ball_albedo[1]] * 3}
    result = rtloop.fit(ball_scene, photo, protocol="paper", generations=(20, 20), seed=seed, uncertainty=False)
    assert _inside(result) == []
    assert all(math.isfinite(v) for row in result.products.values() for v in row)



def _extreme(edit):
    d = copy.deepcopy(BALL_ON_FLOOR)
    edit(d)
    return d


@pytest.mark.parametrize(
    ("edit", "kw"),
    [
        (lambda d: d["light"].__setitem__("color", [1e8, 1, 1]), {}),
        (lambda d: d.__setitem__("exposure", 1e8), {}),
        (lambda d: (d["fit"].__setitem__("objects.ball.albedo", {"min": 1e7, "max": 1e8}),
                    d["objects"][0]["material"].__setitem__("albedo", [1e7] * 3)), {}),
        (lambda d: d["fit"].__setitem__("light.position", {"min": [-1e8, 0.5, -1e8], "max": [1e8] * 3}),
         {"protocol": "paper", "generations": 5}),
        (lambda d: d["fit"].__setitem__("exposure", {"min": 1e-8, "max": 1e8}), {"protocol": "paper", "generations": 5}),
    ],
)
def test_numbers_at_the_limits_fit_end_to_end_with_a_json_report(photo, edit, kw):
    """The 1e308 cases, at the largest accepted values: no bare exception from the fit or the
    uncertainty, a report JSON can hold (no inf or NaN), every value inside its bounds."""
    import json
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        result = rtloop.fit(_extreme(edit), photo, **kw)
    json.dumps(result.report(), allow_nan=False)
    assert _inside(result) == []


def _os_threads() -> int:
    with open("/proc/self/status", encoding="ascii") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("Threads:"))


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="counts threads through Linux's /proc")
def test_worker_pools_are_not_kept_for_every_thread_count(ball_scene, photo):
    """Fits on many thread counts keep only the few most recent pools (they used to stay, all of them:
    fits on 1..64 threads left 2,085 OS threads); the dropped pools' threads end."""
    from rtloop import _native

    before = _os_threads()
    for n in range(1, 13):
        _fit(ball_scene, photo, threads=n)
    kept = _native._kept_pools()
    assert kept[-4:] == [9, 10, 11, 12] and len(kept) <= 4
    # Without eviction 1 + 2 + ... + 12 = 78 threads would stay; the four kept pools have 42. Rayon ends a
    # dropped pool's threads asynchronously: wait for them (an event, not a time bound on the code).
    deadline = time.monotonic() + 60
    while _os_threads() > before + 42 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _os_threads() <= before + 42


def _fifo_with_a_late_writer(path: Path):
    """A FIFO at ``path`` and a process that opens it for writing after 10 s: a reader that blocked in
    open() is then let through (to fail its test) instead of hanging it."""
    import subprocess

    os.mkfifo(path)
    return subprocess.Popen(["sh", "-c", 'sleep 10; : > "$0"', str(path)])


@pytest.mark.parametrize("reader", ["load_image", "load_mask", "load_photo", "load_scene", "load_objects"])
def test_a_fifo_input_is_refused_at_once_naming_it(tmp_path, ball_scene, reader):
    from rtloop.acquisition.response import load_photo
    from rtloop.insert import load_objects

    fifo = tmp_path / ("in.json" if reader in ("load_scene", "load_objects") else "in.png")
    writer = _fifo_with_a_late_writer(fifo)
    call = {"load_image": lambda: rtloop.load_image(fifo, (64, 48)), "load_mask": lambda: rtloop.load_mask(fifo, (64, 48)),
            "load_photo": lambda: load_photo(fifo), "load_scene": lambda: rtloop.load_scene(fifo),
            "load_objects": lambda: load_objects(fifo)}[reader]
    try:
        with pytest.raises(rtloop.RtloopError, match=r"in\.\w+: is a FIFO \(named pipe\), not a regular file"):
            call()
    finally:
        writer.kill()
        writer.wait()


@pytest.mark.parametrize("device", ["/dev/null", "/dev/zero"])
def test_a_device_photo_is_refused_before_it_is_read(tmp_path, ball_scene, device):
    link = tmp_path / "photo.png"
    link.symlink_to(device)
    with pytest.raises(rtloop.RtloopError, match=r"photo\.png: is a character device, not a regular file"):
        rtloop.load_image(link, (64, 48))
