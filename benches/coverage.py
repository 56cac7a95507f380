"""Calibration of the light's error bars on the Mitsuba test photos with truth: how often the true light lies
within 1 and 3 sigma, Gauss-Newton against the block sandwich (``u["robust"]``).

Cases: every folder of ``tests/fixtures/photos`` as rendered ("clean" for direct-*, "mismatch" for the rest:
environment, bounce, gloss, lamp), and for each direct-* photo two more mismatch variants made here: Gaussian
noise (2 % of full scale, linear, seed 0) and the PNG re-saved as JPEG quality 40 (Pillow). Each is fitted
once with the defaults; per light coordinate z = (fitted - true) / sigma.

Printed: a markdown table per case (light error in mm, largest |z| for each method, the sandwich's cost in
ms) and the coverage summary per class.

Usage (from the repository root, with the extension built)::

    python benches/coverage.py [--footprint]

``--footprint`` fits with ``footprint=True`` (pixels integrated over their area at shadow edges and
terminators).
"""

from __future__ import annotations

import io
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

import rtloop

REPO = Path(__file__).resolve().parents[1]
FIXTURES = REPO / "tests" / "fixtures" / "photos"
LIGHT = [f"light.position.{c}" for c in "xyz"]


def cases() -> list[tuple[str, str, Path, Any]]:
    """(name, class, folder, photo maker) for every case: the fixtures and the direct photos' variants."""
    out = []
    for folder in sorted(p for p in FIXTURES.iterdir() if (p / "scene.json").exists()):
        clean = folder.name.startswith("direct-")
        out.append((folder.name, "clean" if clean else "mismatch", folder, None))
        if clean:
            out.append((folder.name + "+noise", "mismatch", folder, "noise"))
            out.append((folder.name + "+jpeg", "mismatch", folder, "jpeg"))
    return out


def photo_of(folder: Path, scene: Any, variant: str | None) -> np.ndarray:
    if variant == "jpeg":
        buf = io.BytesIO()
        Image.open(folder / "objective.png").convert("RGB").save(buf, "JPEG", quality=40)
        with tempfile.NamedTemporaryFile(suffix=".jpg") as f:
            f.write(buf.getvalue())
            f.flush()
            return rtloop.load_image(f.name, scene)
    photo = np.asarray(rtloop.load_image(folder / "objective.png", scene), dtype=np.float32)
    if variant == "noise":
        noise = np.random.default_rng(0).normal(0.0, 0.02, photo.shape)
        photo = np.clip(photo + noise, 0.0, 1.0).astype(np.float32)
    return photo


def run_case(name: str, cls: str, folder: Path, variant: str | None, footprint: bool = False) -> dict[str, Any]:
    truth = json.loads((folder / "scene.json").read_text())
    scene = rtloop.load_scene(folder / "scene_input.json")
    photo = photo_of(folder, scene, variant)
    result = rtloop.fit(scene, photo, footprint=footprint)
    u = result.uncertainty or {}
    fitted = np.array(result.scene.to_dict()["light"]["position"], float)
    err = fitted - np.array(truth["light"]["position"], float)
    row: dict[str, Any] = {"case": name, "class": cls, "light_err_mm": 1e3 * float(np.linalg.norm(err)),
                           "cost_ms": 1e3 * (u.get("robust") or {}).get("seconds", float("nan"))}
    for key, sig in (("gn", u.get("sigma", {})), ("robust", (u.get("robust") or {}).get("sigma", {}))):
        s = np.array([sig.get(n) if sig.get(n) is not None else np.nan for n in LIGHT], float)
        row[f"z_{key}"] = (np.abs(err) / s).tolist()
        row[f"sigma_{key}_mm"] = (1e3 * s).tolist()
    return row


def summary(rows: list[dict[str, Any]]) -> list[str]:
    lines = ["| class | method | coordinates | within 1 sigma | within 3 sigma | median sigma / median error |",
             "|---|---|---|---|---|---|"]
    for cls in ("clean", "mismatch"):
        sel = [r for r in rows if r["class"] == cls]
        for key in ("gn", "robust"):
            z = np.array([v for r in sel for v in r[f"z_{key}"]], float)
            z = z[np.isfinite(z)]
            sig = np.nanmedian([v for r in sel for v in r[f"sigma_{key}_mm"]])
            errs = np.median([abs(v) * s for r in sel for v, s in zip(r[f"z_{key}"], r[f"sigma_{key}_mm"])
                              if np.isfinite(v)])
            lines.append(f"| {cls} | {key} | {z.size} | {100 * np.mean(z <= 1):.0f} % | "
                         f"{100 * np.mean(z <= 3):.0f} % | {sig / errs:.2f} |")
    return lines


def main() -> int:
    rows = []
    print("| case | class | light error (mm) | max z (GN) | max z (sandwich) | sandwich (ms) |")
    print("|---|---|---|---|---|---|")
    for c in cases():
        r = run_case(*c, footprint="--footprint" in sys.argv[1:])
        rows.append(r)
        print(f"| {r['case']} | {r['class']} | {r['light_err_mm']:.1f} | {np.nanmax(r['z_gn']):.1f} | "
              f"{np.nanmax(r['z_robust']):.1f} | {r['cost_ms'] or float('nan'):.1f} |", flush=True)
    print()
    print("\n".join(summary(rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
