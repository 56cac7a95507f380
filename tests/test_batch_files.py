"""A batch job reads its files as a single rtloop-fit does (the mask and grey card its scene names), and a
batch's output folder, lock and results file keep every file that is not the batch's."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import rtloop
from rtloop import cli as fit_cli
from rtloop.acquisition import PinholeCamera, parse_board
from rtloop.acquisition._common import write_png16_srgb
from rtloop.acquisition.synthetic import paste_board_on_floor
from rtloop.batch import Job, fit_many, load_jobs
from rtloop.cli import batch as batch_cli
from rtloop.cli.scene import scene_main
from test_acquisition_cli import BOARD, CARD, CAST, H, TRUE_SCENE, W

FAST = ["--snapshot-every", "0", "--final-scale", "1", "--final-spp", "1", "-q"]


@pytest.fixture(scope="module")
def acquired(tmp_path_factory) -> Path:
    """rtloop-scene's folder for a photo with a board and a grey card of known reflectance: scene.json names
    mask.png (the board left out) and card.png (0.6 reflectance)."""
    d = tmp_path_factory.mktemp("acquired")
    render = rtloop.render(TRUE_SCENE, spp=1)
    cam = PinholeCamera.from_scene_camera(TRUE_SCENE["camera"], W, H)
    photo = paste_board_on_floor(render, rtloop.object_ids(TRUE_SCENE) == 1, 0.45, parse_board(BOARD), cam)
    x, y, w, h = CARD
    photo[y : y + h, x : x + w] *= 0.6 / 0.45
    write_png16_srgb(d / "photo.png", photo * CAST)
    assert scene_main([str(d / "photo.png"), "--board", BOARD, "--ball-radius", "80mm", "--vfov", "50",
                       "--grey-card", ",".join(map(str, CARD)), "--grey-card-reflectance", "0.6",
                       "--board-margin", "0", "--width", "64", "--out", str(d / "scene")]) == 0
    acq = json.loads((d / "scene" / "scene.json").read_text())["meta"]["acquisition"]
    assert acq["mask"] == "mask.png" and acq["grey_card"]["mask"] == "card.png"
    return d / "scene"


def write_jobs(path: Path, jobs: list[dict]) -> Path:
    path.write_text("".join(json.dumps(j) + "\n" for j in jobs), encoding="utf-8")
    return path


def result_json(folder: Path) -> dict:
    return json.loads((folder / "result.json").read_text(encoding="utf-8"))


def test_batch_job_fits_an_acquired_scene_as_rtloop_fit_does(acquired, tmp_path, capsys):
    """The scene's mask and grey card reach the batch's fit: light, values, products and the card's absolute
    numbers equal a single rtloop-fit's bit for bit."""
    scene, photo = acquired / "scene.json", acquired / "objective.png"
    assert fit_cli.main([str(scene), str(photo), "--out", str(tmp_path / "one"), "--seed", "3", *FAST]) == 0
    jobs = write_jobs(tmp_path / "jobs.jsonl", [{"id": "j", "scene": str(scene), "photo": str(photo), "seed": 3}])
    assert batch_cli.main(["--batch", str(jobs), "--out", str(tmp_path / "b"), "--no-images", "-q"]) == 0
    one, job = result_json(tmp_path / "one"), result_json(tmp_path / "b" / "j")
    assert job["light"] == one["light"]
    assert job["fit_report"]["fitted"] == one["fit_report"]["fitted"]
    assert job["fit_report"]["products"] == one["fit_report"]["products"]
    assert job["fit_report"]["reference"] == one["fit_report"]["reference"] is not None
    assert job["fit_report"]["inputs"]["mask"] == one["fit_report"]["inputs"]["mask"] is not None
    (rec,) = [json.loads(line) for line in (tmp_path / "b" / "results.jsonl").read_text().splitlines()]
    assert rec["x"] == one["fit_report"]["fitted"]
    capsys.readouterr()


def test_job_lines_pass_footprint_and_grey_card(acquired, tmp_path, capsys):
    """"footprint" and "grey_card" in a job line do what rtloop-fit's --footprint and the scene's card do;
    "grey_card": false fits without the card."""
    scene, photo = acquired / "scene.json", acquired / "objective.png"
    assert fit_cli.main([str(scene), str(photo), "--out", str(tmp_path / "one"), "--footprint", "off",
                         *FAST]) == 0
    card = {"mask": "card.png", "reflectance": 0.6}
    jobs = [{"id": "off", "scene": "scene.json", "photo": "objective.png", "footprint": "off", "grey_card": card},
            {"id": "nocard", "scene": "scene.json", "photo": "objective.png", "grey_card": False}]
    jobs_file = write_jobs(acquired / "jobs-fp.jsonl", jobs)
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(tmp_path / "b"), "--no-images", "-q"]) == 0
    one, off = result_json(tmp_path / "one"), result_json(tmp_path / "b" / "off")
    assert off["fit_report"]["fitted"] == one["fit_report"]["fitted"]
    assert off["fit_report"]["reference"] == one["fit_report"]["reference"]
    assert result_json(tmp_path / "b" / "nocard")["fit_report"].get("reference") is None
    capsys.readouterr()


