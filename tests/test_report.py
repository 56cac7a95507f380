"""The fit report (``rtloop.report``, ``rtloop-fit --report``): a self-contained page that a real browser
renders with every image, plots whose data are the fit history, and no network references."""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import rtloop
from conftest import REPO, example_scene, example_truth
from rtloop import cli
from rtloop.report import image_metrics, truth_errors

W, H = 32, 24
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")


def _fit_with_report(tmp_path: Path, capsys, final_scale: int, final_spp: int) -> Path:
    """rtloop-fit --report (population 8, 3 generations, no snapshots) of the example scene on a render of its
    truth, in tmp_path/fit, which it returns."""
    scene_path, image_path, out = tmp_path / "scene.json", tmp_path / "objective.png", tmp_path / "fit"
    scene_path.write_text(json.dumps(example_scene(W, H)), encoding="utf-8")
    rtloop.save_image(image_path, rtloop.render(example_truth(W, H), footprint=True))
    code = cli.main([str(scene_path), str(image_path), "--out", str(out), "--population", "8", "--generations",
                     "3", "--final-scale", str(final_scale), "--final-spp", str(final_spp), "--snapshot-every", "0",
                     "--report", "-q"])
    assert code == 0, capsys.readouterr().err
    return out


@pytest.fixture
def speed_png(tmp_path) -> Path:
    """A PNG the caller passes as the speed-against-error plot (a report reads no file of the repository)."""
    path = tmp_path / "my_speed_plot.png"
    Image.fromarray(np.tile(np.arange(64, dtype=np.uint8)[:, None, None] * 4, (1, 48, 3))).save(path)
    return path


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    return np.minimum(rtloop.render(example_truth(W, H), footprint=True), 1.0)


@pytest.fixture(scope="module")
def projected(photo):
    """A default-protocol fit (one stage, light+colour: colours in closed form) and its callback rows."""
    rows: list = []
    result = rtloop.fit(example_scene(W, H), photo, seed=1, population=8, generations=6, callback=rows.append)
    assert result.settings["method"] == "projected"
    return result, rows


@pytest.fixture(scope="module")
def two_stage(photo):
    """The paper protocol (light, then colour) with tiny budgets."""
    rows: list = []
    result = rtloop.fit(example_scene(W, H), photo, protocol="paper", seed=2, population=6, generations=(4, 5),
                        callback=rows.append)
    return result, rows


def data_uris(page: str) -> list[bytes]:
    found = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    return [base64.b64decode(m) for m in found]


# --- (1) a real browser renders the page and every image ---------------------------------------------------


def find_browser() -> str:
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    if os.environ.get("CI"):
        pytest.fail(f"no headless browser found ({', '.join(BROWSERS)}); CI must install chromium (.ci/run)")
    pytest.skip(f"no headless browser found ({', '.join(BROWSERS)}): install Debian's chromium "
                "(apt-get install chromium) to run this test; it is required when CI is set")


def browse(browser: str, page: Path, profile: Path, *args: str) -> subprocess.CompletedProcess[str]:
    cmd = [browser, "--headless", "--disable-gpu", "--no-sandbox", "--no-first-run", "--hide-scrollbars",
           f"--user-data-dir={profile}", "--virtual-time-budget=10000", *args, page.resolve().as_uri()]
    done = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, f"{' '.join(cmd)}\n{done.stderr[-3000:]}"
    return done


