"""Calibration of the error bars on the Mitsuba test photos with truth: how often the true light and the true
colour products lie within 1 and 3 sigma, for Gauss-Newton (``u["sigma"]``), the block sandwich
(``u["robust"]``) and, with ``--bootstrap``, the block bootstrap (``u["bootstrap"]``).

Cases: every folder of ``tests/fixtures/photos`` but edge-* as rendered ("clean" for direct-*: Mitsuba's direct
integrator, a point light, diffuse balls, what rtloop models but the pixel footprint; "mismatch" for the rest:
environment, bounce, gloss, lamp), and for each direct-* photo two more mismatch variants made here: Gaussian
noise (2 % of full scale, linear, seed 0) and the PNG re-saved as JPEG quality 40 (Pillow). Each is fitted
once with the defaults; per light coordinate z = |fitted - true| / sigma, per colour product (exposure x
intensity x colour x albedo, per object and channel: ``result.products`` against the truth's, sigma from
``product_sigma``) the same. Unless ``--classic``, three classes more: "camera" (each direct photo through
a lens's vignetting, an S-shaped tone curve, or with a finely textured floor), "ambient" (each environment
photo with its scene declaring the room light as unoccluded ``ambient``, and tests/fixtures/ambient) and
"onephoto" (tests/fixtures/onephoto: rtloop-scene, then the fit; the light only) and "files" (the camera-pipeline
files of tests/fixtures/camera: Bayer mosaic with noise and demosaicing, a tone curve, vignetting, each as the
camera wrote it; and the coated balls of tests/fixtures/coat from a matte start, the light only). Method "bars" is what the
fit reports (``u["bars"]``: the sandwich widened by what the model lacks, a parameter it does not determine
left out and counted as "not determined").

Printed: a markdown table per case (light error in mm, worst product error relative to the object's largest
true product, largest z per method for the light and the products, the sandwich's and the bootstrap's cost
in ms) and the coverage summary per class, quantity and method (median sigma / median error: below 1 the
bars are too short, far above 1 inflated), then per class the share of photos whose true light lies within 3
reported sigma on every determined coordinate, those whose light is not determined, and the largest light
sigma reported.

Usage (from the repository root, with the extension built)::

    python studies/coverage.py [--footprint {auto,on,off}] [--bootstrap] [--classic] [--no-onephoto] [--only CLASS]
                               [--sandwich-form {cr2,cr1}] [--held {on,off}] [--json rows.json]

``--footprint`` sets the fit's footprint mode: "auto" (the default fit: its polish integrates pixels over
their area at shadow edges and terminators), "on" (every search too), "off" (pixel centres).
``--sandwich-form cr1`` computes the block sandwich without the bias reduction and ``--held off`` holds the
coat roughness the fit chose as known, as the bars did before (the comparison in docs/uncertainty.md).
"""

from __future__ import annotations

import argparse
import contextlib
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
AMBIENT = REPO / "tests" / "fixtures" / "ambient"
ONEPHOTO = REPO / "tests" / "fixtures" / "onephoto"
CAMERA_FILES = REPO / "tests" / "fixtures" / "camera"
COAT = REPO / "tests" / "fixtures" / "coat"
LIGHT = [f"light.position.{c}" for c in "xyz"]


def cases(extra: bool = False) -> list[tuple[str, str, Path, Any]]:
    """(name, class, folder, photo maker) for every case: the fixtures and the direct photos' variants; with
    ``extra`` also the camera class (each direct photo vignetted, tone-curved and with a textured floor) and
    the ambient class (each environment photo with its scene declaring the room light as ``ambient``)."""
    out = []
    # edge-* (clean direct photos whose light shows only on outlines) are kept apart from this set
    for folder in sorted(p for p in FIXTURES.iterdir() if (p / "scene.json").exists()
                         and not p.name.startswith("edge-")):
        clean = folder.name.startswith("direct-")
        out.append((folder.name, "clean" if clean else "mismatch", folder, None))
        if clean:
            out.append((folder.name + "+noise", "mismatch", folder, "noise"))
            out.append((folder.name + "+jpeg", "mismatch", folder, "jpeg"))
            if extra:
                out += [(f"{folder.name}+{v}", "camera", folder, v) for v in CAMERA]
        elif extra and "environment" in json.loads((folder / "scene.json").read_text()):
            out.append((folder.name + "+ambient", "ambient", folder, "ambient"))
    if extra:  # photos made for it: a bright occluded room light, declared as ambient
        out += [(f.name, "ambient", f, None) for f in sorted(AMBIENT.iterdir()) if (f / "scene.json").exists()]
    return out


