"""Calibration of the error bars on the Mitsuba test photos with truth: how often the true light and the true
colour products lie within 1 and 3 sigma, for Gauss-Newton (``u["sigma"]``), the block sandwich
(``u["robust"]``) and, with ``--bootstrap``, the block bootstrap (``u["bootstrap"]``).

Cases: every folder of ``tests/fixtures/photos`` as rendered ("clean" for direct-*: Mitsuba's direct
integrator, a point light, diffuse balls, what rtloop models but the pixel footprint; "mismatch" for the rest:
environment, bounce, gloss, lamp), and for each direct-* photo two more mismatch variants made here: Gaussian
noise (2 % of full scale, linear, seed 0) and the PNG re-saved as JPEG quality 40 (Pillow). Each is fitted
once with the defaults; per light coordinate z = |fitted - true| / sigma, per colour product (exposure x
intensity x colour x albedo, per object and channel: ``result.products`` against the truth's, sigma from
``product_sigma``) the same.

Printed: a markdown table per case (light error in mm, worst product error relative to the object's largest
true product, largest z per method for the light and the products, the sandwich's and the bootstrap's cost
in ms) and the coverage summary per class, quantity and method (median sigma / median error: below 1 the
bars are too short, far above 1 inflated).

Usage (from the repository root, with the extension built)::

    python benches/coverage.py [--footprint {auto,on,off}] [--bootstrap] [--json rows.json]

``--footprint`` sets the fit's footprint mode: "auto" (the default fit: its polish integrates pixels over
their area at shadow edges and terminators), "on" (every search too), "off" (pixel centres).
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

import rtloop
from rtloop.fit.products import products_of

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


METHODS = (("gn", "Gauss-Newton"), ("robust", "block sandwich"), ("boot", "block bootstrap"))


def _sigmas(u: dict[str, Any], key: str, names: list[str]) -> np.ndarray:
    """The sigma of ``names`` by method ``key`` (light coordinates and ``products.<object>.<c>``), NaN where none."""
    if key == "gn":
        sig = {**u.get("sigma", {}), **u.get("product_sigma", {})}
    elif key == "robust":
        rb = u.get("robust") or {}
        sig = {**rb.get("sigma", {}), **rb.get("product_sigma", {})}
    else:
        sig = (u.get("bootstrap") or {}).get("sigma", {})
    return np.array([sig.get(n) if sig.get(n) is not None else np.nan for n in names], float)


def run_case(name: str, cls: str, folder: Path, variant: str | None, footprint: str | bool = "auto",
             bootstrap: bool = False) -> dict[str, Any]:
    """One fit of a case; per light coordinate and per colour product (object x channel) the error and each
    method's sigma (``z_<method>`` = |error| / sigma, ``sigma_<method>``; products as ``pz_``, ``psigma_``)."""
    truth = json.loads((folder / "scene.json").read_text())
    scene = rtloop.load_scene(folder / "scene_input.json")
    photo = photo_of(folder, scene, variant)
    result = rtloop.fit(scene, photo, footprint=footprint, uncertainty="bootstrap" if bootstrap else True)
    u = result.uncertainty or {}
    fitted = np.array(result.scene.to_dict()["light"]["position"], float)
    err = fitted - np.array(truth["light"]["position"], float)
    tp = products_of(truth)
    pnames = [f"products.{o}.{c}" for o in tp for c in "rgb"]
    perr = np.array([result.products[o][i] - tp[o][i] for o in tp for i in range(3)], float)
    pscale = np.array([max(tp[o]) for o in tp for _ in range(3)], float)
    row: dict[str, Any] = {"case": name, "class": cls, "light_err_mm": 1e3 * float(np.linalg.norm(err)),
                           "product_err_rel": (np.abs(perr) / pscale).tolist(),
                           "cost_ms": 1e3 * (u.get("robust") or {}).get("seconds", float("nan")),
                           "boot_ms": (u.get("bootstrap") or {}).get("ms", float("nan"))}
    for key, _ in METHODS:
        if key == "boot" and not bootstrap:
            continue
        s = _sigmas(u, key, LIGHT)
        row[f"z_{key}"] = (np.abs(err) / s).tolist()
        row[f"sigma_{key}_mm"] = (1e3 * s).tolist()
        ps = _sigmas(u, key, pnames)
        row[f"pz_{key}"] = (np.abs(perr) / ps).tolist()
        row[f"psigma_{key}_rel"] = (ps / pscale).tolist()
    return row


def _stats(rows: list[dict[str, Any]], z_key: str, s_key: str) -> tuple[int, float, float, float]:
    """(count, within 1 sigma, within 3 sigma, median sigma / median error) over the rows' values."""
    z = np.array([v for r in rows for v in r[z_key]], float)
    s = np.array([v for r in rows for v in r[s_key]], float)
    ok = np.isfinite(z) & np.isfinite(s)
    if not ok.any():
        return 0, float("nan"), float("nan"), float("nan")
    err = z[ok] * s[ok]
    ratio = float(np.median(s[ok]) / np.median(err)) if np.median(err) > 0 else float("inf")
    return int(z.size), float(np.mean(z[ok] <= 1)), float(np.mean(z[ok] <= 3)), ratio


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """The coverage table: per class, quantity (light coordinates, colour products) and method."""
    lines = ["| class | quantity | method | values | within 1 sigma | within 3 sigma | median sigma / median error |",
             "|---|---|---|---|---|---|---|"]
    for cls in ("clean", "mismatch"):
        sel = [r for r in rows if r["class"] == cls]
        for qty, zp, sp in (("light", "z_", "sigma_{}_mm"), ("products", "pz_", "psigma_{}_rel")):
            for key, _ in METHODS:
                if not sel or f"{zp}{key}" not in sel[0]:
                    continue
                n, w1, w3, ratio = _stats(sel, f"{zp}{key}", sp.format(key))
                lines.append(f"| {cls} | {qty} | {key} | {n} | {100 * w1:.0f} % | {100 * w3:.0f} % | {ratio:.2f} |")
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(prog="coverage.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--footprint", choices=("auto", "on", "off"), default="auto",
                        help="the fit's footprint mode (default: the fit's default, 'auto')")
    parser.add_argument("--bootstrap", action="store_true", help='also uncertainty="bootstrap" (block bootstrap)')
    parser.add_argument("--json", type=Path, help="write the rows here")
    args = parser.parse_args()
    rows = []
    boot = args.bootstrap
    print("| case | class | light error (mm) | worst product (%) | max z light (GN / sandwich" + (" / bootstrap" if boot else "")
          + ") | max z products (GN / sandwich" + (" / bootstrap" if boot else "") + ") | sandwich (ms)"
          + (" | bootstrap (ms)" if boot else "") + " |")
    print("|---|---|---|---|---|---|---|" + ("---|" if boot else ""))
    keys = ["gn", "robust"] + (["boot"] if boot else [])
    for c in cases():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the noisy variants' negative-value warning
            r = run_case(*c, footprint=args.footprint, bootstrap=boot)
        rows.append(r)
        zl = " / ".join(f"{np.nanmax(r[f'z_{k}']):.1f}" for k in keys)
        zp = " / ".join(f"{np.nanmax(r[f'pz_{k}']):.1f}" for k in keys)
        print(f"| {r['case']} | {r['class']} | {r['light_err_mm']:.1f} | {100 * max(r['product_err_rel']):.2f} | "
              f"{zl} | {zp} | {r['cost_ms']:.1f}" + (f" | {r['boot_ms']:.0f}" if boot else "") + " |", flush=True)
    print()
    print("\n".join(summary(rows)))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
