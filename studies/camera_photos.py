"""Accuracy and time of the default fit on the camera-pipeline photos in ``tests/fixtures/camera``.

Every photo folder (made by ``tools/make_camera_photos.py``: Mitsuba renders through vignetting, a
non-sRGB tone curve with JPEG 90, or a Bayer mosaic with high-ISO noise, demosaic and JPEG 85) is fitted
with ``rtloop.fit`` on its ``scene_input.json`` and ``objective.png`` loaded with ``rtloop.load_image``
(extra ``fit()`` options from ``--option KEY=VALUE``), and scored against ``scene.json`` with
``studies/photos.py``'s :func:`score` (``../shared/tools/score_result.py``'s measures).

Printed: a markdown table per photo: light error (cm), worst product error (%), the camera terms the fit
chose, the goodness verdict, the light position's 1-sigma (cm) and the fit time (s).

Usage (from the repository root, with the extension built)::

    python studies/camera_photos.py
    python studies/camera_photos.py --option camera=off --cases blue-ball-tone
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import rtloop

sys.path.insert(0, str(Path(__file__).resolve().parent))
from photos import score  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
FIXTURES = REPO / "tests" / "fixtures" / "camera"


def scaled_products_error(res: dict, truth: dict) -> float:
    """The worst relative product error once every fitted product is scaled by the one factor that fits
    them best (least squares in log): what a photo with an unknown tone curve determines, the colours
    relative to each other."""
    def products(scene: dict) -> np.ndarray:
        light = float(scene["light"]["intensity"]) * np.array(scene["light"].get("color", [1, 1, 1]), float)
        return np.array([light * np.array(o["material"]["albedo"], float) for o in scene["objects"]])

    fitted, true = products(res), products(truth)
    k = np.exp(np.mean(np.log(np.maximum(true, 1e-9) / np.maximum(fitted, 1e-9))))
    return float(max(np.max(np.abs(k * f - t)) / max(float(np.max(t)), 1e-12) for f, t in zip(fitted, true)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="*")
    ap.add_argument("--option", action="append", default=[], help="KEY=VALUE passed to rtloop.fit")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    options = dict(o.split("=", 1) for o in args.option)
    rows = []
    command = " ".join(["python studies/camera_photos.py", *(argv if argv is not None else sys.argv[1:])])
    print(f"# Camera-pipeline photos (`{command}`)\n")
    print("| photo | light (cm) | products (%) | products up to one scale (%) | camera terms | verdict | "
          "light sigma (cm) | time (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for folder in sorted(p for p in FIXTURES.iterdir() if p.is_dir()):
        if args.cases and folder.name not in args.cases:
            continue
        truth = json.loads((folder / "scene.json").read_text())
        scene = rtloop.load_scene(folder / "scene_input.json")
        image = rtloop.load_image(folder / "objective.png", scene)
        t0 = time.perf_counter()
        res = rtloop.fit(scene, image, **options)
        seconds = time.perf_counter() - t0
        s = score(res.scene.to_dict(), truth)
        worst = max(s["product_rel_err"].values())
        scaled = scaled_products_error(res.scene.to_dict(), truth)
        cam = res.model.get("camera", {})
        terms = ",".join(cam.get("terms", [])) or "-"
        verdict = (res.goodness or {}).get("verdict", "?")[:60]
        sig = (res.uncertainty or {}).get("sigma", {})
        lsig = [sig.get(f"light.position.{a}") for a in "xyz"]
        lsig = float(np.linalg.norm([v for v in lsig if v is not None])) * 100 if all(v is not None for v in lsig) else float("nan")
        rows.append({"photo": folder.name, "light_cm": s["light_err_m"] * 100, "products_pct": worst * 100, "scaled_products_pct": scaled * 100,
                     "terms": terms, "verdict": verdict, "sigma_cm": lsig, "seconds": seconds,
                     "model_terms": res.model.get("terms")})
        print(f"| {folder.name} | {s['light_err_m'] * 100:.2f} | {worst * 100:.1f} | {scaled * 100:.1f} | {terms} | {verdict} | "
              f"{lsig:.2f} | {seconds:.1f} |", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
