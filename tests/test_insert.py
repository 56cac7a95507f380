"""Virtual object insertion: the differential-rendering identities, the matte, the CLI's files and errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import rtloop
from rtloop.cli.insert import insert_main

REPO = Path(__file__).resolve().parents[1]
SCENE = str(REPO / "examples" / "yellow-ball" / "scene.json")
BALL2 = {"name": "ball2", "shape": "sphere", "center": [1.8, 0.5, -1.0], "radius": 0.5,
         "material": {"albedo": [0.2, 0.3, 0.8], "specular": 0.0, "shininess": 0.0}}


def test_photo_that_is_the_fitted_render_gives_the_render_with_the_objects():
    # Photo = the scene without the object: photo + (with - without) must be the render with it everywhere.
    photo = rtloop.render(SCENE, 128, 96, 4)
    r = rtloop.insert(SCENE, photo, [BALL2], spp=4, adaptive=False)
    assert np.allclose(r.composite, r.with_objects, atol=1e-5)
    assert np.array_equal(r.without, photo)
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    with_ball = {**scene, "objects": [*scene["objects"], BALL2]}
    assert np.array_equal(r.with_objects, rtloop.render(with_ball, 128, 96, 4))


def test_adaptive_sampling_matches_every_pixel_supersampled():
    # One sample per pixel except where a neighbour differs (silhouettes, shadow edges, the box's creases),
    # against the same 4 x 4 grid in every pixel: no 8-bit sRGB value moves by half a code.
    from rtloop._srgb import encode

    box = {"name": "box", "shape": "mesh", "file": str(REPO / "tests/fixtures/insert/direct-side-box/box.obj"),
           "position": [-1.5, 0, -1.2], "scale": 1.3,
           "material": {"albedo": [0.7, 0.3, 0.2], "specular": 0.2, "shininess": 30.0}}
    photo = rtloop.render(SCENE, 320, 240)
    ref = rtloop.insert(SCENE, photo, [BALL2, box], spp=16, adaptive=False)
    calls = []
    r = rtloop.insert(SCENE, photo, [BALL2, box], spp=16, progress=lambda done, total: calls.append((done, total)))
    for got, want in ((r.with_objects, ref.with_objects), (r.without, ref.without), (r.composite, ref.composite)):
        codes = np.abs(encode(got) - encode(want)) * 255
        assert codes.max() < 0.5 and codes.mean() < 0.01, (codes.max(), codes.mean())
    assert np.array_equal(r.matte, ref.matte)  # the same samples where the matte is not 0 or 1
    assert ((r.matte > 0) & (r.matte < 1)).sum() > 100
    # Progress: tiles of 64 x 64, counted up to all 5 x 4 of them.
    assert calls and calls[-1] == (20, 20)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


def test_progress_that_raises_stops_the_render_and_interrupt_stops_it_too():
    import _thread
    import signal
    import threading

    def fail(done, total):
        raise ValueError("stop here")

    with pytest.raises(ValueError, match="stop here"):
        rtloop.insert(SCENE, rtloop.render(SCENE, 128, 96), [BALL2], progress=fail)
    # ^C while a 12 MP photo is rendered with every pixel supersampled (about 20 s on 2 cores): sent once the
    # render reports progress, taken by the render's own polling (not inside the callback).
    timers, calls = [], []

    def interrupt_soon(done, total):
        calls.append((done, total))
        if not timers:
            timers.append(threading.Timer(0.05, _thread.interrupt_main))
            timers[0].start()

    # A runner started in the background by a non-interactive shell inherits SIGINT ignored, and Python then
    # installs no handler (interrupt_main does nothing): the test takes ^C as an interactive user's Python.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            rtloop.insert(SCENE, np.zeros((3000, 4000, 3), np.float32), [BALL2], adaptive=False,
                          progress=interrupt_soon)
    finally:
        signal.signal(signal.SIGINT, previous)
    timers[0].join()
    assert calls[-1][0] < calls[-1][1]  # stopped before the last tile


def test_real_photo_is_kept_where_the_objects_change_nothing_and_replaced_where_they_are_seen():
    base = rtloop.render(SCENE, 128, 96, 4)
    photo = np.clip(base * 0.7 + 0.05, 0.0, None).astype(np.float32)  # a "real" photo unlike the model
    r = rtloop.insert(SCENE, photo, {"objects": [BALL2]}, spp=4)
    unchanged = (r.matte == 0) & (np.abs(r.with_objects - r.without).max(axis=2) == 0)
    covered = r.matte == 1
    assert unchanged.sum() > 1000 and covered.sum() > 100
    assert np.array_equal(r.composite[unchanged], photo[unchanged])
    assert np.array_equal(r.composite[covered], r.with_objects[covered])
    # The new ball's shadow on the real floor darkens the photo there.
    shadow = (r.matte == 0) & ((r.with_objects - r.without).sum(axis=2) < -0.01)
    assert shadow.sum() > 20
    assert (r.composite[shadow].sum(axis=1) < photo[shadow].sum(axis=1)).all()


def test_matte_is_the_pixel_coverage_of_a_sphere():
    # A sphere on the optical axis at distance d shows as a disc of radius f r / sqrt(d^2 - r^2) pixels
    # (f the focal length in pixels): the matte sums to its area, within the pixel-grid error.
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    cam = np.array(scene["camera"]["position"])
    axis = np.array(scene["camera"]["look_at"]) - cam
    d = 3.0
    centre = cam + d * axis / np.linalg.norm(axis)
    radius = 0.3
    f = 96 / 2 / np.tan(np.radians(scene["camera"]["vfov_deg"]) / 2)
    expected = np.pi * (f * radius / np.sqrt(d * d - radius * radius)) ** 2
    ball = {**BALL2, "center": centre.tolist(), "radius": radius}
    r = rtloop.insert(SCENE, rtloop.render(SCENE, 128, 96), [ball], spp=16)
    assert abs(r.matte.sum() - expected) < 0.01 * expected  # 735 px: the grid error is a few px


@pytest.mark.parametrize("objects, message", [
    ([{**BALL2, "radius": -1}], "added objects: objects[0].radius"),
    ([], "non-empty list"),
    ({"things": []}, "objects"),
])
def test_bad_objects_are_refused_naming_the_field(objects, message):
    with pytest.raises(rtloop.RtloopError, match=message.replace("[", r"\[").replace("]", r"\]")):
        rtloop.insert(SCENE, rtloop.render(SCENE, 128, 96), objects)


def test_photo_of_another_aspect_is_refused():
    with pytest.raises(rtloop.RtloopError, match="aspect ratio"):
        rtloop.insert(SCENE, np.zeros((100, 100, 3), np.float32), [BALL2])


def test_cli_writes_the_composite_matte_and_renders(tmp_path):
    rtloop.save_image(tmp_path / "photo.png", rtloop.render(SCENE, 256, 192, 4))
    (tmp_path / "objects.json").write_text(json.dumps({"objects": [BALL2]}))
    out = tmp_path / "inserted"
    argv = [SCENE, str(tmp_path / "photo.png"), "--add", str(tmp_path / "objects.json"), "--out", str(out),
            "--spp", "4"]
    assert insert_main(argv) == 0
    names = {"composite.png", "composite_linear16.png", "matte.png", "with.png", "without.png"}
    assert {p.name for p in out.iterdir()} == names
    comp = rtloop.load_image(out / "composite_linear16.png", (256, 192), response="linear")
    assert comp.shape == (192, 256, 3)
    assert insert_main(argv) == 1  # DIR not empty without --force
    assert insert_main([*argv, "--force"]) == 0
    assert insert_main([SCENE, str(tmp_path / "photo.png"), "--add", str(tmp_path / "none.json"),
                        "--out", str(tmp_path / "o2")]) == 1


@pytest.fixture(scope="module")
def direct_side_fit():
    """The light fitted on Mitsuba's direct-side photo (no added object): (input scene, photo, fitted)."""
    case = REPO / "tests" / "fixtures" / "photos" / "direct-side"
    scene = rtloop.load_scene(case / "scene_input.json")
    photo = rtloop.load_image(case / "objective.png", scene)
    return scene, photo, rtloop.fit(scene, photo, seed=1).scene


