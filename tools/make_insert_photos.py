"""Mitsuba 3 photos for the insertion test: a make_photos.py case rendered again with one more
object, the object in rtloop's scene format beside it. Writes tests/fixtures/insert/CASE/."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import make_photos as mp

OUT = mp.REPO / "tests" / "fixtures" / "insert"
BOX = OUT / "direct-side-box" / "box.obj"


def box_obj(path: Path, half: float = 0.3, turn_deg: float = 30.0) -> Path:
    """Write a cube of side 2·half standing on y = 0, turned about y (12 triangles: flat faces, creases and
    a polygonal shadow)."""
    c, s = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))
    v = [(c * x - s * z, y, s * x + c * z) for x in (-half, half) for y in (0, 2 * half) for z in (-half, half)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v]
    lines += ["f " + " ".join(str(i + 1) for i in q) for q in quads]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("# a turned cube, tools/make_insert_photos.py\n" + "\n".join(lines) + "\n")
    return path


#: fixture folder -> (make_photos.py case, the object added in make_photos.py's form: a bsdf, not a material)
ADDED = {
    "direct-side": ("direct-side",
                    mp._sphere("ball2", [-1.0, 0.35, -1.1], 0.35, mp._diffuse([0.2, 0.35, 0.75]))),
    "direct-side-box": ("direct-side",
                        {"name": "box", "shape": "mesh", "file": "box.obj", "position": [-1.0, 0.0, -1.1],
                         "bsdf": mp._diffuse([0.75, 0.35, 0.2])}),
}
SPP = 1024


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args()
    box_obj(args.out / "direct-side-box" / "box.obj")
    for folder, (name, obj) in ADDED.items():
        case = next(c for c in mp.CASES if c.name == name)
        out = args.out / folder
        out.mkdir(parents=True, exist_ok=True)
        rendered = {**obj, "file": str(out / obj["file"])} if obj["shape"] == "mesh" else obj
        with_obj = dataclasses.replace(case, objects=[*case.objects, rendered], spp=SPP)
        linear = mp.render(mp.mitsuba_dict(with_obj, spp=SPP, seed=case.seed))
        (out / "with.png").write_bytes(mp.png_bytes(mp.encode8(linear)))
        added = {k: v for k, v in obj.items() if k != "bsdf"}
        added["material"] = {"albedo": obj["bsdf"]["albedo"], "specular": 0.0, "shininess": 0.0}
        (out / "objects.json").write_text(json.dumps({"objects": [added]}, indent=2) + "\n")
        meta = {"photo_without": f"tests/fixtures/photos/{name}/objective.png", "mitsuba": mp.MITSUBA_VERSION,
                "variant": mp.VARIANT, "integrator": case.integrator, "spp": SPP, "seed": case.seed,
                "filter": "box", "added_bsdf": obj["bsdf"]}
        (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
