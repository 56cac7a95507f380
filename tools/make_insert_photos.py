"""Mitsuba 3 photos for the insertion test (issue 17): a make_photos.py case rendered again with one more
object, the object in rtloop's scene format beside it. Writes tests/fixtures/insert/CASE/."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import make_photos as mp

OUT = mp.REPO / "tests" / "fixtures" / "insert"
#: case -> the object added (make_photos.py's form: a bsdf, not a material)
ADDED = {
    "direct-side": mp._sphere("ball2", [-1.0, 0.35, -1.1], 0.35, mp._diffuse([0.2, 0.35, 0.75])),
}
SPP = 1024


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args()
    for name, obj in ADDED.items():
        case = next(c for c in mp.CASES if c.name == name)
        with_obj = dataclasses.replace(case, objects=[*case.objects, obj], spp=SPP)
        linear = mp.render(mp.mitsuba_dict(with_obj, spp=SPP, seed=case.seed))
        out = args.out / name
        out.mkdir(parents=True, exist_ok=True)
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