@pytest.mark.parametrize("fixture, shadow_px", [("direct-side", 200), ("direct-side-box", 300)])
def test_inserted_object_matches_mitsubas_photo_with_it(direct_side_fit, fixture, shadow_px):
    # Fit the light on Mitsuba's photo without the blue ball (or the turned box mesh, box.obj), insert it,
    # compare with Mitsuba's photo with it (tools/make_insert_photos.py), away from the silhouettes (2 px
    # either side of any pixel the matte cuts).
    from scipy import ndimage

    from rtloop._srgb import encode

    scene, photo, fitted = direct_side_fit
    r = rtloop.insert(fitted, photo, REPO / "tests" / "fixtures" / "insert" / fixture / "objects.json", spp=16)
    truth = rtloop.load_image(REPO / "tests" / "fixtures" / "insert" / fixture / "with.png", scene)
    seen = r.matte > 0
    away = ~(ndimage.binary_dilation(seen, iterations=2) ^ ndimage.binary_erosion(seen, iterations=2))
    codes = np.abs(encode(r.composite) - encode(truth)) * 255
    psnr = 10 * np.log10(1 / np.mean((codes[away] / 255) ** 2))
    assert psnr > 40  # the photo without the object: 17 dB
    shadow = away & ~seen & ((r.with_objects - r.without).sum(axis=2) < -0.01)
    assert shadow.sum() > shadow_px
    assert codes[shadow].mean() < 5  # the shadow left out: 115 codes (ball), 113 (box)
    assert codes[away & (r.matte == 1)].mean() < 8  # the object's own shading (its albedo is given, not fitted)


