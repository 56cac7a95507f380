"""The block bootstrap can be watched and stopped: the fit's callback runs after every generation of every
refit (stage "bootstrap R/N"), rtloop-fit shows the refits as progress and a Ctrl-C during them ends the run
within the generation it arrives in (exit 130, nothing written)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import rtloop
from conftest import example_scene
from rtloop.cli.outputs import GenerationLog
from rtloop.fit.result import GenerationInfo
from rtloop.uncertainty.bootstrap import REPLICATES, replicate_of


def scene_dict() -> dict:
    return example_scene(32, 24)


@pytest.fixture(scope="module")
def photo():
    truth = scene_dict()
    truth["light"].update(position=[2.0, 4.0, -1.5], intensity=40.0)
    truth["objects"][0]["material"]["albedo"] = [0.8, 0.7, 0.1]
    return rtloop.render(rtloop.load_scene(truth))


class Stop(Exception):
    pass


def test_callback_sees_every_refit_and_an_exception_ends_the_bootstrap_in_its_refit(photo) -> None:
    seen: list[tuple[str, int]] = []

    def watch(info: GenerationInfo) -> None:
        seen.append((info.stage, info.generation))
        if replicate_of(info.stage) == (3, REPLICATES) and info.generation == 1:
            raise Stop()

    with pytest.raises(Stop):
        rtloop.fit(scene_dict(), photo, population=8, generations=4, uncertainty="bootstrap", callback=watch)
    refits = [replicate_of(s) for s, _ in seen if replicate_of(s) is not None]
    assert [r for r, _ in dict.fromkeys(refits)] == [1, 2, 3]  # in order; none after the one that raised
    assert seen[-1] == (f"bootstrap 3/{REPLICATES}", 1)  # the raising call was the last: no generation after it
    # every refit's generations, from 0
    assert [g for s, g in seen if s == f"bootstrap 1/{REPLICATES}"][:2] == [0, 1]


def test_returning_false_stops_the_bootstrap_with_a_warning(photo) -> None:
    refits: list[int] = []

    def watch(info: GenerationInfo) -> bool:
        r = replicate_of(info.stage)
        if r is not None:
            refits.append(r[0])
            return r[0] < 2
        return True

    result = rtloop.fit(scene_dict(), photo, population=8, generations=4, uncertainty="bootstrap", callback=watch)
    boot = result.uncertainty["bootstrap"]
    assert boot["sigma"] == {} and "stopped the bootstrap in refit 2 of" in boot["warnings"][0]
    assert max(refits) == 2
    assert result.uncertainty["robust"]["sigma"]  # the sandwich's bars are still there


def test_replicate_of() -> None:
    assert replicate_of("bootstrap 4/30") == (4, 30)
    assert replicate_of("light+colour") is None and replicate_of("bootstrap") is None
    assert replicate_of("bootstrap x/30") is None


def test_generation_log_leaves_out_the_refits(tmp_path: Path) -> None:
    scene = rtloop.load_scene(scene_dict())
    with GenerationLog(tmp_path, scene, 0) as log:
        n = len(scene.param_names())
        assert log(GenerationInfo("bootstrap 1/30", 0, 1.0, [1.0], [0.5] * n, 8)) is None
        assert log(GenerationInfo("light+colour", 0, 1.0, [1.0], [0.5] * n, 8)) is not None
    rows = (tmp_path / "best_per_generation.csv").read_text(encoding="utf-8").splitlines()
    assert len(rows) == 2 and rows[1].startswith("light+colour")


# A real SIGINT from inside the run, delivered as the third refit is set up: the main thread takes it and
# sets the stop flag (the launcher waits for that: no race), then every generation and refit that still runs
# is printed. The bound: no generation of the refit runs after the flag is set, and no later refit starts.
LAUNCH = r"""
import os, signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)
import rtloop.cli.fit as F
import rtloop.uncertainty.bootstrap as B
runs, built, after = [], [], []
init = F._Run.__init__
def run_init(self, *a, **k):
    init(self, *a, **k)
    runs.append(self)
F._Run.__init__ = run_init
class Watched(B.Stages):
    def __init__(self, *a, callback=None, **k):
        built.append(1)
        if after:
            print(f"LATER REFIT {len(built)}", file=sys.stderr, flush=True)
        def cb(info):
            if after:
                print(f"LATER GENERATION {info.stage} {info.generation}", file=sys.stderr, flush=True)
            return None if callback is None else callback(info)
        super().__init__(*a, callback=cb, **k)
        if len(built) == 3:
            os.kill(os.getpid(), signal.SIGINT)
            while not runs[0].stop.is_set():
                time.sleep(0.001)
            after.append(1)
            print("SIGNALLED", file=sys.stderr, flush=True)
B.Stages = Watched
sys.exit(F.main())
"""


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_ctrl_c_during_the_bootstrap_stops_within_a_generation(photo, tmp_path: Path) -> None:
    scene_path = tmp_path / "scene.json"
    scene_path.write_text(json.dumps(scene_dict()), encoding="utf-8")
    image_path = tmp_path / "photo.png"
    rtloop.save_image(image_path, photo)
    out = tmp_path / "out"
    cmd = [sys.executable, "-c", LAUNCH, str(scene_path), str(image_path), "--out", str(out), "--population", "8",
           "--generations", "4", "--uncertainty", "bootstrap", "--snapshot-every", "0"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(rtloop.__file__).parents[1]),
                                                        os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)  # a hang guard only
    err = proc.stderr
    assert proc.returncode == 130, err
    assert "SIGNALLED" in err
    later = err.split("SIGNALLED", 1)[1]
    assert "LATER REFIT" not in later  # no refit starts after Ctrl-C
    # at most the one generation whose callback takes the stop (it raises before showing or running more)
    assert later.count("LATER GENERATION") <= 1
    assert f"'bootstrap': {REPLICATES} closed-form refits" in err  # the progress: the stage and each refit
    assert f"bootstrap  refit 1/{REPLICATES}" in err and f"bootstrap  refit 2/{REPLICATES}" in err
    assert err.strip().splitlines()[-1] == "rtloop-fit: interrupted"
    assert "Traceback" not in err and proc.stdout == ""
    assert not out.exists() and not [p for p in tmp_path.iterdir() if ".rtloop-" in p.name]


def test_the_report_leaves_the_refits_out_of_the_search(photo, tmp_path: Path) -> None:
    """rows.append as the callback collects the refits' generations too; the report's search is the fit's."""
    rows: list[GenerationInfo] = []
    result = rtloop.fit(scene_dict(), photo, population=8, generations=4, uncertainty="bootstrap",
                        callback=rows.append)
    assert any(replicate_of(r.stage) for r in rows)
    rtloop.report(result, tmp_path / "report.html", generations=rows)
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert "bootstrap 1/" not in page and f"block bootstrap: {REPLICATES} refits" in page
