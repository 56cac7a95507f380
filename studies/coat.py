#!/usr/bin/env python3
"""The coated lobe on the glossy Mitsuba photos: the default fit's light error, colour products and time (the fastest and
the median run), on this build and (``--baseline DIR``) another, on the glossy photos (tests/fixtures/photos/gloss-*), the
coat fixtures (tests/fixtures/coat, from a matte ball in the user's scene) and matte photos.

Products are exposure x intensity x colour x albedo per object, the worst relative error over objects and
channels (relative to the object's largest true product). A glossy ball's truth is Mitsuba's roughplastic:
``diffuse`` compares with its ``diffuse_reflectance`` (what a coated fit's albedo means), ``effective``
with the Lambertian albedo that renders its base the same on average (scene.json's, what a Blinn-Phong
fit's albedo approximates). Each fit runs in a fresh process (so a coat's tables are built as a user's
first fit builds them), ``--runs`` times, builds alternating (the machine is shared: compare the fastest runs).

    PYTHONPATH=python python studies/coat.py --runs 3 --baseline /tmp/base/python --out studies/results/coat.md
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PHOTOS = REPO / "tests" / "fixtures" / "photos"
COAT = REPO / "tests" / "fixtures" / "coat"
CASES = [("photos", "gloss-a010"), ("photos", "gloss-a025"), ("photos", "gloss-back"),
         ("coat", "coat-a010-red"), ("coat", "coat-a030-blue"), ("coat", "coat-a010-green-half"),
         ("photos", "direct-side"), ("photos", "direct-two-balls"), ("photos", "env-overhead")]

CHILD = r'''
import json, sys, time, copy
import numpy as np
sys.path.insert(0, sys.argv[1])
sys.path.insert(1, sys.argv[5])
import rtloop
from scenes import matte_start
from rtloop.fit.products import products_of
from pathlib import Path
kind, name = sys.argv[2], sys.argv[3]
folder = Path(sys.argv[4]) / name
truth = json.loads((folder / "scene.json").read_text())
if kind == "coat":
    scene = rtloop.load_scene(matte_start(truth))
    diffuse = {**truth, "exposure": 1.0}
    effective = None
else:
    scene = rtloop.load_scene(folder / "scene_input.json")
    effective = truth
    diffuse = copy.deepcopy(truth)
    glossy = json.loads((folder / "meta.json").read_text()).get("extra_truth", {}).get("glossy_objects", {})
    for o in diffuse["objects"]:
        if o["name"] in glossy:
            o["material"]["albedo"] = glossy[o["name"]]["bsdf"]["diffuse_reflectance"]
photo = rtloop.load_image(folder / "objective.png", scene)
t = time.perf_counter()
r = rtloop.fit(scene, photo, uncertainty=False)
dt = time.perf_counter() - t
f = r.scene.to_dict()
def worst(t):
    if t is None:
        return None
    pf, pt = products_of(f), products_of(t)
    return max(float(np.max(np.abs(pf[k] - pt[k])) / np.max(pt[k])) for k in pt)
ev = r.model.get("evidence", {}).get("specular", {})
mat = f["objects"][0]["material"]
print(json.dumps({"light_mm": 1000 * float(np.linalg.norm(np.subtract(f["light"]["position"], truth["light"]["position"]))),
                  "diffuse": worst(diffuse), "effective": worst(effective), "seconds": dt,
                  "terms": r.model["terms"], "lobe": ev.get("lobe", "blinn-phong" if "specular" in r.model["terms"] else "-"),
                  "roughness": mat.get("coat", {}).get("roughness")}))
'''


def run(python_dir: str, kind: str, name: str) -> dict:
    folder = PHOTOS if kind == "photos" else COAT
    out = subprocess.run([sys.executable, "-c", CHILD, python_dir, kind, name, str(folder), str(REPO / "tests")], capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--baseline", metavar="DIR", help="python/ folder of a baseline build")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--only", default="", help="comma-separated photo names (default: all)")
    a = ap.parse_args()
    builds = {"this": str(REPO / "python")}
    if a.baseline:
        builds["baseline"] = a.baseline
    rows = []
    for kind, name in [c for c in CASES if not a.only or c[1] in a.only.split(",")]:
        res: dict[str, list[dict]] = {b: [] for b in builds}
        for _ in range(a.runs):
            for b, path in builds.items():
                res[b].append(run(path, kind, name))
        for b in builds:
            first = res[b][0]
            secs = statistics.median(x["seconds"] for x in res[b])
            fastest = min(x["seconds"] for x in res[b])
            pct = lambda v: "-" if v is None else f"{100 * v:.2f}"  # noqa: E731
            rough = "-" if first["roughness"] is None else f"{first['roughness']:.3f}"
            rows.append(f"| {name} | {b} | {' + '.join(first['terms'])} | {first['lobe']} | {rough} | "
                        f"{first['light_mm']:.1f} | {pct(first['diffuse'])} | {pct(first['effective'])} | {1000 * fastest:.0f} / {1000 * secs:.0f} |")
            print(rows[-1], flush=True)
    head = ["| photo | build | terms | lobe | roughness | light (mm) | products vs diffuse (%) | "
            "products vs effective albedo (%) | time (ms, fastest / median) |", "|---|---|---|---|---|---|---|---|---|"]
    if a.out:
        cmd = "PYTHONPATH=python python studies/coat.py " + " ".join(sys.argv[1:])
        a.out.write_text(f"`{cmd}`\n\n" + "\n".join(head + rows) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