def test_report_shows_the_photo_beside_the_composite(tmp_path):
    scene = rtloop.load_scene(SCENE)
    photo = rtloop.render(scene, spp=4)
    result = rtloop.fit(scene, photo, seed=1, generations=2)
    r = rtloop.insert(result.scene, photo, [BALL2], spp=4)
    page = rtloop.report(result, tmp_path / "report.html", objective=photo, insertion=r)
    html = page.path.read_text()
    assert "<h2>Inserted objects</h2>" in html
    composite = rtloop.load_image(tmp_path / "report" / "insert_composite.png", scene)
    assert np.abs(composite - np.clip(r.composite, 0, 1)).max() < 0.01  # 8-bit sRGB of the composite
    assert "Inserted objects" not in rtloop.report(result, tmp_path / "plain.html").path.read_text()


def _cli_inputs(folder: Path) -> list[str]:
    folder.mkdir(parents=True, exist_ok=True)
    rtloop.save_image(folder / "photo.png", rtloop.render(SCENE, 128, 96, 1))
    (folder / "objects.json").write_text(json.dumps({"objects": [BALL2]}))
    (folder / "result.json").write_text(Path(SCENE).read_text())
    return [str(folder / "result.json"), str(folder / "photo.png"), "--add", str(folder / "objects.json")]


@pytest.mark.parametrize("holds", ["result.json", "photo.png", "objects.json"])
def test_force_never_replaces_a_directory_holding_an_input(tmp_path, capsys, holds):
    inputs = _cli_inputs(tmp_path / "work")
    moved = tmp_path / "work" / holds
    here = tmp_path / "out"
    here.mkdir()
    moved.rename(here / holds)
    inputs = [str(here / holds) if a == str(moved) else a for a in inputs]
    assert insert_main([*inputs, "--out", str(here), "--force", "--spp", "1"]) == 1
    err = capsys.readouterr().err
    assert f"refusing to replace it with --force: it contains {here / holds}" in err and err.count("\n") <= 2
    assert (here / holds).is_file()


@pytest.mark.parametrize("out", [".", ".."])
def test_force_never_replaces_the_working_directory(tmp_path, capsys, monkeypatch, out):
    inputs = _cli_inputs(tmp_path / "work")
    monkeypatch.chdir(tmp_path / "work")
    assert insert_main([*inputs, "--out", out, "--force", "--spp", "1"]) == 1
    err = capsys.readouterr().err
    assert "refusing to replace the current directory (or one above it)" in err
    assert (tmp_path / "work" / "photo.png").is_file()


