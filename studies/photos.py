"""Accuracy and time of the default fit on the Mitsuba test photos in ``tests/fixtures/photos``.

Every case folder (made by ``tools/make_photos.py``) is fitted with the default ``rtloop.fit`` on the
fit section of its ``scene_input.json`` (light position, light intensity, every albedo; no extra options)
and ``objective.png`` loaded with ``rtloop.load_image``, three times; the fitted scene is scored against
``scene.json`` (read as plain JSON) with
:func:`score`, the measures of ``../shared/tools/score_result.py``.

Printed: a markdown table with, per case, the light position error (mm), the light direction error seen
from the first sphere (deg), the worst relative product error over the objects (%), and the fit time
(ms, median of the three runs), then median and max rows per group (direct, env, bounce, env-bounce,
gloss, lamp: the case name's prefix).

Usage (from the repository root, with the extension built)::

    python studies/photos.py
    python studies/photos.py --json /tmp/photos.json --cases direct-side gloss-a010
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import rtloop

REPO = Path(__file__).resolve().parents[1]
FIXTURES = REPO / "tests" / "fixtures" / "photos"
GROUPS = ("direct", "env", "bounce", "env-bounce", "gloss", "lamp")
RUNS = 3


def score(res: dict[str, Any], truth: dict[str, Any]) -> dict[str, Any]:
    """Errors of a fitted scene against the truth (both scene dicts).

    Mirrors ``../shared/tools/score_result.py`` (light_err_m, light_dir_err_deg seen from the first
    sphere's centre, product_rel_err per object = max over RGB of |P fit - P truth| / max(P truth)), with
    one difference: the product P is intensity x color x albedo, not intensity x albedo, because these
    photos have coloured lights that the user's scene_input.json calls white (the image determines the
    whole product; with white lights on both sides the two are the same).
    """
    tl = np.array(truth["light"]["position"], float)
    fl = np.array(res["light"]["position"], float)
    out: dict[str, Any] = {"light_err_m": float(np.linalg.norm(fl - tl))}
    c0 = next((np.array(o["center"], float) for o in truth["objects"] if o["shape"] == "sphere"), None)
    if c0 is not None:
        u, v = fl - c0, tl - c0
        cosang = u @ v / (np.linalg.norm(u) * np.linalg.norm(v))
        out["light_dir_err_deg"] = float(np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0))))

    def light_rgb(scene: dict[str, Any]) -> np.ndarray:
        return float(scene["light"]["intensity"]) * np.array(scene["light"].get("color", [1, 1, 1]), float)

    ti, ri = light_rgb(truth), light_rgb(res)
    fitted = {o["name"]: o for o in res["objects"]}
    out["product_rel_err"] = {}
    for o in truth["objects"]:
        tp = np.array(o["material"]["albedo"], float) * ti
        rp = np.array(fitted[o["name"]]["material"]["albedo"], float) * ri
        out["product_rel_err"][o["name"]] = float(np.max(np.abs(rp - tp)) / max(float(np.max(tp)), 1e-12))
    return out


def group_of(name: str) -> str:
    """The case's group: the longest of GROUPS that prefixes its name."""
    return max((g for g in GROUPS if name.startswith(g + "-")), key=len, default="other")


def fit_case(folder: Path) -> dict[str, Any]:
    """Fit one case RUNS times with the defaults; its errors (first run; the fits are seeded) and times."""
    truth = json.loads((folder / "scene.json").read_text())
    scene = rtloop.load_scene(folder / "scene_input.json")
    photo = rtloop.load_image(folder / "objective.png", scene)
    times, result = [], None
    for _ in range(RUNS):
        t0 = time.perf_counter()
        result = rtloop.fit(scene, photo)
        times.append(time.perf_counter() - t0)
    fitted = result.scene.to_dict()
    if "lights" in fitted:  # the default fit kept a further light: the strongest one is scored
        fitted["light"] = fitted["lights"][0]
    s = score(fitted, truth)
    tested = result.model.get("lights") if isinstance(result, rtloop.FitResult) else result.gate
    return {
        "case": folder.name,
        "group": group_of(folder.name),
        "light_err_mm": 1000.0 * s["light_err_m"],
        "light_dir_err_deg": s["light_dir_err_deg"],
        "worst_product_err_pct": 100.0 * max(s["product_rel_err"].values()),
        "product_err_pct": {k: 100.0 * v for k, v in s["product_rel_err"].items()},
        "fit_ms": 1000.0 * statistics.median(times),
        "fitted_light": fitted["light"]["position"],
        "method": result.report()["settings"].get("method") if isinstance(result, rtloop.FitResult) else "lights",
        "terms": "+".join(result.model.get("terms", ["direct"])[1:]) or "-" if isinstance(result, rtloop.FitResult)
        else "-",
        "lights": f"{len(fitted.get('lights', [0]))} ({'tried' if tested and tested.get('tried') else 'not tried'})"
        if tested else "1",
    }


def _row(cells: list[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def table(rows: list[dict[str, Any]]) -> str:
    """The markdown table: one row per case, then median and max per group."""
    keys = ("light_err_mm", "light_dir_err_deg", "worst_product_err_pct", "fit_ms")
    fmt = ("{:.1f}", "{:.2f}", "{:.2f}", "{:.0f}")
    lines = [_row(["case", "light error (mm)", "light direction (deg)", "worst product (%)", "fit (ms)",
                   "terms added", "lights (a further one tried)"]),
             _row(["---", "---:", "---:", "---:", "---:", "---", "---"])]
    for r in rows:
        lines.append(_row([r["case"]] + [f.format(r[k]) for k, f in zip(keys, fmt, strict=True)] + [r["terms"],
                                                                                                    r["lights"]]))
    for g in GROUPS:
        grp = [r for r in rows if r["group"] == g]
        if not grp:
            continue
        for label, agg in (("median", statistics.median), ("max", max)):
            lines.append(_row([f"**{g}: {label}** ({len(grp)})"]
                              + [f.format(agg(r[k] for r in grp)) for k, f in zip(keys, fmt, strict=True)] + ["", ""]))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Fit every case (or those named) and print the table; ``--json`` also writes the numbers."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fixtures", type=Path, default=FIXTURES,
                        help="folder of case folders (default: tests/fixtures/photos)")
    parser.add_argument("--cases", nargs="+", metavar="NAME", help="only these cases")
    parser.add_argument("--json", type=Path, metavar="PATH", help="write the numbers as JSON")
    args = parser.parse_args(argv)
    folders = sorted(p for p in args.fixtures.iterdir() if (p / "scene_input.json").is_file())
    if args.cases:
        missing = set(args.cases) - {p.name for p in folders}
        if missing:
            parser.error(f"no such case: {', '.join(sorted(missing))}")
        folders = [p for p in folders if p.name in args.cases]
    order = {g: i for i, g in enumerate(GROUPS)}
    folders.sort(key=lambda p: (order.get(group_of(p.name), len(GROUPS)), p.name))
    rows = []
    for folder in folders:
        rows.append(fit_case(folder))
        print(f"{folder.name}: {rows[-1]['light_err_mm']:.1f} mm", file=sys.stderr, flush=True)
    print(table(rows))
    if args.json:
        args.json.write_text(json.dumps({
            "rtloop": getattr(rtloop, "__version__", None),
            "python": platform.python_version(),
            "machine": platform.machine(),
            "runs_per_case": RUNS,
            "cases": rows,
        }, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