def test_page_renders_in_a_headless_browser_with_every_image(projected, photo, tmp_path, speed_png):
    browser = find_browser()
    result, rows = projected
    rep = rtloop.report(result, tmp_path / "report.html", objective=photo, truth=example_truth(W, H),
                        generations=rows, speed_plot=speed_png)
    page = rep.path.read_text(encoding="utf-8")
    n_images = page.count("<img ")
    assert n_images == len(rep.files) >= 3 + 2 + 2  # objective/fitted/difference, strip, plots

    dom = browse(browser, rep.path, tmp_path / "profile-dom", "--dump-dom").stdout
    body = re.search(r"<body([^>]*)>", dom)
    assert body, dom[:2000]
    attrs = dict(re.findall(r'data-([a-z-]+)="([^"]*)"', body.group(1)))
    assert attrs.get("loaded") == "1", f"the page's load handler did not run: {body.group(0)}"
    assert attrs.get("errors") == "0", f"script or resource errors while loading: {body.group(0)}"
    assert attrs.get("images") == str(n_images)
    assert attrs.get("images-ok") == str(n_images), f"not every image decoded: {body.group(0)}"
    assert "Fit report" in dom and "Identifiability" in dom
    # The answer comes first: the light in mm, then the photo beside the fit.
    assert dom.index("The answer") < dom.index("Light at ") < dom.index("Photo, fit and difference")
    assert 'alt="the scene from above and from the side with the fitted light"' in dom

    # A screenshot at desktop and phone widths is not blank: pictures, plot lines, text.
    for size in ("1280,2400", "390,2400"):
        shot = tmp_path / f"shot-{size.split(',')[0]}.png"
        browse(browser, rep.path, tmp_path / f"profile-{size.split(',')[0]}", f"--window-size={size}",
               f"--screenshot={shot}")
        with Image.open(shot) as im:
            arr = np.asarray(im.convert("RGB"), dtype=np.float64)
        assert arr.shape[1] == int(size.split(",")[0])
        assert arr.std() > 20, f"screenshot {shot.name} looks blank (std {arr.std():.1f})"
        colours = np.unique(arr[::4, ::4].reshape(-1, 3), axis=0)
        assert len(colours) > 200, f"screenshot {shot.name} has only {len(colours)} colours"


# --- (2) the plots show the fit history --------------------------------------------------------------------


def test_plotted_data_are_the_fit_history_projected(projected, photo, tmp_path):
    result, rows = projected
    truth = example_truth(W, H)
    rep = rtloop.report(result, tmp_path / "r.html", objective=photo, truth=truth, generations=rows)
    assert rep.source == "generations"
    (stage,) = result.stages
    hist = stage.history
    gens = np.array([h[0] for h in hist], float)
    assert stage.param_names == ["light.position.x", "light.position.y", "light.position.z"]

    x_all = rep.plots["_generation"]["x"]
    np.testing.assert_array_equal(x_all, gens)
    assert rep.plots["_generation"]["rows"] == [(stage.name, int(g)) for g in gens]
    # The searched coordinates are the history's x, generation by generation.
    for k, name in enumerate(stage.param_names):
        x, y = rep.plots["light.position"][name]
        np.testing.assert_array_equal(x, gens)
        np.testing.assert_allclose(y, [h[3][k] for h in hist], rtol=0, atol=0)
    # The fitness curve is the history's fitness.
    x, y = rep.plots["fitness"][f"fitness:{stage.name}"]
    np.testing.assert_array_equal(x, gens)
    np.testing.assert_allclose(y, [h[1] for h in hist], rtol=0, atol=0)
    # The closed-form colours come from the callback's rows (the history holds only the position).
    names = result.scene.param_names()
    for obj in ("ball", "floor"):
        for c in "rgb":
            name = f"objects.{obj}.albedo.{c}"
            _, y = rep.plots[f"objects.{obj}.albedo"][name]
            np.testing.assert_allclose(y, [r.params[names.index(name)] for r in rows], rtol=0, atol=0)
    _, y = rep.plots["light.intensity"]["light.intensity"]
    np.testing.assert_allclose(y, [r.params[names.index("light.intensity")] for r in rows])
    # The last generation's parameters are the fitted values.
    for name in names:
        pid = name.rsplit(".", 1)[0] if name.startswith(("light.position", "objects.")) else name
        assert rep.plots[pid][name][1][-1] == pytest.approx(result.x[name], rel=1e-9, abs=1e-12)
    # Truth: dashed lines at the true values; the degenerate scene also plots the products.
    x, y = rep.plots["light.position"]["truth:light.position.y"]
    np.testing.assert_allclose(y, [truth["light"]["position"][1]] * 2)
    assert x[0] == gens[0] and x[-1] == gens[-1]
    _, y = rep.plots["objects.ball.albedo"]["truth:objects.ball.albedo.g"]
    np.testing.assert_allclose(y, [0.7, 0.7])
    assert result.identifiability["degenerate"]
    _, y = rep.plots["products.ball"]["product:ball.r"]
    i, a = names.index("light.intensity"), names.index("objects.ball.albedo.r")
    want = [r.params[i] * r.params[a] for r in rows]
    np.testing.assert_allclose(y, want, rtol=1e-12)
    _, y = rep.plots["products.floor"]["truth:product:floor.b"]
    np.testing.assert_allclose(y, [40.0 * 0.6] * 2)
    # The strip renders generations 0, k, 2k, ... and the last.
    assert rep.strip[0][:2] == (stage.name, 0)
    assert rep.strip[-1][:2] == (stage.name, int(gens[-1]))