def test_a_mesh_file_inside_out_is_an_input_too(tmp_path, capsys):
    inputs = _cli_inputs(tmp_path / "work")
    out = tmp_path / "out"
    out.mkdir()
    (out / "tri.obj").write_text("v 1.5 0.1 -1\nv 2 0.1 -1\nv 1.7 0.8 -1\nf 1 2 3\n")
    mesh = {"name": "tri", "shape": "mesh", "file": str(out / "tri.obj"), "material": {"albedo": [0.5, 0.5, 0.5]}}
    Path(inputs[3]).write_text(json.dumps([mesh]))
    assert insert_main([*inputs, "--out", str(out), "--force", "--spp", "1"]) == 1
    assert "it contains" in capsys.readouterr().err and (out / "tri.obj").is_file()


def test_ctrl_c_exits_130_with_one_line(tmp_path):
    import os
    import signal
    import subprocess
    import sys

    inputs = _cli_inputs(tmp_path / "work")
    rtloop.save_image(tmp_path / "work" / "photo.png", rtloop.render(SCENE, 1024, 768, 1))
    env = {**os.environ, "PYTHONPATH": str(Path(rtloop.__file__).parents[1])}
    proc = subprocess.Popen([sys.executable, "-m", "rtloop.cli.insert", *inputs, "--out", str(tmp_path / "o"),
                             "--uniform", "--spp", "4096"], stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stderr.readline()  # the rendering has begun
    assert "rendering" in line
    proc.send_signal(signal.SIGINT)
    rest = proc.communicate(timeout=120)[1]
    assert proc.returncode == 130
    assert "rtloop-insert: interrupted" in rest and "Traceback" not in rest
    assert not (tmp_path / "o").exists()


def test_a_photo_turned_by_its_exif_orientation_is_read_as_rtloop_fit_reads_it(tmp_path, capsys):
    from PIL import Image

    inputs = _cli_inputs(tmp_path / "work")
    shown = (np.clip(rtloop.render(SCENE, 128, 96, 1), 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)
    exif = Image.Exif()
    exif[0x0112] = 6  # stored a quarter turn anticlockwise, shown turned back clockwise
    Image.fromarray(np.ascontiguousarray(np.rot90(shown, 1))).save(tmp_path / "work" / "photo.jpg", exif=exif)
    inputs[1] = str(tmp_path / "work" / "photo.jpg")
    assert insert_main([*inputs, "--out", str(tmp_path / "o"), "--spp", "1"]) == 0, capsys.readouterr().err
    assert rtloop.load_image(tmp_path / "o" / "composite.png", (128, 96)).shape == (96, 128, 3)


def test_photos_above_the_pixel_cap_are_refused_in_one_line(monkeypatch):
    import sys

    monkeypatch.setattr(sys.modules["rtloop.insert"], "MAX_INSERT_PIXELS", 128 * 96 - 1)
    with pytest.raises(rtloop.RtloopError, match=r"photo: 128x96 = 0.0 megapixels, more than the 0 an insertion"):
        rtloop.insert(SCENE, rtloop.render(SCENE, 128, 96, 1), [BALL2])


def test_an_added_object_is_named_by_its_place_in_the_objects_file(tmp_path):
    objects = tmp_path / "objects.json"
    objects.write_text(json.dumps([BALL2, {**BALL2, "name": "bad", "radius": -1}]))
    with pytest.raises(rtloop.RtloopError, match=r"objects\.json: objects\[1\]\.radius"):
        rtloop.insert(SCENE, rtloop.render(SCENE, 128, 96, 1), objects)


def test_a_sphere_enclosing_the_camera_and_the_light_warns(capsys, tmp_path):
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    shell = {**BALL2, "name": "shell", "center": scene["camera"]["position"], "radius": 20.0}
    with pytest.warns(rtloop.RtloopWarning, match=r"objects\[0\] \(shell\): the sphere encloses the camera and "
                                                  r"the light"):
        rtloop.insert(SCENE, rtloop.render(SCENE, 32, 24, 1), [shell], spp=1)
    inputs = _cli_inputs(tmp_path / "work")
    Path(inputs[3]).write_text(json.dumps([shell]))
    assert insert_main([*inputs, "--out", str(tmp_path / "o"), "--spp", "1"]) == 0
    assert "rtloop-insert: warning: " in capsys.readouterr().err
