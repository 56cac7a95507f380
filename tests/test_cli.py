"""The ``rtloop-fit`` command line: outputs, progress, errors, and the all-or-nothing output directory."""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import rtloop
from conftest import EXAMPLE, REPO, example_scene, example_truth
from rtloop import cli

W, H = 32, 24
OUTPUTS = ("result.json", "best_per_generation.csv", "final.png", "objective.png", "snapshots")


@pytest.fixture
def inputs(tmp_path: Path) -> tuple[Path, Path]:
    """(scene.json, objective.png) in tmp_path; the objective is rendered by rtloop from a known truth."""
    scene_path = tmp_path / "scene.json"
    scene_path.write_text(json.dumps(example_scene(W, H)), encoding="utf-8")
    truth = example_truth(W, H)
    image_path = tmp_path / "objective.png"
    rtloop.save_image(image_path, rtloop.render(rtloop.load_scene(truth), footprint=True))
    return scene_path, image_path


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = cli.main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def leftovers(parent: Path) -> list[str]:
    """Temporary or set-aside directories the CLI may have left in ``parent``."""
    return sorted(p.name for p in parent.iterdir() if ".rtloop-" in p.name)


def stages_of(out: Path) -> list[tuple[str, int]]:
    report = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]
    return [(s["name"], s["generations"]) for s in report["stages"]]


def error_line(err: str) -> str:
    lines = err.strip("\n").splitlines()
    assert len(lines) == 1, f"expected one line on stderr, got {err!r}"
    assert lines[0].startswith("rtloop-fit: error: "), lines[0]
    return lines[0]


# --- a successful run --------------------------------------------------------------------------------------