def onephoto_cases() -> list[tuple[str, str, Path, Any]]:
    """The one-photo views (tests/fixtures/onephoto): rtloop-scene, then the fit, as a user runs them."""
    return [(f"onephoto-{f.name}", "onephoto", f, "onephoto") for f in sorted(ONEPHOTO.iterdir())
            if (f / "photo.png").exists()]


def run_onephoto(name: str, cls: str, folder: Path, variant: Any = None, footprint: str | bool = "auto",
                 bootstrap: bool = False) -> dict[str, Any]:
    """rtloop-scene on a one-photo view (its board, ball radius and grey card), then the fit with the
    defaults; the light against the view's truth (meta.json; no product truth: its products are not
    compared)."""
    from rtloop.cli.scene import scene_main
    from rtloop.fit.files import fit_inputs, load_inputs

    meta = json.loads((folder / "meta.json").read_text())
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "scene"
        with contextlib.redirect_stdout(io.StringIO()):  # its own report, not this table's
            code = scene_main([str(folder / "photo.png"), "--board", meta["board"]["spec"], "--ball-radius",
                               str(meta["ball"]["radius"]), "--grey-card",
                               ",".join(map(str, meta["grey_card"]["rect_px"])), "--grey-card-reflectance",
                               str(meta["grey_card"]["reflectance"]), "--out", str(out)])
        if code != 0:
            raise SystemExit(f"{name}: rtloop-scene failed ({code})")
        result = fit_inputs(load_inputs(out / "scene.json", out / "objective.png"), footprint=footprint,
                            uncertainty="bootstrap" if bootstrap else True)
    return _row(name, cls, result, np.asarray(meta["light"]["position"], float), None, bootstrap)


def file_cases() -> list[tuple[str, str, Path, Any]]:
    """The camera-pipeline files and the coated balls (class "files")."""
    out = [(f.name, "files", f, "file") for f in sorted(CAMERA_FILES.iterdir()) if (f / "scene_input.json").exists()]
    return out + [(f.name, "files", f, "coat") for f in sorted(COAT.iterdir()) if (f / "scene.json").exists()]


def run_file(name: str, cls: str, folder: Path, variant: str, footprint: str | bool = "auto",
             bootstrap: bool = False) -> dict[str, Any]:
    """A camera-pipeline file fitted from its scene_input.json against its truth (light and products), or a
    coated ball from the matte start a user writes (tests/scenes.py; the light only: the fit's products are
    the coat's diffuse ones)."""
    truth = json.loads((folder / "scene.json").read_text())
    if variant == "coat":
        if str(REPO / "tests") not in sys.path:
            sys.path.insert(0, str(REPO / "tests"))
        from scenes import matte_start

        scene, products_truth = rtloop.load_scene(matte_start(truth)), None
    else:
        scene, products_truth = rtloop.load_scene(folder / "scene_input.json"), truth
    result = rtloop.fit(scene, rtloop.load_image(folder / "objective.png", scene), footprint=footprint,
                        uncertainty="bootstrap" if bootstrap else True)
    return _row(name, cls, result, np.array(truth["light"]["position"], float), products_truth, bootstrap)


#: The camera class's variants of a direct photo.
CAMERA = ("vignetting", "tone", "texture")


def _codes(x: np.ndarray) -> np.ndarray:
    """Linear values through 8-bit sRGB codes and back."""
    from rtloop._srgb import decode, encode

    return decode(np.round(encode(np.clip(x, 0.0, 1.0)) * 255.0) / 255.0).astype(np.float32)