def test_job_lines_pass_the_camera_terms(tmp_path, capsys):
    """"vignetting" and "tone" in a job line do what rtloop-fit's --vignetting and --tone-curve do: a vignetted
    photo's job equals the single fit bit for bit with the falloff fitted, given, or left out."""
    case = Path(__file__).resolve().parent / "fixtures" / "camera" / "blue-ball-vignette"
    scene, photo = case / "scene_input.json", case / "objective.png"
    flags = {"fit": [], "given": ["--vignetting=-0.3,-0.1"], "off": ["--vignetting", "off", "--tone-curve", "off"]}
    for name, extra in flags.items():
        assert fit_cli.main([str(scene), str(photo), "--out", str(tmp_path / name), *extra, *FAST]) == 0
    jobs = write_jobs(tmp_path / "jobs.jsonl", [
        {"id": "fit", "scene": str(scene), "photo": str(photo)},
        {"id": "given", "scene": str(scene), "photo": str(photo), "vignetting": [-0.3, -0.1]},
        {"id": "off", "scene": str(scene), "photo": str(photo), "vignetting": "off", "tone": "off"}])
    assert batch_cli.main(["--batch", str(jobs), "--out", str(tmp_path / "b"), "--no-images", "-q"]) == 0
    for name in flags:
        one, job = result_json(tmp_path / name), result_json(tmp_path / "b" / name)
        assert job["fit_report"]["fitted"] == one["fit_report"]["fitted"], name
        assert job["fit_report"]["model"].get("camera") == one["fit_report"]["model"].get("camera"), name
    assert result_json(tmp_path / "fit")["fit_report"]["model"]["camera"]["terms"] == ["vignetting"]
    assert result_json(tmp_path / "off")["fit_report"]["model"].get("camera", {}).get("terms", []) == []
    capsys.readouterr()


LIGHTS = Path(__file__).resolve().parent / "fixtures" / "lights"


def test_a_lights_job_writes_what_rtloop_fit_lights_writes(tmp_path, capsys):
    """"lights" in a job line (or --lights for every job) takes the lights fit as rtloop-fit --lights does:
    the same lights, error bars and products bit for bit, the lights fit's result.json, and a results.jsonl
    line that lists the lights. A scene with a "lights" list takes it without the field."""
    key_fill, window = LIGHTS / "key-fill-25", LIGHTS / "lamp-window"
    for name, case, extra in (("two", key_fill, ["--lights", "2"]), ("listed", window, [])):
        assert fit_cli.main([str(case / "scene_input.json"), str(case / "objective.png"), "--out",
                             str(tmp_path / name), *extra, *FAST]) == 0
    jobs = write_jobs(tmp_path / "jobs.jsonl", [
        {"id": "two", "scene": str(key_fill / "scene_input.json"), "photo": str(key_fill / "objective.png"),
         "lights": 2},
        {"id": "listed", "scene": str(window / "scene_input.json"), "photo": str(window / "objective.png")}])
    assert batch_cli.main(["--batch", str(jobs), "--out", str(tmp_path / "b"), "-q"]) == 0
    records = {r["id"]: r for r in map(json.loads, (tmp_path / "b" / "results.jsonl").read_text().splitlines())}
    for name, count in (("two", 2), ("listed", 2)):
        one, job = result_json(tmp_path / name)["fit_report"], result_json(tmp_path / "b" / name)["fit_report"]
        assert job["method"] == "lights" and len(job["lights"]) == count, name
        assert job["lights"] == one["lights"] and job["products"] == one["products"], name
        assert records[name]["status"] == "ok" and records[name]["lights"] == job["lights"], name
        assert (tmp_path / "b" / name / "final.png").is_file()
    capsys.readouterr()


def test_a_photo_read_as_linear_takes_the_lights_fit(tmp_path, capsys):
    """--response linear declares the photo linear (``tone="linear"``), which the lights fit takes as it
    takes every photo: not refused as a camera term it would ignore."""
    case = LIGHTS / "key-fill-25"
    assert fit_cli.main([str(case / "scene_input.json"), str(case / "objective.png"), "--response", "linear",
                         "--lights", "2", "--out", str(tmp_path / "out"), *FAST]) == 0
    assert len(result_json(tmp_path / "out")["fit_report"]["lights"]) == 2
    capsys.readouterr()


