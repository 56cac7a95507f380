"""``rtloop-fit --lights N|auto`` and a scene with its own ``lights`` list, on the Mitsuba photos of
tests/fixtures/lights (their truth unseen by the fit): result.json and the summary list each light with
its position, intensity and error bars, and the evidence for the number of lights."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rtloop.cli.fit import main

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "lights"
QUICK = ["--final-scale", "1", "--final-spp", "1"]


def run(tmp_path: Path, name: str, *flags: str, capsys: pytest.CaptureFixture) -> tuple[int, dict, str, str]:
    folder = FIXTURES / name
    out = tmp_path / "out"
    code = main([str(folder / "scene_input.json"), str(folder / "objective.png"), "--out", str(out), *QUICK,
                 *flags])
    cap = capsys.readouterr()
    result = json.loads((out / "result.json").read_text()) if code == 0 else {}
    return code, result, cap.out, cap.err


def truth(name: str) -> dict:
    return json.loads((FIXTURES / name / "scene.json").read_text())


def test_auto_finds_key_and_fill_and_writes_the_evidence(tmp_path, capsys):
    code, result, out, _ = run(tmp_path, "key-fill-25", "--lights", "auto", "-q", capsys=capsys)
    assert code == 0
    report = result["fit_report"]
    assert report["method"] == "lights" and len(report["lights"]) == 2
    for light, want in zip(report["lights"], truth("key-fill-25")["lights"]):
        assert np.linalg.norm(np.subtract(light["position"], want["position"])) < (0.05 if light is
                                                                                  report["lights"][0] else 0.30)
        bar = np.asarray(light["position_error"])
        assert bar.shape == (3,) and np.all(np.isfinite(bar)) and np.all(bar > 0) and np.all(bar < 16)
    assert report["lights"][0]["intensity_error"] is None  # held
    fill = report["lights"][1]
    assert fill["intensity_error"] > 0 and abs(fill["intensity"] - 10.0) < 0.05 * 10.0
    evidence = report["number_of_lights"]["evidence"]
    assert [e["lights"] for e in evidence] == [1, 2, 3] and [e["kept"] for e in evidence] == [False, True, False]
    assert evidence[1]["held_out"] < 0.75 * evidence[0]["held_out"]
    # the summary: each light with its position, intensity and error bar, and the held-out error per count
    assert "light0 (point) at (" in out and "light1 (point) at (" in out and "+-" in out
    assert "held-out error per number of lights: 1: " in out
    # the fitted scene is a scene with both lights
    assert len(result["lights"]) == 2 and (tmp_path / "out" / "final.png").is_file()


def test_a_scene_s_own_lights_list_is_respected(tmp_path, capsys):
    code, result, out, _ = run(tmp_path, "lamp-window", "-q", capsys=capsys)
    assert code == 0
    lights = result["fit_report"]["lights"]
    assert [(light["name"], light["kind"]) for light in lights] == [("key", "point"), ("window", "rectangle")]
    lamp, window = truth("lamp-window")["lights"]
    assert np.linalg.norm(np.subtract(lights[0]["position"], lamp["position"])) < 0.05
    assert np.linalg.norm(np.subtract(lights[1]["position"], window["position"])) < 0.30
    assert lights[1]["size"] == [1.5, 1.0]
    assert "window (rectangle) at (" in out and "1.5 x 1 m" in out


@pytest.mark.parametrize("value", ["0", "9", "-2", "2.5", "two", "", "AUTO"])
def test_a_bad_lights_flag_is_one_line_naming_it(tmp_path, capsys, value):
    code, _, _, err = run(tmp_path, "key-fill-25", "--lights", value, capsys=capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "--lights" in lines[0] and "from 1 to 8 or 'auto'" in lines[0], lines


@pytest.mark.parametrize("flags, named", [(["--truth", "x.json"], "--truth"), (["--generations", "5,5"], "--generations")])
def test_options_the_lights_fit_does_not_take_are_refused(tmp_path, capsys, flags, named):
    code, _, _, err = run(tmp_path, "key-fill-25", "--lights", "2", *flags, capsys=capsys)
    assert code == 1
    lines = err.strip().splitlines()
    assert lines[-1].startswith("rtloop-fit: error: " + named) and len([x for x in lines if "error" in x]) == 1


def test_help_teaches_the_lights_flag(capsys):
    assert main(["--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "--lights N|auto" in text and "'auto' to choose how many" in text


def test_one_light_on_a_one_light_scene_is_the_ordinary_fit(tmp_path, capsys):
    """``--lights 1`` on a scene with one point light: the ordinary fit's result.json, no lights fit."""
    from conftest import BALL_ON_FLOOR

    import rtloop

    (tmp_path / "scene.json").write_text(json.dumps(BALL_ON_FLOOR))
    rtloop.save_image(tmp_path / "photo.png", rtloop.render(BALL_ON_FLOOR))
    code = main([str(tmp_path / "scene.json"), str(tmp_path / "photo.png"), "--out", str(tmp_path / "out"), *QUICK,
                 "--lights", "1", "--generations", "2", "--population", "8", "--uncertainty", "off", "-q"])
    assert code == 0, capsys.readouterr().err
    report = json.loads((tmp_path / "out" / "result.json").read_text())["fit_report"]
    assert report.get("method") != "lights" and "stages" in json.dumps(report)


def test_the_report_lists_each_light_and_the_evidence(tmp_path, capsys):
    code, result, _, _ = run(tmp_path, "key-fill-25", "--lights", "auto", "--report", "-q", capsys=capsys)
    assert code == 0
    page = (tmp_path / "out" / "report.html").read_text()
    for light in result["fit_report"]["lights"]:
        assert f"<td>{light['name']}</td>" in page
        assert f"{np.linalg.norm(light['position_error']) * 100:.2f} cm" in page
    assert "How many lights" in page and page.count("<tr>") > 8
    assert (tmp_path / "out" / "report" / "difference.png").is_file()


def test_a_fitted_size_is_written_with_its_error_bars(tmp_path, capsys):
    """The softbox's size, free in its scene's fit section: result.json holds it with an error bar per side
    (metres, within a quarter of the side), the summary and the report print them."""
    code, result, out, _ = run(tmp_path, "lamp-softbox", "--report", "-q", capsys=capsys)
    assert code == 0
    softbox = result["fit_report"]["lights"][1]
    want = truth("lamp-softbox")["lights"][1]["size"]
    assert all(abs(s - w) < 0.2 * w for s, w in zip(softbox["size"], want)), softbox["size"]
    assert all(0 < b < 0.25 * s for s, b in zip(softbox["size"], softbox["size_error"])), softbox
    written = next(light for light in result["lights"] if light["name"] == "softbox")["size"]
    assert np.allclose(written, softbox["size"], rtol=1e-5)  # the report rounds to 6 digits
    assert "softbox (rectangle) at (" in out and "(width +- " in out and ", height +- " in out
    page = (tmp_path / "out" / "report.html").read_text()
    assert "(width ± " in page