def test_outputs(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    out = tmp_path / "runs" / "fit"  # the parent does not exist yet
    code, stdout, stderr = run(capsys, scene_path, image_path, "--out", out, "--population", 12,
                               "--generations", 6, "--seed", 3, "--quiet")
    assert code == 0, stderr
    assert stderr == ""
    assert sorted(os.listdir(out)) == sorted(OUTPUTS)
    assert leftovers(out.parent) == []

    # result.json: the fitted scene in the scene format, plus fit_report with the input paths.
    data = json.loads((out / "result.json").read_text(encoding="utf-8"))
    report = data["fit_report"]
    assert report["inputs"]["scene"] == str(scene_path.resolve())
    assert report["inputs"]["image"] == str(image_path.resolve())
    assert report["seed"] == 3 and report["settings"]["population"] == 12
    fitted = rtloop.load_scene(out / "result.json")
    scene = rtloop.load_scene(scene_path)
    assert fitted.param_names() == scene.param_names()
    assert fitted.get_params(scene.fit_paths) == pytest.approx(list(report["fitted"].values()))
    stages = stages_of(out)
    # DE runs exactly --generations; L-SHADE (the default method) spends population x (generations + 1)
    # evaluations over more, shrinking generations.
    assert stages and all(g >= 6 for _, g in stages)
    # (plus one: the polish re-evaluates the search's best with the pixel footprint)
    assert report["evaluations"] <= 12 * 7 + report["settings"]["polish"] + 1

    # best_per_generation.csv: one row per generation (0..N) of every stage, in order.
    with open(out / "best_per_generation.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["stage", "generation", "evaluations", "fitness", *scene.param_names()]
    body = rows[1:]
    assert len(body) == sum(g + 1 for _, g in stages)
    assert [(r[0], int(r[1])) for r in body] == [(n, g) for n, total in stages for g in range(total + 1)]
    evaluations = [int(r[2]) for r in body]
    assert evaluations == sorted(evaluations) and evaluations[-1] == report["evaluations"]
    assert all(np.isfinite([float(v) for v in r[3:]]).all() for r in body)
    # The last row holds the final stage's best individual (after the polish, when one runs).
    assert float(body[-1][3]) == pytest.approx(report["stages"][-1]["fitness"])

    # snapshots: generations 0, 5 of every stage (N = 6, every 5), at the working resolution.
    shots = sorted(os.listdir(out / "snapshots"))
    assert shots == sorted(f"{n}_gen{g:04d}.bmp" for n, total in stages for g in range(0, total + 1, 5))
    with Image.open(out / "snapshots" / shots[0]) as im:
        assert im.size == (W, H)

    # final.png at 4x the scene's size; objective.png at the working resolution.
    with Image.open(out / "final.png") as im:
        assert im.size == (4 * W, 4 * H)
    with Image.open(out / "objective.png") as im:
        assert im.size == (W, H)

    # The summary on stdout: every fitted value, the output directory.
    for name in scene.param_names():
        assert name in stdout
    assert str(out) in stdout
    assert "evaluations" in stdout
    if report["identifiability"]["degenerate"]:
        assert "determined products" in stdout and "ball" in stdout and "floor" in stdout


def test_a_refit_that_frees_a_lobe_logs_the_scenes_own_parameters(tmp_path, capsys):
    """A photo of a glossy ball (tests/fixtures/photos/gloss-a025): the fit frees the ball's lobe (a coat's
    specular weight, its roughness chosen from the photo) for its refit, a stage whose scene has more
    parameters than the user's. Its generations
    are logged with the user's parameters like the first stage's (the CSV's columns, the snapshots rendered
    from the user's scene; it raised "expected 10 values, got 12" from the snapshot's render), and its
    progress line names it a closed-form stage (an L-SHADE budget), not one of a generation count; the
    report shows the fitted scene's parameters, the lobe at its fitted value."""
    photo = REPO / "tests" / "fixtures" / "photos" / "gloss-a025"
    out = tmp_path / "gloss"
    code, stdout, stderr = run(capsys, photo / "scene_input.json", photo / "objective.png", "--out", out,
                               "--final-scale", 1, "--final-spp", 1, "--report")
    assert code == 0, stderr
    report = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]
    assert "specular" in report["model"]["terms"]
    names = rtloop.load_scene(photo / "scene_input.json").param_names()
    with open(out / "best_per_generation.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["stage", "generation", "evaluations", "fitness", *names]
    assert all(len(r) == len(rows[0]) for r in rows[1:])
    refit = [r for r in rows[1:] if r[0] == "light+colour+specular"]
    assert refit and all(np.isfinite([float(v) for v in r[3:]]).all() for r in refit)
    assert any(n.startswith("light+colour+specular_gen") for n in os.listdir(out / "snapshots"))
    assert "stage 2 'light+colour+specular': L-SHADE, then a Nelder-Mead polish" in stderr
    assert "gen 0/" not in stderr
    # The report plots the fitted scene's parameters, the lobe at its fitted value (it raised "row has 10
    # parameter values; the scene has 12").
    page = (out / "report.html").read_text(encoding="utf-8")
    # the ball is coated plastic (Mitsuba's roughplastic): the lobe freed is the coat's specular weight
    assert report["model"]["evidence"]["specular"]["lobe"] == "coat"
    assert "objects.ball.specular" in page and "freed by the fit for its refit" in page
    assert "lobe: a clear coat (GGX roughness" in stdout + stderr


def test_paper_protocol_generation_pair_and_options(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    out = tmp_path / "paper"
    code, _, stderr = run(capsys, scene_path, image_path, "-o", out, "--protocol", "paper", "--population", 8,
                          "--generations", "4,7", "--snapshot-every", 3, "--final-scale", 2, "--final-spp", 1,
                          "--threads", 2, "--f", 0.5, "--cr", 0.9, "--quiet")
    assert code == 0, stderr
    assert stages_of(out) == [("light", 4), ("colour", 7)]
    with open(out / "best_per_generation.csv", newline="", encoding="utf-8") as fh:
        assert sum(1 for _ in fh) == 1 + 5 + 8
    assert sorted(os.listdir(out / "snapshots")) == sorted(
        [f"light_gen{g:04d}.bmp" for g in (0, 3)] + [f"colour_gen{g:04d}.bmp" for g in (0, 3, 6)]
    )
    with Image.open(out / "final.png") as im:
        assert im.size == (2 * W, 2 * H)
    settings = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]["settings"]
    assert settings["f"] == 0.5 and settings["cr"] == 0.9 and settings["generations"] == [4, 7]


def test_loss_space_option(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    out = tmp_path / "srgb"
    code, _, stderr = run(capsys, scene_path, image_path, "-o", out, "--loss-space", "srgb", "--population", 8,
                          "--generations", 3, "--snapshot-every", 0, "--final-scale", 1, "--final-spp", 1, "--quiet")
    assert code == 0, stderr
    settings = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]["settings"]
    assert settings["space"] == "srgb" and settings["norm"] == "l1"
    code, stdout, _ = run(capsys, "--help")
    assert "--loss-space {auto,linear,srgb}" in stdout


def test_footprint_option(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    out = tmp_path / "footprint"
    code, _, stderr = run(capsys, scene_path, image_path, "-o", out, "--footprint", "--population", 8,
                          "--generations", 3, "--snapshot-every", 0, "--final-scale", 1, "--final-spp", 1, "--quiet")
    assert code == 0, stderr
    settings = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]["settings"]
    assert settings["footprint"] == "on"
    code, _, stderr = run(capsys, scene_path, image_path, "-o", tmp_path / "off", "--footprint", "off",
                          "--population", 8, "--generations", 3, "--snapshot-every", 0, "--final-scale", 1,
                          "--final-spp", 1, "--quiet")
    assert code == 0, stderr
    settings = json.loads((tmp_path / "off" / "result.json").read_text(encoding="utf-8"))["fit_report"]["settings"]
    assert settings["footprint"] == "off"
    code, stdout, _ = run(capsys, "--help")
    assert "--footprint [{auto,silhouette,on,off}]" in stdout


def test_uncertainty_option(inputs, tmp_path, capsys):
    """--uncertainty bootstrap adds the block bootstrap to result.json (method, cost, seed) and prints its
    sigma with the method; the default names the sandwich and the pixel footprint's shift on the light; off
    leaves the uncertainty out; a value outside the choices is refused."""
    scene_path, image_path = inputs
    common = ("--population", 8, "--generations", 3, "--snapshot-every", 0, "--final-scale", 1, "--final-spp", 1)
    out = tmp_path / "boot"
    code, stdout, stderr = run(capsys, scene_path, image_path, "-o", out, "--uncertainty", "bootstrap", *common)
    assert code == 0, stderr
    u = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]["uncertainty"]
    boot = u["bootstrap"]
    assert boot["method"] == "block-bootstrap" and boot["ms"] > 0 and boot["seed"] == 0
    assert all(boot["sigma"][f"light.position.{c}"] > 0 for c in "xyz")
    assert "block bootstrap" in stdout
    out = tmp_path / "default"
    code, stdout, stderr = run(capsys, scene_path, image_path, "-o", out, *common)
    assert code == 0, stderr
    shift = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]["uncertainty"]["robust"][
        "footprint_shift"]
    moved = 1e3 * float(np.linalg.norm([shift[f"light.position.{c}"] for c in "xyz"]))
    assert f"block sandwich (correlated residuals) plus the pixel footprint's shift (robust.footprint_shift, " \
           f"{moved:.2g} mm on the light)" in stdout
    out = tmp_path / "off"
    code, _, stderr = run(capsys, scene_path, image_path, "-o", out, "--uncertainty", "off", *common)
    assert code == 0, stderr
    assert json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]["uncertainty"] is None
    code, _, stderr = run(capsys, scene_path, image_path, "--uncertainty", "thorough")
    assert code != 0 and "--uncertainty" in stderr


