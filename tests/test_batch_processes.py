"""The process engine (``fit_many(engine="processes")``, ``rtloop-fit --batch --processes``): the same results as
single fits bit for bit, a failing job and a worker that dies each one line while the rest run, the files as
the thread engine writes them, and the options it does not take refused in one line."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rtloop
from rtloop.batch import ENGINES, fit_many, jobs_from, to_run
from rtloop.batch.processes import run_processes
from rtloop.batch.worker import run_plain
from rtloop.cli import batch as batch_cli
from test_batch import jobs_of, photos, records, single, write_jobs  # noqa: F401 (photos: a fixture)


def _dies_on_kill(job: dict, digest: str, threads: int, kwargs: dict) -> rtloop.JobResult:
    """A worker's task that kills its own process for the job with id "kill" (as the kernel's OOM killer
    would), and fits every other job."""
    if job["id"] == "kill":
        os.kill(os.getpid(), signal.SIGKILL)
    return run_plain(job, digest, threads, kwargs)


def test_processes_equal_single_fits_bit_for_bit(photos):
    scene, paths = photos
    results = {r.id: r for r in fit_many(jobs_of(scene, paths), "processes", workers=2)}
    assert sorted(results) == ["f0", "f1", "f2"]
    for i, p in enumerate(paths):
        r, ref = results[f"f{i}"], single(scene, p, 10 + i)
        assert r.status == "ok" and r.error is None and r.fit is None  # a plain result, as on Ray
        assert r.x == ref.x and r.products == ref.products and r.fitness == ref.fitness
        assert r.light == rtloop.scene_to_dict(ref.scene)["light"]


def test_a_failing_job_is_one_line_and_the_batch_goes_on(photos):
    scene, paths = photos
    jobs = jobs_of(scene, paths[:2]) + [{"id": "gone", "scene": str(scene), "photo": "missing.png"}]
    by_id = {r.id: r for r in fit_many(jobs, "processes", workers=2)}
    assert by_id["f0"].ok and by_id["f1"].ok
    assert by_id["gone"].status == "error" and "missing.png" in by_id["gone"].error
    assert "\n" not in by_id["gone"].error


def test_a_worker_that_dies_fails_its_job_in_one_line_and_the_others_run(photos):
    scene, paths = photos
    jobs = jobs_of(scene, paths) + [{"id": "kill", "scene": str(scene), "photo": str(paths[0]), "seed": 1}]
    todo, _ = to_run(jobs_from(jobs), {}, None)
    out = list(run_processes(todo, workers=1, threads=1, task=_dies_on_kill, options={}, out=None, images=False,
                             final_scale=1, final_spp=1, snapshot_every=0))
    by_id = {r.id: r for r in out}
    assert sorted(by_id) == ["f0", "f1", "f2", "kill"]  # every job answered once
    killed = by_id["kill"]
    assert killed.status == "error" and killed.error.startswith("processes: ") and "\n" not in killed.error
    # one worker: the jobs queued behind the killed one ran on a new pool (those in flight with it may fail too)
    assert sum(r.ok for r in out) >= 1 and all(r.ok or r.error.startswith("processes: ") for r in out)
    assert by_id[max(by_id.keys() - {"kill"})].ok


def test_the_batch_writes_what_the_thread_engine_writes(photos, tmp_path, capsys):
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths))
    for name, flags in (("threads", []), ("processes", ["--processes"])):
        assert batch_cli.main(["--batch", str(jobs_file), "--out", str(tmp_path / name), "--snapshot-every", "2",
                               *flags]) == 0
    capsys.readouterr()
    plain = {r["id"]: {k: v for k, v in r.items() if k != "seconds"} for r in records(tmp_path / "threads")}
    procs = {r["id"]: {k: v for k, v in r.items() if k != "seconds"} for r in records(tmp_path / "processes")}
    assert plain == procs
    for job in plain:
        a, b = tmp_path / "threads" / job, tmp_path / "processes" / job
        assert sorted(p.relative_to(a) for p in a.rglob("*")) == sorted(p.relative_to(b) for p in b.rglob("*"))
        for png in ("final.png", "objective.png"):
            assert (a / png).read_bytes() == (b / png).read_bytes()
        fitted = [json.loads((d / "result.json").read_text())["fit_report"]["fitted"] for d in (a, b)]
        assert fitted[0] == fitted[1]


@pytest.mark.parametrize("flag,says", [("--ray", "it runs the jobs as Ray tasks"),
                                       ("--warm-start", "it runs the jobs in order, in one process")])
def test_what_the_process_engine_does_not_take_is_refused_in_one_line(photos, tmp_path, capsys, flag, says):
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths[:1]))
    assert batch_cli.main(["--batch", str(jobs_file), "--out", str(tmp_path / "o"), "--processes", flag]) == 2
    assert capsys.readouterr().err == f"rtloop-fit: error: --processes: not with {flag} ({says})\n"
    assert not (tmp_path / "o").exists()
    with pytest.raises(rtloop.RtloopError, match=r"^fit_many: warm_start runs the jobs in order"):
        list(fit_many(jobs_of(scene, paths[:1]), "processes", warm_start=True))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(engine=st.one_of(st.text(max_size=12), st.integers(), st.none(), st.sampled_from(["Local", "process", "RAY"])))
def test_an_engine_that_is_not_one_is_refused_in_one_line(photos, engine):
    scene, paths = photos
    if engine in ENGINES:
        return
    with pytest.raises(rtloop.RtloopError, match=r"^fit_many: engine must be one of 'local', 'processes', 'ray'") as e:
        fit_many(jobs_of(scene, paths[:1]), engine)
    assert "\n" not in str(e.value)