def test_a_lights_job_refuses_the_options_the_lights_fit_does_not_take(tmp_path, capsys):
    """An option the lights fit would ignore (a norm, a camera term) is the job's one-line error naming it,
    not a fit that drops it; a "lights" field of the wrong kind is the line's error."""
    case = LIGHTS / "key-fill-25"
    job = {"id": "l2", "scene": str(case / "scene_input.json"), "photo": str(case / "objective.png"),
           "lights": "auto"}
    jobs = write_jobs(tmp_path / "jobs.jsonl", [job | {"norm": "l2"}, job | {"id": "vig", "vignetting": "on"}])
    assert batch_cli.main(["--batch", str(jobs), "--out", str(tmp_path / "b"), "--no-images", "-q"]) == 1
    records = {r["id"]: r for r in map(json.loads, (tmp_path / "b" / "results.jsonl").read_text().splitlines())}
    assert records["l2"]["status"] == "error" and records["l2"]["error"].startswith("norm: not taken by the lights")
    assert records["vig"]["error"].startswith("vignetting: not taken by the lights")
    assert not (tmp_path / "b" / "l2").exists()
    for bad in (True, "two", 2.0, [2]):
        write_jobs(tmp_path / "bad.jsonl", [job | {"lights": bad}])
        with pytest.raises(rtloop.RtloopError, match=r"'lights' must be \"auto\" or a whole number"):
            load_jobs(tmp_path / "bad.jsonl")
    capsys.readouterr()


def test_job_objects_are_checked_as_job_lines_are(acquired, tmp_path):
    """An id of a Job object is checked as a job line's: no path outside the output folder."""
    out = tmp_path / "out"
    out.mkdir()
    for jid in ("../escaped", str(tmp_path / "abs"), "", ".hidden", "results.jsonl"):
        job = Job(jid, str(acquired / "scene.json"), str(acquired / "objective.png"))
        with pytest.raises(rtloop.RtloopError, match="id"):
            list(fit_many([job], out=out, images=False))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"] and not any(out.iterdir())
    with pytest.raises(rtloop.RtloopError, match="'seed'"):
        list(fit_many([Job("a", "s.json", "p.png", seed=-1)]))
    with pytest.raises(rtloop.RtloopError, match="'crop'"):
        list(fit_many([Job("a", "s.json", "p.png", options={"crop": "no"})]))


def test_shared_options_are_checked_and_a_seed_is_each_jobs(acquired):
    job = {"id": "a", "scene": str(acquired / "scene.json"), "photo": str(acquired / "objective.png")}
    with pytest.raises(rtloop.RtloopError, match="'seed' is each job's own"):
        list(fit_many([job], options={"seed": 4}))
    with pytest.raises(rtloop.RtloopError, match="'crop' must be true or false"):
        list(fit_many([job], options={"crop": "no"}))


@pytest.mark.parametrize(("line", "message"), [
    ('{"id": "a", "scene": null, "photo": "p.png"}', "'scene' must be a path"),
    ('{"id": "a", "scene": "s.json", "photo": "p.png", "crop": "no"}', "'crop' must be true or false"),
    ('{"id": "a", "scene": "s.json", "photo": "p.png", "id": "b"}', "field 'id' given twice"),
    ('{"id": "a", "scene": "s.json", "photo": "p.png", "seed": 1' + "0" * 5000 + "}", "not JSON this program"),
    ("[" * 100_000 + "]" * 100_000, "nested too deep"),
    ('{"id": "results.jsonl", "scene": "s.json", "photo": "p.png"}', "batch's own file"),
    ('{"id": "a", "scene": "s.json", "photo": "p.png", "grey_card": {"mask": "c.png"}}', "'grey_card' must be"),
    ('{"id": "a", "scene": "s.json", "photo": "p.png", "footprint": 1}', "'footprint' must be one of"),
    ('{"id": "a", "scene": "s.json", "photo": "p.png", "seed": 18446744073709551616}', "'seed' must be"),
])
def test_bad_job_lines_are_one_line_each(tmp_path, capsys, line, message):
    jobs = tmp_path / "jobs.jsonl"
    jobs.write_text(line + "\n", encoding="utf-8")
    assert batch_cli.main(["--batch", str(jobs), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"rtloop-fit: error: {jobs}:1: ") and message in err[0], err


def batch_process(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """``rtloop-fit --batch ...`` in a child (a read that blocks ends the child, not the tests)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(rtloop.__file__).resolve().parents[1]),
                                                        os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "rtloop.cli", "--batch", *args], env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_a_jobs_file_or_results_file_that_is_not_a_regular_file_is_refused(acquired, tmp_path):
    fifo = tmp_path / "jobs.fifo"
    os.mkfifo(fifo)
    done = batch_process(str(fifo), "--out", str(tmp_path / "o"))
    assert done.returncode == 1 and done.stderr == f"rtloop-fit: error: {fifo}: not a regular file\n"
    jobs = write_jobs(tmp_path / "jobs.jsonl", [{"id": "a", "scene": str(acquired / "scene.json"),
                                                 "photo": str(acquired / "objective.png")}])
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.jsonl").symlink_to("/dev/zero")  # endless: never read whole
    done = batch_process(str(jobs), "--out", str(out))
    assert done.returncode == 1 and "results.jsonl: not a regular file" in done.stderr
    assert len(done.stderr.splitlines()) == 1
