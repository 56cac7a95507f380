"""Re-running a batch: failed jobs are not passed over as done, a warm-started chain resumes as it would
have gone on, a second batch on the same folder stops, job ids never replace what the batch did not write,
and bad command lines and a results file that cannot be appended to are one line each."""

from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path

import pytest

from rtloop import cli as fit_cli
from rtloop.batch import fit_many
from rtloop.batch.folder import LOCK
from rtloop.cli import batch as batch_cli
from test_batch import jobs_of, photos, records, write_jobs  # noqa: F401 (photos: a fixture)


def run(capsys, *args: object) -> tuple[int, list[str]]:
    code = batch_cli.main([str(a) for a in args])
    return code, capsys.readouterr().err.strip().splitlines()


def test_a_rerun_counts_the_jobs_that_failed_before(photos, tmp_path, capsys):
    scene, paths = photos
    jobs = jobs_of(scene, paths[:2]) + [{"id": "gone", "scene": str(scene), "photo": "missing.png"}]
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs)
    out = tmp_path / "out"
    assert run(capsys, "--batch", jobs_file, "--out", out, "--no-images")[0] == 1
    code, err = run(capsys, "--batch", jobs_file, "--out", out, "--no-images")
    assert code == 1
    assert "2 already done, 1 failed before (run with --retry-failed to retry)" in err[-1]
    code, err = run(capsys, "--batch", jobs_file, "--out", out, "--no-images", "--retry-failed")
    assert code == 1 and "1/1 done, 1 failed, 2 already done" in err[-1]
    assert [r["id"] for r in records(out)].count("gone") == 2


def test_a_resumed_warm_start_goes_on_as_an_uninterrupted_run(photos, tmp_path, capsys):
    scene, paths = photos
    jobs = [{"id": f"t{i}", "scene": str(scene), "photo": str(paths[i % 3]), "seed": 1} for i in range(6)]
    whole = tmp_path / "whole"
    assert run(capsys, "--batch", write_jobs(tmp_path / "all.jsonl", jobs), "--out", whole, "--no-images",
               "--warm-start")[0] == 0
    resumed = tmp_path / "resumed"
    # interrupted after three frames: results.jsonl holds them; the re-run goes on from the third's light
    assert run(capsys, "--batch", write_jobs(tmp_path / "first.jsonl", jobs[:3]), "--out", resumed, "--no-images",
               "--warm-start")[0] == 0
    code, err = run(capsys, "--batch", tmp_path / "all.jsonl", "--out", resumed, "--no-images", "--warm-start")
    assert code == 0 and "3/3 done, 0 failed, 3 already done" in err[-1]
    assert records(resumed) == [{**r, "seconds": s["seconds"]} for r, s in zip(records(whole), records(resumed))]
    # a changed warm-start fraction is another chain: every frame after the first runs again
    skip, fitted = {r["id"]: r["hash"] for r in records(whole)}, {r["id"]: r["x"] for r in records(whole)}
    assert list(fit_many(jobs, warm_start=True, skip=skip, fitted=fitted)) == []
    again = fit_many(jobs, warm_start=True, warm_fraction=0.2, skip=skip, fitted=fitted)
    assert [r.id for r in again] == [f"t{i}" for i in range(1, 6)]


def test_a_second_batch_on_the_same_folder_stops(photos, tmp_path, capsys):
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths[:1]))
    out = tmp_path / "out"
    out.mkdir()
    fd = os.open(out / LOCK, os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # as a running batch holds it (another open file: flock excludes it)
        code, err = run(capsys, "--batch", jobs_file, "--out", out, "--no-images")
    finally:
        os.close(fd)
    assert code == 1 and err == [f"rtloop-fit: error: {out}: another batch is running on this output directory "
                                 f"(it holds {LOCK}); wait for it to end"]
    assert not (out / "results.jsonl").exists() and not (out / "f0").exists()
    assert run(capsys, "--batch", jobs_file, "--out", out, "--no-images")[0] == 0  # released: it runs


@pytest.mark.parametrize("jid", ["notes", "scene.json", "f0"])
def test_a_job_id_never_replaces_what_the_batch_did_not_write(photos, tmp_path, capsys, jid):
    scene, paths = photos
    out = tmp_path / "out"
    (out / "notes").mkdir(parents=True)
    (out / "notes" / "todo.txt").write_text("keep me", encoding="utf-8")
    (out / "scene.json").write_bytes(scene.read_bytes())
    (out / "f0").symlink_to(out / "notes")
    before = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", [{"id": jid, "scene": str(scene), "photo": str(paths[0])}])
    code, err = run(capsys, "--batch", jobs_file, "--out", out)
    assert code == 1 and len(err) == 1 and "not written by rtloop-fit --batch" in err[0] and jid in err[0]
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.name != LOCK) == before
    assert (out / "notes" / "todo.txt").read_text(encoding="utf-8") == "keep me"
    # fit_many writing into the folder refuses the job the same way, and the batch goes on
    (r,) = fit_many([{"id": jid, "scene": str(scene), "photo": str(paths[0])}], out=out, images=False)
    assert r.status == "error" and "not written by rtloop-fit --batch" in r.error
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.name != LOCK) == before


def test_the_batchs_own_job_folders_are_replaced(photos, tmp_path, capsys):
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths[:1]))
    out = tmp_path / "out"
    assert run(capsys, "--batch", jobs_file, "--out", out, "--no-images")[0] == 0
    paths[0].write_bytes(paths[1].read_bytes())  # the job changes: its folder is the batch's, replaced
    assert run(capsys, "--batch", jobs_file, "--out", out, "--no-images")[0] == 0
    assert [r["id"] for r in records(out)] == ["f0", "f0"]


@pytest.mark.parametrize("flag", [["--threads", "0"], ["--threads", "100000"], ["--final-spp", "0"],
                                  ["--final-spp", "1000000000"], ["--final-scale", "1000000"],
                                  ["--population", "3"], ["--population", "1000000000"], ["--norm", "l7"],
                                  ["--workers", "0"]])
def test_batch_flags_out_of_range_are_refused_before_any_fit(photos, tmp_path, capsys, flag):
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths[:1]))
    code, err = run(capsys, "--batch", jobs_file, "--out", tmp_path / "out", *flag)
    assert code == 2 and len(err) == 1 and err[0].startswith("rtloop-fit: error: argument " + flag[0])
    assert not (tmp_path / "out").exists()


def test_batch_help(capsys):
    assert fit_cli.main(["--batch", "--help"]) == 0
    printed = capsys.readouterr().out
    assert "--batch JOBS" in printed and "grey_card" in printed and "--footprint" in printed


def test_a_results_file_that_cannot_be_appended_to_is_one_line(photos, tmp_path, capsys, monkeypatch):
    scene, paths = photos
    jobs_file = write_jobs(tmp_path / "jobs.jsonl", jobs_of(scene, paths[:2]))
    fsync = os.fsync

    def full(fd: int) -> None:
        if os.readlink(f"/proc/self/fd/{fd}").endswith("results.jsonl"):
            raise OSError(28, "No space left on device")
        fsync(fd)

    monkeypatch.setattr(os, "fsync", full)
    code, err = run(capsys, "--batch", jobs_file, "--out", tmp_path / "out", "--no-images", "--workers", "1")
    assert code == 1
    assert err[-1] == (f"rtloop-fit: error: {tmp_path / 'out' / 'results.jsonl'}: cannot append a result "
                       "(No space left on device)")