def test_snapshots_disabled(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    out = tmp_path / "out"
    code, _, stderr = run(capsys, scene_path, image_path, "--out", out, "--population", 8, "--generations", 3,
                          "--snapshot-every", 0, "--final-spp", 1, "--quiet")
    assert code == 0, stderr
    assert os.listdir(out / "snapshots") == []


def test_progress_on_stderr(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    code, _, stderr = run(capsys, scene_path, image_path, "--out", tmp_path / "out", "--protocol", "paper",
                          "--population", 8, "--generations", 12, "--final-spp", 1)
    assert code == 0, stderr
    assert "stage 1 'light'" in stderr and "stage 2 'colour'" in stderr
    for stage in ("light", "colour"):
        gens = [line.split()[2] for line in stderr.splitlines() if line.split()[:2] == [stage, "gen"]]
        assert gens == ["0/12", "10/12", "12/12"]
    assert "best" in stderr and "evals" in stderr


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_on_a_terminal_is_one_updating_line(inputs, tmp_path, capsys, monkeypatch):
    scene_path, image_path = inputs
    term = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", term)
    code = cli.main([str(scene_path), str(image_path), "--out", str(tmp_path / "out"), "--protocol", "paper",
                     "--population", "8", "--generations", "12", "--final-spp", "1"])
    assert code == 0, term.getvalue()
    lines = term.getvalue().split("\n")
    updating = [line for line in lines if "\r" in line]
    assert len(updating) == 2  # one per stage, each ending at the stage's last generation
    assert all(line.rstrip().endswith("s") and " gen 12/12 " in line.split("\r")[-1] for line in updating)
    assert capsys.readouterr().err == ""


def test_scene_and_image_swapped(inputs, tmp_path, capsys):
    """An image given as SCENE is one line that names the likely mistake, not a UTF-8 decoding error."""
    scene_path, image_path = inputs
    code, stdout, stderr = run(capsys, image_path, scene_path, "--out", tmp_path / "out", "--quiet")
    assert (code, stdout) == (1, "")
    assert error_line(stderr) == (f"rtloop-fit: error: {image_path}: is not a scene (JSON) but {scene_path} is: "
                                  "SCENE and IMAGE swapped? (usage: rtloop-fit SCENE IMAGE --out DIR)")
    code, _, stderr = run(capsys, image_path, image_path, "--out", tmp_path / "out", "--quiet")
    assert code == 1 and error_line(stderr) == (f"rtloop-fit: error: {image_path}: is not a scene file (JSON "
                                                "text); SCENE comes first, then IMAGE")
    assert "codec" not in stderr and not (tmp_path / "out").exists()


def test_crop_and_linear_response(inputs, tmp_path, capsys):
    scene_path, _ = inputs
    wide = tmp_path / "wide.png"
    Image.fromarray(np.full((H, 2 * W, 3), 128, np.uint8)).save(wide)
    code, _, stderr = run(capsys, scene_path, wide, "--out", tmp_path / "nocrop", "--quiet")
    assert code == 1 and "aspect" in error_line(stderr)
    # In the command line's words: the option, not the Python argument (which rtloop.load_image names).
    assert error_line(stderr).endswith("crop the image or pass --crop") and "crop=True" not in stderr
    with pytest.raises(rtloop.RtloopError, match=r"pass crop=True$"):
        rtloop.load_image(wide, rtloop.load_scene(scene_path))
    out = tmp_path / "crop"
    code, _, stderr = run(capsys, scene_path, wide, "--out", out, "--crop", "--response", "linear",
                          "--population", 8, "--generations", 1, "--final-spp", 1, "--quiet")
    assert code == 0, stderr
    inputs_ = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]["inputs"]
    assert inputs_["crop"] is True and inputs_["response"] == "linear"


# --- bad input ---------------------------------------------------------------------------------------------


def test_bad_scene_file(inputs, tmp_path, capsys):
    _, image_path = inputs
    bad = tmp_path / "bad_scene.json"
    d = example_scene(W, H)
    d["objects"][0]["radius"] = -1
    bad.write_text(json.dumps(d), encoding="utf-8")
    out = tmp_path / "out"
    code, stdout, stderr = run(capsys, bad, image_path, "--out", out)
    assert code == 1
    line = error_line(stderr)
    assert str(bad) in line and "radius" in line
    assert stdout == ""
    assert not out.exists() and leftovers(tmp_path) == []

    bad.write_text("{ not json", encoding="utf-8")
    code, _, stderr = run(capsys, bad, image_path, "--out", out)
    assert code == 1 and str(bad) in error_line(stderr)


def test_missing_files(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    missing = tmp_path / "nope.json"
    code, _, stderr = run(capsys, missing, image_path, "--out", tmp_path / "out")
    assert code == 1 and str(missing) in error_line(stderr)
    missing = tmp_path / "nope.png"
    code, _, stderr = run(capsys, scene_path, missing, "--out", tmp_path / "out")
    assert code == 1 and str(missing) in error_line(stderr)
    assert not (tmp_path / "out").exists() and leftovers(tmp_path) == []


def test_wrong_image_file(inputs, tmp_path, capsys):
    scene_path, _ = inputs
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"this is not a PNG")
    code, _, stderr = run(capsys, scene_path, junk, "--out", tmp_path / "out")
    assert code == 1 and str(junk) in error_line(stderr)
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize(
    "extra",
    [
        [],
        ["--population", "2"],
        ["--population", "many"],
        ["--generations", "x"],
        ["--generations", "1,2,3"],
        ["--generations", "-1"],
        ["--f", "0"],
        ["--cr", "1.5"],
        ["--protocol", "fast"],
        ["--response", "gamma"],
        ["--loss-space", "gamma"],
        ["--snapshot-every", "-1"],
        ["--final-scale", "0"],
        ["--final-scale", "16385"],
        ["--final-spp", "5000"],
        ["--final-spp", "0"],
        ["--threads", str(2**40)],
        ["--threads", "0"],
        ["--population", "1000000000"],
        ["--seed", "-1"],
        ["--seed", str(2**64)],
        ["--norm", "bogus"],
        ["--norm", "huber:-1"],
        ["--norm", "huber:nan"],
        ["--bogus"],
    ],
)
def test_bad_command_line(inputs, tmp_path, capsys, extra):
    scene_path, image_path = inputs
    args = [scene_path, image_path, "--out", tmp_path / "out", *extra] if extra else []
    code, stdout, stderr = run(capsys, *args)
    assert code == 2
    error_line(stderr)
    assert stdout == ""
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("extra", "flag"), [(["--final-spp", "5000"], "--final-spp"),
                                             (["--norm", "bogus"], "--norm"),
                                             (["--final-scale", "1000"], "--final-scale 1000")])