def camera_variant(photo: np.ndarray, variant: str, truth: Any) -> np.ndarray:
    """A lens's radial falloff (corners at 40 % of the centre), an S-shaped tone curve on the codes, or the
    floor's albedo varied per pixel by a uniform factor 1 +- 0.3 (seed 0; exact for direct light). A value the
    photo has clipped stays clipped: its radiance is unknown, and a lens or a texture acts before the sensor
    clips (darkening a clipped 1.0 would make a value no camera records)."""
    from rtloop import _native
    from rtloop._srgb import decode, encode

    h, w = photo.shape[:2]
    clipped = photo >= 1.0
    if variant == "vignetting":
        yy, xx = np.mgrid[0:h, 0:w]
        r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
        return _codes(np.where(clipped, 1.0, photo * (1.0 - 0.6 * r2)[..., None]))
    if variant == "tone":
        e = encode(np.clip(photo, 0.0, 1.0))
        return _codes(decode(np.clip(e + 0.12 * np.sin(2 * np.pi * e), 0.0, 1.0)))
    ids = np.asarray(_native.object_ids(truth)).reshape(h, w)
    factor = 1.0 + 0.3 * np.random.default_rng(0).uniform(-1.0, 1.0, (h, w))
    out = photo.copy()
    floor = ids == truth.object_names.index("floor")
    out[floor] *= factor[floor][:, None]
    return _codes(np.where(clipped, 1.0, out))


def photo_of(folder: Path, scene: Any, variant: str | None) -> np.ndarray:
    if variant == "jpeg":
        buf = io.BytesIO()
        Image.open(folder / "objective.png").convert("RGB").save(buf, "JPEG", quality=40)
        with tempfile.NamedTemporaryFile(suffix=".jpg") as f:
            f.write(buf.getvalue())
            f.flush()
            return rtloop.load_image(f.name, scene)
    photo = np.asarray(rtloop.load_image(folder / "objective.png", scene), dtype=np.float32)
    if variant in CAMERA:
        return camera_variant(photo, variant, rtloop.load_scene(folder / "scene.json"))
    if variant == "noise":
        noise = np.random.default_rng(0).normal(0.0, 0.02, photo.shape)
        photo = np.clip(photo + noise, 0.0, 1.0).astype(np.float32)
    return photo


METHODS = (("gn", "Gauss-Newton"), ("robust", "block sandwich"), ("boot", "block bootstrap"),
           ("bars", "the reported bars"))


def _sigmas(u: dict[str, Any], key: str, names: list[str]) -> np.ndarray:
    """The sigma of ``names`` by method ``key`` (light coordinates and ``products.<object>.<c>``), NaN where none."""
    if key == "gn":
        sig = {**u.get("sigma", {}), **u.get("product_sigma", {})}
    elif key == "robust":
        rb = u.get("robust") or {}
        sig = {**rb.get("sigma", {}), **rb.get("product_sigma", {})}
    elif key == "bars":
        sig = (u.get("bars") or {}).get("sigma", {})
    else:
        sig = (u.get("bootstrap") or {}).get("sigma", {})
    return np.array([sig.get(n) if sig.get(n) is not None else np.nan for n in names], float)


def run_case(name: str, cls: str, folder: Path, variant: str | None, footprint: str | bool = "auto",
             bootstrap: bool = False) -> dict[str, Any]:
    """One fit of a case; per light coordinate and per colour product (object x channel) the error and each
    method's sigma (``z_<method>`` = |error| / sigma, ``sigma_<method>``; products as ``pz_``, ``psigma_``)."""
    truth = json.loads((folder / "scene.json").read_text())
    given = json.loads((folder / "scene_input.json").read_text())
    if variant == "ambient":  # the room light declared as the unoccluded ambient of the same radiance
        given["ambient"] = truth["environment"]
    scene = rtloop.load_scene(given)
    photo = photo_of(folder, scene, variant)
    result = rtloop.fit(scene, photo, footprint=footprint, uncertainty="bootstrap" if bootstrap else True)
    return _row(name, cls, result, np.array(truth["light"]["position"], float), truth, bootstrap)