def test_plotted_data_are_the_fit_history_two_stages(two_stage, tmp_path):
    result, rows = two_stage
    assert [s.name for s in result.stages] == ["light", "colour"]
    light, colour = result.stages
    rep = rtloop.report(result, tmp_path / "r.html")  # no rows: rebuilt from the history
    assert rep.source == "history" and rep.notes
    n1 = len(light.history)
    x_all = rep.plots["_generation"]["x"]
    # Generation counts on across stages: the colour stage starts right after the light stage.
    np.testing.assert_array_equal(x_all, np.arange(n1 + len(colour.history), dtype=float))
    for stage, sl in ((light, slice(0, n1)), (colour, slice(n1, None))):
        _, y = rep.plots["fitness"][f"fitness:{stage.name}"]
        np.testing.assert_allclose(y, [h[1] for h in stage.history], rtol=0, atol=0)
        for k, name in enumerate(stage.param_names):
            pid = name.rsplit(".", 1)[0] if name.startswith(("light.position", "objects.")) else name
            _, y = rep.plots[pid][name]
            np.testing.assert_allclose(y[sl], [h[3][k] for h in stage.history], rtol=0, atol=0)
    # During the colour stage the light is held where the light stage left it.
    _, y = rep.plots["light.position"]["light.position.z"]
    np.testing.assert_allclose(y[n1:], light.history[-1][3][2])

    # With the callback's rows the plots are those rows exactly; tuples as the CLI records them do the same.
    names = result.scene.param_names()
    tuples = [(r.stage, r.generation, r.fitness, np.asarray(r.params)) for r in rows]
    for given in (rows, tuples):
        rep = rtloop.report(result, tmp_path / "g.html", generations=given)
        for j, name in enumerate(names):
            pid = name.rsplit(".", 1)[0] if name.startswith(("light.position", "objects.")) else name
            np.testing.assert_allclose(rep.plots[pid][name][1], [r.params[j] for r in rows], rtol=0, atol=0)
        np.testing.assert_allclose(
            np.concatenate([rep.plots["fitness"][f"fitness:{s}"][1] for s in ("light", "colour")]),
            [r.fitness for r in rows],
        )


# --- (3) self-contained: no external URLs, the embedded images are the files -------------------------------