def test_final_render_and_norm_checked_before_the_fit_naming_the_flag(inputs, tmp_path, capsys, extra, flag):
    scene_path, image_path = inputs
    code, _, stderr = run(capsys, scene_path, image_path, "--out", tmp_path / "out", *extra)
    assert code == (1 if flag == "--final-scale 1000" else 2)  # the scene's size is known once it is loaded
    assert flag in error_line(stderr) and "fitting" not in stderr
    assert not (tmp_path / "out").exists()


def test_help(capsys):
    code, stdout, _ = run(capsys, "--help")
    assert code == 0
    for word in ("result.json", "best_per_generation.csv", "snapshots/", "final.png", "objective.png",
                 "examples/yellow-ball/scene_input.json", "examples/yellow-ball/objective.png",
                 '"fit" section', "light", "colour", "--force"):
        assert word in stdout, word


def test_console_script():
    exe = shutil.which("rtloop-fit")
    if exe is None:
        pytest.skip("rtloop-fit is not on PATH (package not installed)")
    proc = subprocess.run([exe, "--help"], check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "result.json" in proc.stdout and "final.png" in proc.stdout
    proc = subprocess.run([exe], check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [proc.stderr.strip()]
    assert "Traceback" not in proc.stderr


# --- the output directory: nothing lost, nothing half-written ------------------------------------------------


def old_results(path: Path) -> Path:
    path.mkdir()
    (path / "keep.txt").write_text("old results", encoding="utf-8")
    return path


def test_existing_dir_needs_force(inputs, tmp_path, capsys, monkeypatch):
    scene_path, image_path = inputs
    out = old_results(tmp_path / "out")

    def no_fit(*args, **kwargs):
        raise AssertionError("the fit must not start")

    monkeypatch.setattr(rtloop, "fit", no_fit)
    code, _, stderr = run(capsys, scene_path, image_path, "--out", out)
    assert code != 0
    line = error_line(stderr)
    assert str(out) in line and "--force" in line
    assert os.listdir(out) == ["keep.txt"]
    assert (out / "keep.txt").read_text(encoding="utf-8") == "old results"
    assert leftovers(tmp_path) == []


def test_force_replaces(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    out = old_results(tmp_path / "out")
    code, _, stderr = run(capsys, scene_path, image_path, "--out", out, "--force", "--population", 8,
                          "--generations", 2, "--final-spp", 1, "--quiet")
    assert code == 0, stderr
    assert sorted(os.listdir(out)) == sorted(OUTPUTS)
    assert leftovers(tmp_path) == []


def test_existing_empty_dir_is_used(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    out = tmp_path / "out"
    out.mkdir()
    code, _, stderr = run(capsys, scene_path, image_path, "--out", out, "--population", 8, "--generations", 2,
                          "--final-spp", 1, "--quiet")
    assert code == 0, stderr
    assert sorted(os.listdir(out)) == sorted(OUTPUTS)


def test_out_is_a_file(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    out = tmp_path / "out"
    out.write_text("x", encoding="utf-8")
    code, _, stderr = run(capsys, scene_path, image_path, "--out", out, "--force")
    assert code == 1 and "not a directory" in error_line(stderr)
    assert out.read_text(encoding="utf-8") == "x"


def test_force_refuses_to_replace_the_inputs(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    code, _, stderr = run(capsys, scene_path, image_path, "--out", tmp_path, "--force")
    assert code == 1 and "refusing" in error_line(stderr)
    assert scene_path.exists() and image_path.exists()


def test_refuses_to_replace_the_current_directory(inputs, tmp_path, capsys, monkeypatch):
    scene_path, image_path = inputs
    out = old_results(tmp_path / "out")
    monkeypatch.chdir(out)
    code, _, stderr = run(capsys, scene_path, image_path, "--out", ".", "--force")
    assert code == 1 and "current directory" in error_line(stderr)
    assert os.listdir(out) == ["keep.txt"]


def failing_fit(monkeypatch, exc: BaseException, seen: list[list[str]], parent: Path) -> None:
    """Make rtloop.fit raise ``exc`` in the middle of its first stage (after generation 3)."""
    real_fit = rtloop.fit

    def fit(*args, callback=None, **kwargs):
        def cb(info):
            callback(info)
            if info.generation == 3:
                seen.append(leftovers(parent))
                raise exc
        return real_fit(*args, callback=cb, **kwargs)

    monkeypatch.setattr(rtloop, "fit", fit)


@pytest.mark.parametrize("force", [False, True])
def test_failure_midway_leaves_nothing(inputs, tmp_path, capsys, monkeypatch, force):
    scene_path, image_path = inputs
    parent = tmp_path / "results"
    parent.mkdir()
    out = parent / "out"
    if force:
        old_results(out)
    seen: list[list[str]] = []
    failing_fit(monkeypatch, rtloop.RtloopError("boom in the middle"), seen, parent)
    args = [scene_path, image_path, "--out", out, "--population", 8, "--generations", 10, "--snapshot-every", 1]
    code, stdout, stderr = run(capsys, *args, *(["--force"] if force else []))
    assert code == 1
    assert error_line(stderr.splitlines()[-1]) == "rtloop-fit: error: boom in the middle"
    assert stdout == ""
    assert len(seen) == 1 and len(seen[0]) == 1 and "rtloop-tmp" in seen[0][0]  # it was being written
    assert leftovers(parent) == []
    if force:
        assert os.listdir(out) == ["keep.txt"]
    else:
        assert os.listdir(parent) == []


def test_keyboard_interrupt_cleans_up(inputs, tmp_path, capsys, monkeypatch):
    scene_path, image_path = inputs
    out = old_results(tmp_path / "out")
    seen: list[list[str]] = []
    failing_fit(monkeypatch, KeyboardInterrupt(), seen, tmp_path)
    code, stdout, stderr = run(capsys, scene_path, image_path, "--out", out, "--force", "--population", 8,
                               "--generations", 10)
    assert code == 130
    assert stderr.strip().splitlines()[-1] == "rtloop-fit: interrupted"
    assert "Traceback" not in stderr and stdout == ""
    assert seen and leftovers(tmp_path) == []
    assert os.listdir(out) == ["keep.txt"]


def test_failure_writing_final_image(inputs, tmp_path, capsys, monkeypatch):
    scene_path, image_path = inputs
    out = tmp_path / "out"
    real_save = rtloop.save_image

    def save_image(path, image):
        if Path(path).name == "final.png":
            raise OSError(28, "No space left on device", str(path))
        real_save(path, image)

    monkeypatch.setattr(rtloop, "save_image", save_image)
    code, _, stderr = run(capsys, scene_path, image_path, "--out", out, "--population", 8, "--generations", 2,
                          "--final-spp", 1, "--quiet")
    assert code == 1 and "No space left on device" in error_line(stderr)
    assert not out.exists() and leftovers(tmp_path) == []


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("sig, code, word", [(signal.SIGINT, 130, "interrupted"),
                                             (signal.SIGTERM, 143, "terminated")])
def test_signal_during_fit(inputs, tmp_path, sig, code, word):
    """A real Ctrl-C (or SIGTERM) in the middle of a long fit stops it promptly and cleans up."""
    scene_path, image_path = inputs
    out = old_results(tmp_path / "out")
    # A shell may start background processes with SIGINT ignored; restore Python's handler for the test.
    launch = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
              "from rtloop.cli import main; sys.exit(main())")
    cmd = [sys.executable, "-c", launch,
           str(scene_path), str(image_path), "--out", str(out), "--force", "--generations", "1000000",
           "--snapshot-every", "0"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        while True:  # wait for the event "the fit is under way": its CSV has rows (the fit asks for 10^6 gens)
            tmp = [p for p in tmp_path.iterdir() if "rtloop-tmp" in p.name]
            csv_file = tmp[0] / "best_per_generation.csv" if tmp else None
            if csv_file is not None and csv_file.exists() and csv_file.stat().st_size > 2000:
                break
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        proc.send_signal(sig)
        # The behaviour, not its speed: the run ends by itself on the signal (10^6 generations would not end
        # in this test's lifetime), with the status and message below. The timeout is only a hang guard.
        stdout, stderr = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == code, stderr
    assert stderr.strip().splitlines()[-1] == f"rtloop-fit: {word}"
    assert "Traceback" not in stderr and stdout == ""
    assert leftovers(tmp_path) == []
    assert os.listdir(out) == ["keep.txt"]


# --- the README's example ----------------------------------------------------------------------------------


def test_repo_example(tmp_path, capsys):
    scene_path = EXAMPLE / "scene_input.json"
    image_path = EXAMPLE / "objective.png"
    out = tmp_path / "yellow-ball-fit"
    code, stdout, stderr = run(capsys, scene_path, image_path, "--out", out, "--seed", 1, "--population", 8,
                               "--generations", 3, "--snapshot-every", 0, "--final-scale", 1, "--final-spp", 1)
    assert code == 0, stderr
    assert "stage 1" in stderr
    scene = rtloop.load_scene(scene_path)
    fitted = rtloop.load_scene(out / "result.json")
    assert (fitted.width, fitted.height) == (scene.width, scene.height)
    for name in scene.param_names():
        assert name in stdout
    with Image.open(out / "final.png") as im:
        assert im.size == (scene.width, scene.height)


def test_mask_option(capsys, inputs, tmp_path):
    scene_path, image_path = inputs
    mask = np.ones((H, W, 3), np.float32)
    mask[:, : W // 4] = 0.0
    rtloop.save_image(tmp_path / "mask.png", mask)
    out = tmp_path / "masked"
    code, _, err = run(capsys, scene_path, image_path, "--out", out, "--mask", tmp_path / "mask.png",
                       "--population", 8, "--generations", 3, "--quiet", "--snapshot-every", 0)
    assert code == 0, err
    report = json.loads((out / "result.json").read_text(encoding="utf-8"))["fit_report"]
    assert report["inputs"]["mask"] == str((tmp_path / "mask.png").resolve())
    assert report["settings"]["masked_pixels"] == H * (W // 4)
    code, _, err = run(capsys, scene_path, image_path, "--out", tmp_path / "x", "--mask", tmp_path / "nope.png")
    assert code == 1 and "nope.png" in error_line(err)


# --- what killed runs leave --------------------------------------------------------------------------------


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_staging_dirs_of_dead_runs_are_cleaned(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    dead = tmp_path / f".out.rtloop-tmp-p{_dead_pid()}-abc123"
    live = tmp_path / f".out.rtloop-tmp-p{os.getpid()}-abc123"  # a run still under way: kept
    other = tmp_path / f".other.rtloop-tmp-p{_dead_pid()}-abc123"  # another DIR's: not ours to clean
    for d in (dead, live, other):
        d.mkdir()
        (d / "partial.csv").write_text("x")
    code, _, stderr = run(capsys, scene_path, image_path, "--out", tmp_path / "out", "-q")
    assert code == 0, stderr
    assert f"deleted {dead.name}" in stderr
    assert not dead.exists() and live.is_dir() and other.is_dir()


def test_a_replace_killed_between_its_renames_is_recovered(inputs, tmp_path, capsys):
    scene_path, image_path = inputs
    out = tmp_path / "out"
    aside = tmp_path / f".out.rtloop-old-p{_dead_pid()}-0123abcd"  # DIR renamed aside, then the kill
    aside.mkdir()
    (aside / "keep.txt").write_text("old results")
    code, _, stderr = run(capsys, scene_path, image_path, "--out", out, "-q")
    assert code == 1 and "recovered" in stderr and "--force" in stderr.splitlines()[-1]
    assert (out / "keep.txt").read_text() == "old results" and not aside.exists()
    code, _, stderr = run(capsys, scene_path, image_path, "--out", out, "-q", "--force")
    assert code == 0, stderr
    assert (out / "result.json").is_file() and leftovers(tmp_path) == []


@pytest.mark.parametrize(("where", "argv0", "entry", "code"), [
    ("rtloop._native", "/usr/bin/rtloop-fit", "rtloop.cli:main", 130),
    ("rtloop.cli.fit", "/usr/bin/rtloop-fit", "rtloop.cli:main", 130),
    ("rtloop._native", "my_script.py", "rtloop.cli:main", None),
    ("cv2", "/usr/bin/rtloop-acquire", "rtloop.cli.acquire:acquire_main", 130),
    ("rtloop.acquisition.calibration", "/usr/bin/rtloop-acquire", "rtloop.cli.acquire:acquire_main", 130),
    ("rtloop.acquisition.response", "/usr/bin/rtloop-scene", "rtloop.cli.scene:scene_main", 130),
    ("rtloop.acquisition.response", "my_script.py", "rtloop.cli.scene:scene_main", None),
])
def test_ctrl_c_while_importing(where, argv0, entry, code):
    """A Ctrl-C that lands while the console script imports (the event made certain here: an import hook
    raises it when ``where`` is imported) prints one line and exits 130; a library import re-raises it."""
    launch = ("import sys\n"
              f"sys.argv[0] = {argv0!r}\n"
              "class Interrupt:\n"
              "    def find_spec(self, name, path=None, target=None):\n"
              f"        if name == {where!r}:\n"
              "            raise KeyboardInterrupt\n"
              "sys.meta_path.insert(0, Interrupt())\n"
              f"from {entry.split(':')[0]} import {entry.split(':')[1]}\n")
    proc = subprocess.run([sys.executable, "-c", launch], capture_output=True, text=True, check=False)
    if code == 130:
        script = argv0.rsplit("/", 1)[-1]
        assert proc.returncode == 130 and proc.stderr == f"{script}: interrupted\n", proc.stderr
    else:  # not a console script: the interrupt propagates as usual
        assert proc.returncode != 0 and "KeyboardInterrupt" in proc.stderr


@pytest.mark.parametrize("damage", ["truncated", "corrupt"])
def test_a_damaged_png_gives_one_line_on_stderr(tmp_path, capfd, damage):
    """libpng and OpenCV write their diagnostics straight to the process's stderr (fd 2); a damaged
    photo must still give one line that names the file, with the decoder's reason in it."""
    data = bytearray((EXAMPLE / "objective.png").read_bytes())
    if damage == "truncated":
        data = data[: len(data) // 2]
    else:  # flip bits inside the first IDAT chunk's compressed stream
        start = data.index(b"IDAT") + 40
        for i in range(start, start + 200):
            data[i] ^= 0x5A
    photo = tmp_path / "photo.png"
    photo.write_bytes(bytes(data))
    capfd.readouterr()
    code = cli.main([str(EXAMPLE / "scene_input.json"), str(photo), "--out", str(tmp_path / "out"), "-q"])
    err = capfd.readouterr().err
    assert code == 1
    assert err.strip().splitlines() == [err.strip()], err
    assert str(photo) in err and "not a readable image" in err


@pytest.mark.parametrize("norm", ["l2", "huber:0.05"])
def test_norm_option_reaches_the_fit(inputs, tmp_path, capsys, norm):
    """--norm is the fit's per-pixel penalty: the CLI's fit is the library's with the same norm (same light
    to the last digit, and a different one from the L1 default's), and result.json records it."""
    scene_path, image_path = inputs
    out = tmp_path / "fit"
    code, _, stderr = run(capsys, scene_path, image_path, "-o", out, "--norm", norm, "--seed", 4,
                          "--snapshot-every", 0, "--final-scale", 1, "--final-spp", 1, "--quiet")
    assert code == 0, stderr
    saved = json.loads((out / "result.json").read_text(encoding="utf-8"))
    assert saved["fit_report"]["settings"]["norm"] == norm
    scene = rtloop.load_scene(scene_path)
    photo = rtloop.load_image(image_path, scene)
    same = rtloop.fit(scene, photo, seed=4, norm=norm, uncertainty=False).scene.to_dict()["light"]["position"]
    l1 = rtloop.fit(scene, photo, seed=4, uncertainty=False).scene.to_dict()["light"]["position"]
    fitted = saved["light"]["position"]  # result.json is the fitted scene plus its fit_report
    assert fitted == same and fitted != l1


def test_save_scene_round_trips_and_writes_whole_files(tmp_path):
    """save_scene writes what load_scene reads back identically (floats to the last bit: serde_json's
    float_roundtrip), from a Scene or a dict; a dict that is not valid JSON (NaN) is refused and leaves the
    file that was there as it was."""
    scene = rtloop.load_scene(example_scene(W, H))
    d = scene.to_dict()
    d["light"]["position"] = [0.1, 1 / 3, 2.0000000000000004]  # decimals that need all 17 digits
    path = tmp_path / "s.json"
    rtloop.save_scene(rtloop.load_scene(d), path)
    assert rtloop.load_scene(path).to_dict() == rtloop.load_scene(d).to_dict()
    assert rtloop.load_scene(path).to_dict()["light"]["position"] == [0.1, 1 / 3, 2.0000000000000004]
    rtloop.save_scene(d, tmp_path / "d.json")
    assert json.loads((tmp_path / "d.json").read_text()) == d
    before = path.read_bytes()
    with pytest.raises(rtloop.SceneError, match=r"s\.json: the scene cannot be written as JSON .*nothing written"):
        rtloop.save_scene({**d, "exposure": float("nan")}, path)
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["d.json", "s.json"]
