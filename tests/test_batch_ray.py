"""The Ray engine on a local Ray (``ray.init(num_cpus=2)``): equality with single fits, a failing job,
a worker killed mid-batch, resume through the command line, a real run killed and interrupted in a
subprocess and resumed. Skipped when Ray is not installed."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ray = pytest.importorskip("ray", reason="Ray not installed (pip install '.[ray]')")

import rtloop
import test_batch as tb
from rtloop.batch import fit_many, jobs
from rtloop.batch.on_ray import run_ray
from rtloop.batch.folder import LOCK
from rtloop.cli import batch as batch_cli

photos = tb.photos  # the fixture: a 32x24 scene and three photos of it
jobs_of, records, single, write_jobs = tb.jobs_of, tb.records, tb.single, tb.write_jobs



@pytest.fixture(scope="module", autouse=True)
def local_ray():
    # the workers import the rtloop this test imported (a checkout's python/ or an installed wheel)
    saved = os.environ.get("PYTHONPATH")
    here = str(Path(rtloop.__file__).resolve().parents[1])
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH")) if p)
    ray.init(num_cpus=2, logging_level="warning", log_to_driver=False, include_dashboard=False)
    yield
    ray.shutdown()
    if saved is None:
        del os.environ["PYTHONPATH"]
    else:
        os.environ["PYTHONPATH"] = saved


def test_ray_equals_single_fits_and_records_a_failure(photos, tmp_path):
    scene, paths = photos
    batch = jobs_of(scene, paths) + [{"id": "gone", "scene": str(scene), "photo": str(tmp_path / "x.png")}]
    results = {r.id: r for r in fit_many(batch, "ray")}
    assert sorted(results) == ["f0", "f1", "f2", "gone"]
    for i, p in enumerate(paths):
        r = results[f"f{i}"]
        ref = single(scene, p, 10 + i, threads=1)
        assert r.status == "ok" and r.x == ref.x and r.products == ref.products
        assert r.fit is None  # only plain data comes back from a task
    assert results["gone"].status == "error" and "x.png" in results["gone"].error


def test_killed_worker_is_retried_and_the_batch_completes(photos, tmp_path):
    scene, paths = photos
    marker = tmp_path / "killed-once"

    def dies_once(job, digest, threads, kwargs):  # pickled by value into the worker
        from rtloop.batch.on_ray import _task

        if job["id"] == "f1" and not os.path.exists(marker):
            open(marker, "w").close()
            os._exit(1)  # the worker process dies mid-task, as on a lost node
        return _task(job, digest, threads, kwargs)

    todo = [(j, jobs.job_hash(j)) for j in jobs.jobs_from(jobs_of(scene, paths))]
    results = {r.id: r for r in run_ray(todo, address=None, threads=1, max_retries=2, task=dies_once,
                                        options={}, out=None, images=False, final_scale=1, final_spp=1)}
    assert marker.exists()
    assert sorted(results) == ["f0", "f1", "f2"] and all(r.ok for r in results.values())
    assert results["f1"].x == single(scene, paths[1], 11).x

    # with no retries left, the job is recorded as failed and the others still finish
    marker.unlink()
    results = {r.id: r for r in run_ray(todo, address=None, threads=1, max_retries=0, task=dies_once,
                                        options={}, out=None, images=False, final_scale=1, final_spp=1)}
    assert results["f1"].status == "error" and results["f1"].error.startswith("ray: ")
    assert results["f0"].ok and results["f2"].ok


def test_ray_cli_resumes(photos, tmp_path, capsys):
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths))
    out = tmp_path / "out"
    # a previous run finished f0 only
    (r0,) = list(fit_many(jobs_of(scene, paths[:1])))
    out.mkdir()
    (out / "results.jsonl").write_text(json.dumps(r0.record()) + "\n", encoding="utf-8")
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(out), "--ray", "--no-images"]) == 0
    assert "2/2 done, 0 failed, 1 already done" in capsys.readouterr().err
    recs = records(out)
    assert [r["id"] for r in recs[:1]] == ["f0"] and sorted(r["id"] for r in recs[1:]) == ["f1", "f2"]
    for r in recs[1:]:
        assert json.loads((out / r["id"] / "result.json").read_text(encoding="utf-8"))["light"] == r["light"]


def _wait_for_lines(path: Path, n: int, proc: subprocess.Popen) -> None:
    """Until ``path`` holds ``n`` lines, or the process has ended (a safety limit only: the test waits on
    the file, not on a clock)."""
    limit = time.monotonic() + 300
    while time.monotonic() < limit and proc.poll() is None:
        if path.exists() and path.read_bytes().count(b"\n") >= n:
            return
        time.sleep(0.02)


def test_a_ray_batch_killed_then_interrupted_resumes_each_job_exactly_once(photos, tmp_path):
    """``rtloop-fit --batch --ray ADDRESS`` in a subprocess on this test's local Ray: SIGKILL once some
    lines are in results.jsonl, then a re-run stopped by Ctrl-C (exit 130), then a re-run to the end.
    Every job is in results.jsonl exactly once, equal to a single fit with its seed, its
    DIR/<id>/result.json matches its line, and no staging directory of the killed run is left."""
    scene, paths = photos
    n = 240
    batch = [{"id": f"r{i}", "scene": str(scene), "photo": str(paths[i % 3]), "seed": i % 2} for i in range(n)]
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", batch)
    out = tmp_path / "out"
    lines = out / "results.jsonl"
    address = ray.get_runtime_context().gcs_address
    launch = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
              "from rtloop.cli import main; sys.exit(main())")  # Ctrl-C as a terminal delivers it
    cmd = [sys.executable, "-c", launch, "--batch", str(jobs_file), "--out", str(out), "--ray", address,
           "--no-images", "-q"]

    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _wait_for_lines(lines, 5, proc)
    proc.send_signal(signal.SIGKILL)  # the driver dies without a word: its tasks in flight are lost
    proc.wait()
    proc.stderr.close()
    killed = records(out)
    assert 5 <= len(killed) < n, "the batch ended before it could be killed"

    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _wait_for_lines(lines, len(killed) + 5, proc)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=120) == 130, proc.stderr.read().decode()
    proc.stderr.close()
    interrupted = records(out)
    assert len(killed) < len(interrupted) < n

    done = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    recs = records(out)
    ids = [r["id"] for r in recs]
    assert sorted(ids) == sorted(j["id"] for j in batch) and len(set(ids)) == n  # each once
    assert recs[: len(interrupted)] == interrupted  # earlier lines untouched
    assert not [p.name for p in out.iterdir() if p.name.startswith(".") and p.name != LOCK]  # staging tidied
    want = {(k, s): single(scene, paths[k], s) for k in range(3) for s in range(2)}
    for r in recs:
        i = int(r["id"][1:])
        assert r["status"] == "ok" and r["x"] == want[(i % 3, i % 2)].x, r["id"]
        assert json.loads((out / r["id"] / "result.json").read_text(encoding="utf-8"))["light"] == r["light"]