def test_page_is_self_contained(projected, photo, tmp_path, speed_png):
    result, rows = projected
    out = tmp_path / "deep" / "report.html"
    rep = rtloop.report(result, out, objective=photo, truth=example_truth(W, H), generations=rows,
                        speed_plot=speed_png)
    assert rep.path == out and out.is_file()
    page = out.read_text(encoding="utf-8")
    assert page.startswith("<!doctype html>") and page.rstrip().endswith("</html>")
    assert 'name="viewport"' in page
    assert "http://" not in page and "https://" not in page
    attributes = re.findall(r'\b(src|href|srcset|action|data)\s*=\s*["\']([^"\']*)', page, re.IGNORECASE)
    assert attributes
    for attr, value in attributes:
        assert attr.lower() == "src" and value.startswith("data:image/png;base64,"), (attr, value[:80])
    assert not re.search(r"<(link|iframe|object|embed)\b", page, re.IGNORECASE)
    assert not re.search(r"<script[^>]*\bsrc\b", page, re.IGNORECASE)
    assert not re.search(r"url\(|@import", page, re.IGNORECASE)  # nothing fetched from CSS either
    # Every embedded image is one of the PNGs written beside the page, byte for byte, in page order.
    assert all(p.parent == tmp_path / "deep" / "report" for p in rep.files)
    embedded = data_uris(page)
    assert embedded == [p.read_bytes() for p in rep.files]
    assert sorted(os.listdir(tmp_path / "deep")) == ["report", "report.html"]  # no temporary files left
    assert sorted(os.listdir(tmp_path / "deep" / "report")) == sorted(p.name for p in rep.files)
    copied = tmp_path / "deep" / "report" / "speed_vs_error.png"
    assert copied.read_bytes() == speed_png.read_bytes() and "Speed against error" in page
    # The numbers are on the page: error metrics, truth errors, products, identifiability.
    for text in ("L1", "RMSE", "PSNR", "light position error", "product relative error",
                 result.identifiability["note"].split(":")[0]):
        assert text in page, text
    # In mm and %, not raw floats.
    assert f"<td>light position error</td><td>{1000 * rep.truth['light_position_m']:.3g} mm</td>" in page
    assert f"<td>ball: product relative error</td><td>{100 * rep.truth['product_relative']['ball']:.3g} %</td>" in page
    # The fit's per-parameter uncertainty is shown, one row per parameter.
    assert "Uncertainty" in page
    for name in result.uncertainty["sigma"]:
        assert name in page
    assert "block sandwich" in page and "light position (whole, m)" in page

    # Written again with a coarser strip: stale strip frames go, nothing else is left behind.
    saved, result.uncertainty = result.uncertainty, {"light.position.x": 0.01}
    try:
        rep2 = rtloop.report(result, out, generations=rows, strip_every=100)
    finally:
        result.uncertainty = saved  # the fixture is shared: ``del`` would leave the class default, None
    assert "Uncertainty" in out.read_text(encoding="utf-8")
    kept = {p.name for p in rep.files if not p.name.startswith(("strip_", "param_"))}
    assert sorted(os.listdir(tmp_path / "deep" / "report")) == sorted({p.name for p in rep2.files} | kept)
    assert len(rep2.strip) == 2  # generation 0 and the last


def test_speed_plot_only_when_given(projected, tmp_path, monkeypatch, capsys):
    """A report reads no file of the repository: run from its root without a speed plot, neither
    rtloop.report nor rtloop-fit --report includes one."""
    result, rows = projected
    monkeypatch.chdir(REPO)
    rep = rtloop.report(result, tmp_path / "r.html", generations=rows)
    assert "speed_vs_error.png" not in {p.name for p in rep.files}
    assert "Speed against error" not in rep.path.read_text(encoding="utf-8")
    out = _fit_with_report(tmp_path, capsys, final_scale=1, final_spp=1)
    assert not (out / "report" / "speed_vs_error.png").exists()
    assert "Speed against error" not in (out / "report.html").read_text(encoding="utf-8")


def test_error_numbers_follow_their_formulas():
    rng = np.random.default_rng(0)
    objective = rng.uniform(0.1, 0.8, (H, W, 3))
    render = objective + 0.05
    render[0, 0] = 3.0  # clipped to 1 as the fit compares
    m = image_metrics(render, objective)
    d = np.minimum(render, 1.0) - objective
    assert m["l1_linear"] == pytest.approx(np.mean(np.abs(d)))
    assert m["rmse_linear"] == pytest.approx(np.sqrt(np.mean(d**2)))
    assert m["sum_abs_linear"] == pytest.approx(np.sum(np.abs(d)))

    def srgb(x):
        x = np.clip(x, 0, 1)
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)

    mse = np.mean((srgb(np.minimum(render, 1)) - srgb(objective)) ** 2)
    assert m["psnr_srgb_db"] == pytest.approx(-10 * np.log10(mse))


def test_truth_errors(projected):
    result, _ = projected
    truth = example_truth(W, H)
    err = truth_errors(result, truth)
    fitted = result.scene.to_dict()
    want = np.linalg.norm(np.subtract(fitted["light"]["position"], truth["light"]["position"]))
    assert err["light_position_m"] == pytest.approx(want)
    for k, obj in enumerate(("ball", "floor")):
        p_true = 40.0 * np.array(truth["objects"][k]["material"]["albedo"])
        p_fit = fitted["light"]["intensity"] * np.array(fitted["objects"][k]["material"]["albedo"])
        want = np.linalg.norm(p_fit - p_true) / np.linalg.norm(p_true)
        assert err["product_relative"][obj] == pytest.approx(want)
    assert err["values"]["light.intensity"] == 40.0
    # Intensity and albedos are known only as products here: marked, the light position is not.
    assert sorted(err["split_convention"]) == sorted(
        ["light.intensity"] + [f"objects.{o}.albedo.{c}" for o in ("ball", "floor") for c in "rgb"])
    assert err["errors"]["light.position.x"] == pytest.approx(result.x["light.position.x"] - 2.0)
    other = example_truth(W, H)
    other["objects"][0]["name"] = "sphere"
    with pytest.raises(rtloop.RtloopError, match="ball"):
        truth_errors(result, other)


