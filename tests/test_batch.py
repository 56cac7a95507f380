"""fit_many and ``rtloop-fit --batch``: equality with single fits, failing jobs, resume, whole lines."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import rtloop
from conftest import example_scene
from rtloop.batch import fit_many, job_hash, load_jobs
from rtloop.batch.folder import LOCK, MARKER
from rtloop.cli import batch as batch_cli

W, H = 32, 24
TRUTHS = [([2.0, 4.0, -1.5], 40.0), ([2.5, 4.5, -1.0], 55.0), ([1.5, 3.5, -2.0], 30.0)]


@pytest.fixture
def photos(tmp_path: Path) -> tuple[Path, list[Path]]:
    """A 32x24 scene and three photos of it rendered by rtloop from known lights."""
    d = example_scene(W, H)
    scene_path = tmp_path / "scene.json"
    scene_path.write_text(json.dumps(d), encoding="utf-8")
    paths = []
    for i, (pos, intensity) in enumerate(TRUTHS):
        truth = json.loads(json.dumps(d))
        truth["light"].update(position=pos, intensity=intensity)
        p = tmp_path / f"photo{i}.png"
        rtloop.save_image(p, rtloop.render(rtloop.load_scene(truth)))
        paths.append(p)
    return scene_path, paths


def jobs_of(scene: Path, photos: list[Path], **extra: object) -> list[dict]:
    return [{"id": f"f{i}", "scene": str(scene), "photo": str(p), "seed": 10 + i, **extra}
            for i, p in enumerate(photos)]


def single(scene: Path, photo: Path, seed: int, **kw: object) -> rtloop.FitResult:
    s = rtloop.load_scene(scene)
    return rtloop.fit(s, rtloop.load_image(photo, s), seed=seed, **kw)


# --- fit_many ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("workers,threads", [(2, 1), (1, 2)])
def test_fit_many_equals_single_fits(photos, workers, threads):
    scene, paths = photos
    results = {r.id: r for r in fit_many(jobs_of(scene, paths), workers=workers, threads=threads)}
    assert sorted(results) == ["f0", "f1", "f2"]
    for i, p in enumerate(paths):
        r, ref = results[f"f{i}"], single(scene, p, 10 + i)
        assert r.status == "ok" and r.error is None
        assert r.x == ref.x  # same seed, same numbers, bit for bit
        assert r.products == ref.products
        assert r.light == rtloop.scene_to_dict(ref.scene)["light"]
        # and the fit found the light the photo was rendered with
        pos = r.light["position"]
        assert max(abs(a - b) for a, b in zip(pos, TRUTHS[i][0])) < 0.1


def test_per_job_options_reach_the_fit(photos):
    scene, paths = photos
    jobs = jobs_of(scene, paths[:1], protocol="paper", generations=[3, 3], population=8)
    (r,) = list(fit_many(jobs))
    ref = single(scene, paths[0], 10, protocol="paper", generations=(3, 3), population=8)
    assert r.x == ref.x and r.evaluations == ref.evaluations
    assert [s.name for s in r.fit.stages] == [s.name for s in ref.stages]


def test_failing_jobs_are_recorded_and_the_batch_goes_on(photos, tmp_path):
    scene, paths = photos
    bad_scene = tmp_path / "bad.json"
    bad_scene.write_text('{"camera": 3}', encoding="utf-8")
    jobs = jobs_of(scene, paths)
    jobs.insert(1, {"id": "missing", "scene": str(scene), "photo": str(tmp_path / "nope.png")})
    jobs.insert(2, {"id": "badscene", "scene": str(bad_scene), "photo": str(paths[0])})
    jobs.append({"id": "badopt", "scene": str(scene), "photo": str(paths[0]), "norm": "l7"})
    results = {r.id: r for r in fit_many(jobs, workers=2)}
    assert len(results) == 6
    assert [results[f"f{i}"].status for i in range(3)] == ["ok"] * 3
    for jid in ("missing", "badscene", "badopt"):
        assert results[jid].status == "error" and results[jid].light is None
    assert "nope.png" in results["missing"].error
    assert "l7" in results["badopt"].error


def test_bad_job_lines_are_refused_up_front(photos):
    scene, paths = photos
    with pytest.raises(rtloop.RtloopError, match="unknown field 'genrations'"):
        list(fit_many([{"id": "a", "scene": str(scene), "photo": str(paths[0]), "genrations": 3}]))
    with pytest.raises(rtloop.RtloopError, match="used twice"):
        list(fit_many(jobs_of(scene, paths[:1]) * 2))
    with pytest.raises(rtloop.RtloopError, match="id '../x'"):
        list(fit_many([{"id": "../x", "scene": str(scene), "photo": str(paths[0])}]))


def test_hash_follows_every_input(photos, tmp_path):
    scene, paths = photos
    (job,) = load_jobs(write_jobs(tmp_path / "j.jsonl", jobs_of(scene, paths[:1])))
    h = job_hash(job)
    assert job_hash(job) == h
    assert job_hash(job, {"norm": "l2"}) != h
    changed = rtloop.batch.Job(job.id, job.scene, str(paths[1]), job.seed)
    assert job_hash(changed) != h
    assert job_hash(rtloop.batch.Job(job.id, job.scene, job.photo, job.seed + 1)) != h


def test_warm_start_runs_in_order_from_the_previous_light(photos):
    scene, paths = photos
    # frames of a "video": the same photo three times; each later frame searches near the first's light
    jobs = [{"id": f"t{i}", "scene": str(scene), "photo": str(paths[0]), "seed": 1} for i in range(3)]
    results = list(fit_many(jobs, warm_start=True))
    assert [r.id for r in results] == ["t0", "t1", "t2"]
    assert all(r.ok for r in results)
    cold = single(scene, paths[0], 1)
    assert results[0].x == cold.x  # the first frame has no previous light
    pos0 = results[0].light["position"]
    for r in results[1:]:
        assert max(abs(a - b) for a, b in zip(r.light["position"], pos0)) < 0.05
        # the fitted scene keeps the scene's own bounds, not the narrowed ones
        assert r.fit.scene.bounds(["light.position"]) == rtloop.load_scene(scene).bounds(["light.position"])


# --- rtloop-fit --batch ------------------------------------------------------------------------------------


def write_jobs(path: Path, jobs: list[dict]) -> Path:
    path.write_text("".join(json.dumps(j) + "\n" for j in jobs), encoding="utf-8")
    return path


def records(out: Path) -> list[dict]:
    text = (out / "results.jsonl").read_text(encoding="utf-8")
    assert text == "" or text.endswith("\n")
    return [json.loads(line) for line in text.splitlines()]


def test_batch_cli_outputs_and_resume(photos, tmp_path, capsys):
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths))
    out = tmp_path / "out"
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(out), "--no-images"]) == 0
    err = capsys.readouterr().err
    assert "3/3 done, 0 failed" in err
    recs = records(out)
    assert sorted(r["id"] for r in recs) == ["f0", "f1", "f2"]
    for r in recs:
        assert r["status"] == "ok" and r["error"] is None and r["seconds"] > 0
        result_json = json.loads((out / r["id"] / "result.json").read_text(encoding="utf-8"))
        assert r["light"] == result_json["light"]
        assert r["products"] == result_json["fit_report"]["products"]
        assert not (out / r["id"] / "final.png").exists()
    ref = single(scene, paths[1], 11)
    assert next(r for r in recs if r["id"] == "f1")["x"] == ref.x
    # and equal to a single rtloop-fit with the same seed
    assert rtloop.cli.main([str(scene), str(paths[1]), "--out", str(tmp_path / "one"), "--seed", "11", "-q"]) == 0
    one = json.loads((tmp_path / "one" / "result.json").read_text(encoding="utf-8"))
    assert next(r for r in recs if r["id"] == "f1")["light"] == one["light"]
    assert next(r for r in recs if r["id"] == "f1")["x"] == one["fit_report"]["fitted"]
    capsys.readouterr()

    # a re-run skips all three; after f1's photo changes, only f1 runs again
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(out), "--no-images"]) == 0
    assert "3 already done" in capsys.readouterr().err
    assert len(records(out)) == 3
    paths[1].write_bytes(paths[2].read_bytes())
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(out)]) == 0
    recs = records(out)
    assert [r["id"] for r in recs[3:]] == ["f1"]
    assert recs[3]["x"] == single(scene, paths[2], 11).x
    assert (out / "f1" / "final.png").is_file() and (out / "f1" / "objective.png").is_file()


def test_batch_job_directory_holds_what_a_single_rtloop_fit_writes(photos, tmp_path, capsys):
    """DIR/<id>/ gets rtloop-fit's files: the same per-generation CSV and snapshots, byte for byte, as a
    single rtloop-fit with the same seed; --no-images leaves result.json alone."""
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths[:2]))
    out = tmp_path / "out"
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(out), "--snapshot-every", "3", "-q"]) == 0
    assert rtloop.cli.main([str(scene), str(paths[1]), "--out", str(tmp_path / "one"), "--seed", "11",
                            "--snapshot-every", "3", "-q"]) == 0
    one, job = tmp_path / "one", out / "f1"
    names = sorted(p.relative_to(one).as_posix() for p in one.rglob("*"))
    assert sorted(p.relative_to(job).as_posix() for p in job.rglob("*")) == sorted([*names, MARKER])
    shots = [n for n in names if n.startswith("snapshots/") and n.endswith(".bmp")]
    assert shots and "best_per_generation.csv" in names
    for name in ["best_per_generation.csv", "objective.png", "final.png", *shots]:
        assert (job / name).read_bytes() == (one / name).read_bytes(), name
    rows = (job / "best_per_generation.csv").read_text(encoding="utf-8").splitlines()
    assert rows[0].split(",")[:4] == ["stage", "generation", "evaluations", "fitness"] and len(rows) > 10
    capsys.readouterr()

    quick = tmp_path / "quick"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (quick / f".f1.rtloop-tmp-p{dead.pid}-x1").mkdir(parents=True)  # a killed run's staging
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(quick), "--no-images", "-q"]) == 0
    assert sorted(p.name for p in (quick / "f1").iterdir()) == [MARKER, "result.json"]
    assert sorted(p.name for p in quick.iterdir()) == [LOCK, "f0", "f1", "results.jsonl"]
    assert records(quick)[0]["x"] == next(r for r in records(out) if r["id"] == records(quick)[0]["id"])["x"]


def test_batch_cli_without_uncertainty_fits_the_same(photos, tmp_path, capsys):
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths[:1]))
    out = tmp_path / "out"
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(out), "--no-images", "--no-uncertainty"]) == 0
    (rec,) = records(out)
    assert rec["x"] == single(scene, paths[0], 10).x
    assert json.loads((out / "f0" / "result.json").read_text(encoding="utf-8"))["fit_report"]["uncertainty"] is None


def test_batch_cli_failed_job_exit_status(photos, tmp_path, capsys):
    scene, paths = photos
    jobs = jobs_of(scene, paths[:1]) + [{"id": "gone", "scene": str(scene), "photo": "missing.png"}]
    out = tmp_path / "out"
    code = batch_cli.main(["--batch", str(write_jobs(tmp_path / "jobs.jsonl", jobs)), "--out", str(out),
                           "--no-images"])
    assert code == 1
    assert "1 failed" in capsys.readouterr().err
    by_id = {r["id"]: r for r in records(out)}
    assert by_id["f0"]["status"] == "ok"
    assert by_id["gone"]["status"] == "error" and "missing.png" in by_id["gone"]["error"]


def test_batch_cli_bad_jobs_file(tmp_path, capsys):
    bad = tmp_path / "jobs.jsonl"
    bad.write_text('{"id": "a"}\n', encoding="utf-8")
    assert batch_cli.main(["--batch", str(bad), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"rtloop-fit: error: {bad}:1: missing 'scene'"]


def test_ray_flag_without_ray_says_how_to_install(photos, tmp_path, capsys, monkeypatch):
    scene, paths = photos
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths[:1]))
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(tmp_path / "o"), "--ray"]) == 1
    assert capsys.readouterr().err == ("rtloop-fit: error: --ray: Ray is not installed: pip install 'rtloop[ray]' "
                                       "(or pip install 'ray>=2.9')\n")
    with pytest.raises(rtloop.RtloopError, match=r"pip install 'rtloop\[ray\]'"):
        list(fit_many(jobs_of(scene, paths[:1]), "ray"))


def test_interrupted_batch_leaves_whole_lines_and_resumes(photos, tmp_path):
    scene, paths = photos
    jobs = [{"id": f"k{i}", "scene": str(scene), "photo": str(paths[i % 3]), "seed": i} for i in range(1000)]
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs)
    out = tmp_path / "out"
    # The child imports the rtloop this test imported (a checkout's python/ or an installed wheel).
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(rtloop.__file__).resolve().parents[1]),
                                                        os.environ.get("PYTHONPATH", "")])}
    # A shell may start background processes (CI, say) with SIGINT ignored, which the child inherits (the
    # batch then runs to its end): restore Python's handler, as a terminal's Ctrl-C finds it.
    launch = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
              "from rtloop.cli import main; sys.exit(main())")
    cmd = [sys.executable, "-c", launch, "--batch", str(jobs_file), "--out", str(out), "--no-images",
           "--workers", "2"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if (out / "results.jsonl").exists() and (out / "results.jsonl").stat().st_size > 2000:
            break
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)  # no chance to clean up: only the line-by-line appends protect the file
    proc.wait()
    proc.stderr.close()
    done = records(out)
    assert 0 < len(done) < 1000
    assert all(r["status"] == "ok" for r in done)
    # Ctrl-C: a clean stop with status 130, every finished result kept
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    n0 = len(done)
    while time.monotonic() < deadline and len(records(out)) < n0 + 5:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=30) == 130
    proc.stderr.close()
    after = records(out)
    assert len(after) > n0 and len({r["id"] for r in after}) == len(after)  # nothing run twice


def test_history_is_recorded_without_a_callback(photos):
    """The per-generation history comes from the core (no GIL per generation); a callback sees the same."""
    scene, paths = photos
    seen: list[tuple[str, int, float]] = []
    for kw in ({}, {"protocol": "paper", "generations": (4, 4), "population": 8}):
        seen.clear()
        quiet = single(scene, paths[0], 5, **kw)
        watched = single(scene, paths[0], 5, callback=lambda i: seen.append((i.stage, i.generation, i.fitness)),
                         **kw)
        assert quiet.x == watched.x
        for a, b in zip(quiet.stages, watched.stages, strict=True):
            assert [(g, f, o) for g, f, o, _ in a.history] == [(g, f, o) for g, f, o, _ in b.history]
            assert all((xa == xb).all() for (*_, xa), (*_, xb) in zip(a.history, b.history, strict=True))
        assert seen == [(s.name, g, f) for s in quiet.stages for g, f, _, _ in s.history]