def _row(name: str, cls: str, result: Any, light: np.ndarray, truth: dict[str, Any] | None,
         bootstrap: bool) -> dict[str, Any]:
    """A case's row from its fit: the light against ``light``, the products against ``truth``'s (none
    without it)."""
    u = result.uncertainty or {}
    fitted = np.array(result.scene.to_dict()["light"]["position"], float)
    err = fitted - light
    tp = products_of(truth) if truth is not None else {}
    pnames = [f"products.{o}.{c}" for o in tp for c in "rgb"]
    perr = np.array([result.products[o][i] - tp[o][i] for o in tp for i in range(3)], float)
    pscale = np.array([max(tp[o]) for o in tp for _ in range(3)], float)
    row: dict[str, Any] = {"case": name, "class": cls, "light_err_mm": 1e3 * float(np.linalg.norm(err)),
                           "product_err_rel": (np.abs(perr) / pscale).tolist() or [float("nan")],
                           "cost_ms": 1e3 * (u.get("robust") or {}).get("seconds", float("nan")),
                           "boot_ms": (u.get("bootstrap") or {}).get("ms", float("nan")),
                           "model_lacks": (u.get("bars") or {}).get("model_lacks"),
                           "widened_by": (u.get("bars") or {}).get("widened_by"),
                           "light_blocks": (u.get("robust") or {}).get("light_blocks"),
                           "not_determined": sorted((u.get("bars") or {}).get("not_determined", {})),
                           "explained": (result.goodness or {}).get("explained", {}),
                           "terms": list((result.model or {}).get("terms", [])),
                           "constant": (result.model or {}).get("constant")}
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


def _stats(rows: list[dict[str, Any]], z_key: str, s_key: str) -> tuple[int, int, float, float, float]:
    """(count, not determined, within 1 sigma, within 3 sigma, median sigma / median error) over the rows'
    values (those with a sigma)."""
    z = np.array([v for r in rows for v in r[z_key]], float)
    s = np.array([v for r in rows for v in r[s_key]], float)
    ok = np.isfinite(z) & np.isfinite(s)
    if not ok.any():
        return int(z.size), int(z.size), float("nan"), float("nan"), float("nan")
    err = z[ok] * s[ok]
    ratio = float(np.median(s[ok]) / np.median(err)) if np.median(err) > 0 else float("inf")
    return int(z.size), int((~ok).sum()), float(np.mean(z[ok] <= 1)), float(np.mean(z[ok] <= 3)), ratio


CLASSES = ("clean", "mismatch", "camera", "ambient", "onephoto", "files")


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """The coverage table: per class, quantity (light coordinates, colour products) and method."""
    lines = ["| class | quantity | method | values | not determined | within 1 sigma | within 3 sigma | "
             "median sigma / median error |", "|---|---|---|---|---|---|---|---|"]
    for cls in CLASSES:
        sel = [r for r in rows if r["class"] == cls]
        for qty, zp, sp in (("light", "z_", "sigma_{}_mm"), ("products", "pz_", "psigma_{}_rel")):
            for key, _ in METHODS:
                if not sel or f"{zp}{key}" not in sel[0]:
                    continue
                n, nd, w1, w3, ratio = _stats(sel, f"{zp}{key}", sp.format(key))
                lines.append(f"| {cls} | {qty} | {key} | {n} | {nd} | {100 * w1:.0f} % | {100 * w3:.0f} % | "
                             f"{ratio:.2f} |")
    return lines


def photo_summary(rows: list[dict[str, Any]], key: str = "bars") -> list[str]:
    """Per class and over all photos: the share of photos whose true light lies within 3 sigma on every
    determined coordinate (photos whose light is not determined at all are counted apart), the largest
    determined light sigma, and how many image blocks the light's sandwich bar rests on (``robust["light_blocks"]``)."""
    lines = [("| class | photos | light within 3 sigma | light not determined | largest light sigma (m) | "
              "light's bar rests on (blocks, median) |"), "|---|---|---|---|---|---|"]
    for cls in (*CLASSES, "all"):
        sel = [r for r in rows if cls in (r["class"], "all")]
        if not sel:
            continue
        judged = [r for r in sel if np.isfinite(r[f"z_{key}"]).any()]
        inside = sum(bool(np.nanmax(r[f"z_{key}"]) <= 3) for r in judged)
        big = max((np.nanmax(r[f"sigma_{key}_mm"]) for r in judged), default=float("nan")) / 1e3
        blocks = [r["light_blocks"] for r in sel if r.get("light_blocks") is not None]
        lines.append(f"| {cls} | {len(sel)} | {inside} / {len(judged)} ({100 * inside / max(len(judged), 1):.0f} %) | "
                     f"{len(sel) - len(judged)} | {big:.3g} | {np.median(blocks) if blocks else float('nan'):.1f} |")
    return lines