# Zero-mean noise on a dark photo makes values negative, which fit() notes: expected here.
@pytest.mark.filterwarnings("ignore:image.* of the values are negative:rtloop.errors.RtloopWarning")
def test_directional_light_uncertainty_is_one_line_in_degrees(projected, tmp_path):
    """A directional light's uncertainty: the two angles' sigmas (radians, marked so) and, on one row of
    the uncertainty table, the cone in degrees from result.uncertainty["light_direction"]."""
    truth = example_truth(W, H)
    sun = np.array([0.6, 1.0, -0.4])
    truth["light"] = {"type": "directional", "direction": list(sun / np.linalg.norm(sun)), "intensity": 2.5}
    truth["fit"].pop("light.position")
    truth["fit"]["light.direction"] = {"min": [-1, 0.05, -1], "max": [1, 1, 1]}
    truth["fit"]["light.intensity"] = {"min": 0.1, "max": 20}
    start = json.loads(json.dumps(truth))
    start["light"]["direction"] = [0.0, 1.0, 0.0]
    clean = rtloop.render(truth)
    photo = np.minimum(clean + 0.01 * np.random.default_rng(0).normal(size=clean.shape), 1.0)
    result = rtloop.fit(start, photo.astype(np.float32), seed=1, population=8, generations=10)
    cone = result.uncertainty["light_direction"]
    assert cone["angle_deg"] > 0 and cone["rms_angle_deg"] >= cone["angle_deg"]
    rep = rtloop.report(result, tmp_path / "r.html", objective=photo)
    page = rep.path.read_text(encoding="utf-8")
    rows = re.findall(r"<tr>(.*?)</tr>", page)
    line = [r for r in rows if "light direction" in r]
    assert len(line) == 1, line
    cells = re.findall(r"<td[^>]*>(.*?)</td>", line[0])
    robust = result.uncertainty["robust"]["light_direction_deg"]
    assert robust >= cone["angle_deg"]  # here the correlated residuals widen it
    assert cells == ["light direction (angle, degrees)",
                     f"{cone['angle_deg']:.3g}° along the worse axis, {cone['rms_angle_deg']:.3g}° rms",
                     f"{robust:.3g}° along the worse axis"]
    first = re.findall(r"<tr><td[^>]*>(.*?)</td>", page)  # the first cell of every table row
    assert [n for n in first if n.startswith(("light.direction.u", "light.direction.v"))] == [
        "light.direction.u (rad)", "light.direction.v (rad)"]
    assert first.index("light direction (angle, degrees)") == first.index("light.direction.v (rad)") + 1
    # An angle the image does not determine: the row says so.
    result.uncertainty = {**result.uncertainty, "light_direction": {**cone, "angle_deg": None,
                                                                     "rms_angle_deg": None}}
    page = rtloop.report(result, tmp_path / "r.html").path.read_text(encoding="utf-8")
    assert "<td>light direction (angle, degrees)</td><td>not determined</td>" in page
    # A point light has no such row.
    point, _ = projected
    assert point.uncertainty["sigma"]
    page = rtloop.report(point, tmp_path / "p.html").path.read_text(encoding="utf-8")
    assert "Uncertainty" in page and "light direction" not in page and "(rad)" not in page


def test_import_rtloop_does_not_import_matplotlib():
    code = "import sys, rtloop; assert callable(rtloop.report); print('matplotlib' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"


# --- (4) the command line -----------------------------------------------------------------------------------


