"""Interleaved A/B CPU time of the default fit between two builds' Python packages
(benches/results/silhouette.md).

Usage (from anywhere; each build's ``python`` folder with its extension built)::

    TREES=A=/path/to/a/python,B=/path/to/b/python python benches/fit_ab.py ROUNDS CASE[,CASE..] FITS

Per round, one process per build (alternating) fits each photo of tests/fixtures/photos once to warm up, then
FITS times (``rtloop.fit(scene, photo, uncertainty=False, threads=1)``); printed per photo: the least CPU time
per fit over the rounds for each build, their ratio, the medians, and whether the two fitted lights agree.
"""

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

PHOTOS = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "photos"
CHILD = r"""
import json, sys, time, warnings
from pathlib import Path
import rtloop
warnings.simplefilter("ignore")
out = {}
for name in sys.argv[2].split(","):
    d = Path(sys.argv[1]) / name
    scene = rtloop.load_scene(d / "scene_input.json")
    photo = rtloop.load_image(d / "objective.png", scene)
    r = rtloop.fit(scene, photo, uncertainty=False, threads=1)
    ts = []
    for _ in range(int(sys.argv[3])):
        t = time.process_time()
        rtloop.fit(scene, photo, uncertainty=False, threads=1)
        ts.append(time.process_time() - t)
    out[name] = (min(ts), r.scene.to_dict()["light"]["position"])
print(json.dumps(out))
"""


def main() -> None:
    rounds, cases, fits = int(sys.argv[1]), sys.argv[2].split(","), sys.argv[3]
    trees = dict(kv.split("=", 1) for kv in os.environ["TREES"].split(","))
    times = {k: {c: [] for c in cases} for k in trees}
    lights = {}
    for _ in range(rounds):
        for k, path in trees.items():
            env = {"PYTHONPATH": path, "PATH": os.environ.get("PATH", "/usr/bin:/bin")}
            run = subprocess.run([sys.executable, "-c", CHILD, str(PHOTOS), ",".join(cases), fits],
                                 capture_output=True, text=True, env=env, cwd="/tmp", check=True)
            for c, (t, light) in json.loads(run.stdout.strip().splitlines()[-1]).items():
                times[k][c].append(t)
                lights[(k, c)] = light
    a, b = list(trees)[:2]
    for c in cases:
        ta, tb = min(times[a][c]), min(times[b][c])
        print(f"{c}: {a} {1e3 * ta:.2f} ms  {b} {1e3 * tb:.2f} ms  {b}/{a} {tb / ta:.3f}  medians "
              f"{1e3 * statistics.median(times[a][c]):.2f}/{1e3 * statistics.median(times[b][c]):.2f}  "
              f"same light={lights[(a, c)] == lights[(b, c)]}")


if __name__ == "__main__":
    main()