def _worst(rel: list[float]) -> str:
    """The worst product error in %, or "-" where the products have no truth."""
    a = np.asarray(rel, float)
    return f"{100 * np.nanmax(a):.2f}" if np.isfinite(a).any() else "-"


def _max(z: list[float]) -> str:
    """The largest z, or "n.d." where no value has a sigma."""
    a = np.asarray(z, float)
    return f"{np.nanmax(a):.1f}" if np.isfinite(a).any() else "n.d."


def main() -> int:
    parser = argparse.ArgumentParser(prog="coverage.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--footprint", choices=("auto", "on", "off"), default="auto",
                        help="the fit's footprint mode (default: the fit's default, 'auto')")
    parser.add_argument("--bootstrap", action="store_true", help='also uncertainty="bootstrap" (block bootstrap)')
    parser.add_argument("--json", type=Path, help="write the rows here")
    parser.add_argument("--no-onephoto", action="store_true", help="leave out the one-photo views (rtloop-scene "
                        "then the fit on each 640x480 photo: about a minute in all)")
    parser.add_argument("--only", choices=CLASSES, help="only this class of photos")
    parser.add_argument("--classic", action="store_true",
                        help="only the fixtures and their noise and JPEG variants (no camera or ambient class)")
    parser.add_argument("--sandwich-form", choices=("cr2", "cr1"), default="cr2",
                        help="the block sandwich's form: 'cr2' (the default: each block's score bias-reduced for its "
                        "leverage) or 'cr1' (the plain form with B / (B - p), as before; "
                        "rtloop.uncertainty.sandwich.BIAS_REDUCED)")
    parser.add_argument("--held", choices=("on", "off"), default="on",
                        help="whether the bars carry the coat roughness the fit chose (off: held as known, as before; "
                        "rtloop.uncertainty.nuisance.HELD_TERMS)")
    args = parser.parse_args()
    from rtloop.uncertainty import nuisance, sandwich

    sandwich.BIAS_REDUCED = args.sandwich_form == "cr2"
    nuisance.HELD_TERMS = args.held == "on"
    rows = []
    boot = args.bootstrap
    print("| case | class | light error (mm) | worst product (%) | max z light (GN / sandwich" + (" / bootstrap" if boot else "")
          + " / bars) | max z products (GN / sandwich" + (" / bootstrap" if boot else "") + " / bars) | bars widened | "
          "sandwich (ms)" + (" | bootstrap (ms)" if boot else "") + " |")
    print("|---|---|---|---|---|---|---|---|" + ("---|" if boot else ""))
    keys = ["gn", "robust"] + (["boot"] if boot else []) + ["bars"]
    todo = cases(extra=not args.classic) + ([] if args.classic or args.no_onephoto else onephoto_cases())
    todo += [] if args.classic else file_cases()
    todo = [c for c in todo if args.only in (None, c[1])]
    run = {"onephoto": run_onephoto, "files": run_file}
    for c in todo:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the noisy variants' negative-value warning
            r = run.get(c[1], run_case)(*c, footprint=args.footprint, bootstrap=boot)
        rows.append(r)
        zl = " / ".join(_max(r[f"z_{k}"]) for k in keys)
        zp = " / ".join(_max(r[f"pz_{k}"]) for k in keys)
        print(f"| {r['case']} | {r['class']} | {r['light_err_mm']:.1f} | {_worst(r['product_err_rel'])} | "
              f"{zl} | {zp} | {r['widened_by']:.2f} | {r['cost_ms']:.1f}" + (f" | {r['boot_ms']:.0f}" if boot else "")
              + " |", flush=True)
    print()
    print("\n".join(summary(rows)))
    print()
    print("\n".join(photo_summary(rows)))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