def test_cli_report_and_truth(tmp_path, capsys, speed_png):
    scene_path = tmp_path / "scene.json"
    scene_path.write_text(json.dumps(example_scene(W, H)), encoding="utf-8")
    truth_path = tmp_path / "truth.json"
    truth_path.write_text(json.dumps(example_truth(W, H)), encoding="utf-8")
    image_path = tmp_path / "objective.png"
    rtloop.save_image(image_path, rtloop.render(example_truth(W, H), footprint=True))
    out = tmp_path / "fit"
    code = cli.main([str(scene_path), str(image_path), "--out", str(out), "--population", "8",
                     "--generations", "5", "--final-scale", "1", "--final-spp", "1", "--report",
                     "--truth", str(truth_path), "--quiet", "--speed-plot", str(speed_png)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert captured.err == ""
    page = out / "report.html"
    assert page.is_file() and (out / "report").is_dir()
    assert sorted(p.name for p in tmp_path.iterdir() if ".rtloop-" in p.name) == []
    html_text = page.read_text(encoding="utf-8")
    assert "http://" not in html_text and "https://" not in html_text
    files = sorted(os.listdir(out / "report"))
    assert {"objective.png", "fitted.png", "difference.png", "fitness.png", "speed_vs_error.png"} <= set(files)
    assert (out / "report" / "speed_vs_error.png").read_bytes() == speed_png.read_bytes()
    assert len(data_uris(html_text)) == len(files)
    # The rows the CLI recorded are those of best_per_generation.csv: the plots show them.
    assert "light+colour" in html_text and "truth" in html_text

    # stdout ends with the fitted values (with truth and error), the errors, and the paths.
    lines = captured.out.rstrip("\n").splitlines()
    assert lines[-1] == f"report: {page}"
    assert lines[-2] == f"results in {out}"
    assert re.fullmatch(r"product relative error: ball [\d.e+-]+%, floor [\d.e+-]+%", lines[-3]), lines[-3]
    assert re.fullmatch(r"light position error: [\d.e+-]+ m", lines[-4]), lines[-4]
    # The photo fixes intensity x albedo only: those rows show "(split)", not an error, and say why.
    assert lines[-5].startswith("  (split): the photo fixes only the products of these"), lines[-5]
    # The light's distance and direction from the subject, each with its sigma (determined here).
    assert re.fullmatch(r"light from the subject: direction \+- [\d.e+-]+ deg, distance [\d.]+ m \+- [\d.e+-]+ m",
                        lines[-6]), lines[-6]
    # What the error bars hold, below the table.
    assert lines[-7].startswith("error bars (+-): block sandwich (correlated residuals) plus the pixel footprint"), \
        lines[-7]
    fitted = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]["fitted"]
    table = lines[-7 - len(fitted):-7]
    for (name, value), line in zip(fitted.items(), table):
        parts = line.split()
        assert parts[0] == name and float(parts[1]) == pytest.approx(value, rel=1e-5, abs=1e-9)
        split = name == "light.intensity" or ".albedo." in name
        assert (parts[3] == "(split)") == split, line
        if not split:
            float(parts[3])  # an error in metres
    assert table[0].split()[0] == "light.position.x" and "truth" in lines[-8 - len(fitted)]
    assert html_text.count("<td>split convention</td>") == 7 and "Split convention:" in html_text

    # A truth that does not match the scene is one clear line, before any fitting.
    bad = example_truth(W, H)
    bad["objects"][1]["name"] = "ground"
    bad_path = tmp_path / "bad.json"
    bad_path.write_text(json.dumps(bad), encoding="utf-8")
    code = cli.main([str(scene_path), str(image_path), "--out", str(tmp_path / "x"),
                     "--truth", str(bad_path)])
    captured = capsys.readouterr()
    assert code == 1 and captured.out == ""
    assert captured.err.startswith(f"rtloop-fit: error: {bad_path}: ") and "floor" in captured.err
    assert not (tmp_path / "x").exists()

    # --speed-plot: a file that is not there, or without --report, is one clear line, before any fitting.
    for extra, status, message in ((["--report", "--speed-plot", str(tmp_path / "none.png")], 1,
                                    f"rtloop-fit: error: --speed-plot: {tmp_path / 'none.png'}: no such file"),
                                   (["--speed-plot", str(speed_png)], 2,
                                    "rtloop-fit: error: --speed-plot: only with --report")):
        code = cli.main([str(scene_path), str(image_path), "--out", str(tmp_path / "x"), *extra])
        captured = capsys.readouterr()
        assert (code, captured.out, captured.err.strip()) == (status, "", message)
        assert not (tmp_path / "x").exists()


def test_the_bootstrap_column_when_the_fit_ran_it(photo, tmp_path):
    """A fit with uncertainty="bootstrap": the uncertainty table gets a third sigma column naming the
    refits and their cost, with the bootstrap's value for the light coordinates; without it, no column."""
    result = rtloop.fit(example_scene(W, H), photo, seed=1, population=8, generations=6, uncertainty="bootstrap")
    boot = result.uncertainty["bootstrap"]
    page = rtloop.report(result, tmp_path / "r.html").path.read_text(encoding="utf-8")
    assert f"block bootstrap: {boot['replicates']} refits" in page
    section = page[page.index("<h3>Uncertainty"):]
    row = re.search(r"<tr><td>light\.position\.x</td>(.*?)</tr>", section)
    assert row is not None and f"{boot['sigma']['light.position.x']:.6g}" in row.group(1), row
    del result.uncertainty["bootstrap"]
    page = rtloop.report(result, tmp_path / "s.html").path.read_text(encoding="utf-8")
    assert "block bootstrap" not in page


# --- (5) the answer first, in mm and % -----------------------------------------------------------------------


def cells(page: str, first: str) -> list[str]:
    """The cells of the table row whose first cell is ``first``."""
    row = re.search(rf"<tr><td[^>]*>{re.escape(first)}</td>(.*?)</tr>", page)
    assert row is not None, first
    return re.findall(r"<td[^>]*>(.*?)</td>", row.group(1))


def test_the_page_opens_with_the_answer(projected, photo, tmp_path):
    """The first section: the light's position in mm with its 1σ in mm (the block sandwich's), the
    products with their 1σ in %, the truth's errors, the verdict, and the picture of the scene."""
    result, rows = projected
    rep = rtloop.report(result, tmp_path / "r.html", objective=photo, truth=example_truth(W, H), generations=rows)
    page = rep.path.read_text(encoding="utf-8")
    headings = re.findall(r"<h2>(.*?)</h2>", page)
    assert headings[:2] == ["The answer", "Photo, fit and difference"]
    answer = page[page.index("<h2>The answer</h2>"):page.index("<h2>Photo, fit and difference</h2>")]
    sigma = result.uncertainty["robust"]["sigma"]
    light = result.scene.to_dict()["light"]["position"]
    want = ", ".join(f"{c} {1000 * v:.1f} ± {1000 * sigma[f'light.position.{c}']:.2g}" for c, v in zip("xyz", light))
    assert f"Light at {want} mm (1σ, block sandwich" in answer
    assert f"{1000 * rep.truth['light_position_m']:.2g} mm from the true light" in answer
    for obj in ("ball", "floor"):
        row = cells(answer, obj)
        assert row[0] == "light intensity × albedo (W/sr)"
        for c, cell in zip("rgb", row[1:4]):
            value = result.products[obj]["rgb".index(c)]
            pct = 100 * result.uncertainty["robust"]["product_sigma"][f"products.{obj}.{c}"] / value
            assert cell == f"{value:.4g} ± {pct:.2g} %", cell
        assert row[4] == f"{100 * rep.truth['product_relative'][obj]:.2g} %"
    assert "a convention" in answer and f"Verdict: {result.goodness['verdict']}" in answer
    assert rep.answer["light"]["position_mm"] == pytest.approx([1000 * v for v in light])
    assert "scene_views.png" in {p.name for p in rep.files}


def test_the_scene_picture_draws_the_light_and_its_error_ellipse(projected):
    """Both views put the light at its fitted coordinates; the ellipse is the 1σ one of the light
    position's covariance (the fit's correlations times its block-sandwich sigmas), drawn magnified by a
    whole factor until it shows."""
    from rtloop.report.answer import MIN_ELLIPSE, VIEWS, answer, scene_views

    result, _ = projected
    info = answer(result)
    _, drawn = scene_views(result, info)
    unc = result.uncertainty
    names = [f"light.position.{c}" for c in "xyz"]
    idx = [unc["names"].index(n) for n in names]
    s = np.array([unc["robust"]["sigma"][n] for n in names])
    cov = np.asarray(unc["correlation"])[np.ix_(idx, idx)] * np.outer(s, s)
    light = result.scene.to_dict()["light"]["position"]
    for title, a, b in VIEWS:
        view = drawn[title]
        assert view["light"] == pytest.approx([light[a], light[b]])
        sub = cov[np.ix_([a, b], [a, b])]
        width, height, _ = view["ellipse"]
        assert sorted([width, height]) == pytest.approx(sorted(2 * np.sqrt(np.linalg.eigvalsh(sub))), rel=1e-9)
        assert view["magnified"] >= 1 and view["magnified"] * width > 0
    # Millimetre error bars in a metres-wide scene: magnified, and said so.
    assert min(v["magnified"] for v in drawn.values()) > 1
    assert MIN_ELLIPSE > 0


def test_final_png_beside_the_photo(tmp_path, capsys):
    """rtloop-fit --report shows final.png (at --final-scale times the size), not the one-sample render."""
    out = _fit_with_report(tmp_path, capsys, final_scale=3, final_spp=4)
    with Image.open(out / "report" / "fitted.png") as shown, Image.open(out / "final.png") as final:
        assert shown.size == final.size == (3 * W, 3 * H)
        assert np.array_equal(np.asarray(shown.convert("RGB")), np.asarray(final.convert("RGB")))
    assert "final.png, 3× the photo" in (out / "report.html").read_text(encoding="utf-8")


def test_values_in_mm_and_percent(projected, tmp_path):
    result, rows = projected
    page = rtloop.report(result, tmp_path / "r.html", truth=example_truth(W, H), generations=rows).path.read_text(
        encoding="utf-8")
    x = result.x["light.position.x"]
    row = cells(page, "light.position.x")
    assert row[0] == f"{1000 * x:.1f} mm" and row[2] == "2000.0 mm" and row[3].endswith(" mm")
    assert row[1] == f"± {1000 * result.uncertainty['robust']['sigma']['light.position.x']:.2g} mm"
    row = cells(page, "objects.ball.albedo.g")
    assert row[0] == f"{100 * result.x['objects.ball.albedo.g']:.1f} % (convention)" and row[2] == "70.0 %"
    assert row[3] == "split convention"
    for name in result.x:  # every fitted value with its unit
        assert re.search(r" (mm|%|W/sr)( \(convention\))?$", cells(page, name)[0]), cells(page, name)


def test_the_settings_that_ran(projected, two_stage, tmp_path):
    """L-SHADE: its budget and the generations it ran, no F or CR (it adapts them) and no raw list; DE:
    population, F and CR, and each stage's generations."""
    result, rows = projected
    page = rtloop.report(result, tmp_path / "a.html", generations=rows).path.read_text(encoding="utf-8")
    pop, gens = result.settings["population"], result.settings["generations"]
    assert cells(page, "search") == [f"L-SHADE (adapts its own F and CR), population {pop} shrinking, "
                                     f"a budget of {pop * (gens[0] + 1)} evaluations"]
    (stage,) = result.stages
    assert cells(page, "generations run") == [f"light+colour {stage.generations}"]
    assert cells(page, "polish") == [f"Nelder-Mead, up to {result.settings['polish']} evaluations"]
    assert "F, CR" not in page and str(list(gens)) not in page
    result, rows = two_stage
    page = rtloop.report(result, tmp_path / "b.html", generations=rows).path.read_text(encoding="utf-8")
    assert cells(page, "search") == ["differential evolution, population 6, F 0.6, CR 0.8"]
    assert cells(page, "generations run") == ["light 4, colour 5"]
    assert "<td>polish</td>" not in page


def test_one_loss_figure_and_split_plots_say_they_are_a_convention(projected, tmp_path):
    from rtloop.report import plot_search
    from rtloop.report.answer import split_names

    result, rows = projected
    rep = rtloop.report(result, tmp_path / "r.html", generations=rows)
    assert [p.name for p in rep.files if "fitness" in p.name or "loss" in p.name] == ["fitness.png"]
    split = split_names(result)
    assert "light.intensity" in split and "light.position.x" not in split
    figs, _ = plot_search(result.scene, rep_rows(result, rows), split=split)
    titles = {pid: fig.axes[0].get_title() for pid, fig in figs}
    assert "a convention" in titles["objects.ball.albedo"] and "a convention" in titles["light.intensity"]
    assert "convention" not in titles["light.position"] and "convention" not in titles["fitness"]


def rep_rows(result, rows):
    from rtloop.report.plots import _rows_given

    return _rows_given(result, rows, result.scene.param_names())
