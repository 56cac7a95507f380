"""The image terms' in-sample and held-out evidence on test photos, and what the held-out check costs.

Each case (a folder with ``scene_input.json``, ``objective.png`` and the truth ``scene.json``: the
committed Mitsuba photos of tests/fixtures/photos and the held-out photos of tests/fixtures/heldout) is
fitted with the defaults (and ``--fit KEY=VALUE`` keywords, e.g. ``norm=l2``) RUNS times; printed per
case: the light's error against the truth (mm), the terms taken, each tested term's in-sample gain and
held-out gain (``evidence[term]["held_out"]``), the fit's median time and the part of it the held-out check
took (ms, timed around ``heldout.held_out_loss``).

Usage (from the repository root, with the extension built)::

    python studies/heldout_terms.py
    python studies/heldout_terms.py --fit norm=l2 --cases rim room
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import rtloop
from rtloop.fit import heldout, selection, terms

REPO = Path(__file__).resolve().parents[1]
FOLDERS = (REPO / "tests" / "fixtures" / "photos", REPO / "tests" / "fixtures" / "heldout")
RUNS = 3


def _timed(spent: list[float]) -> None:
    """Time every held-out loss into ``spent[0]``."""
    plain = heldout.held_out_loss

    def timed(*a: Any, **k: Any) -> float:
        t0 = time.perf_counter()
        try:
            return plain(*a, **k)
        finally:
            spent[0] += time.perf_counter() - t0

    selection.held_out_loss = timed  # type: ignore[assignment]
    terms.held_out_loss = timed  # type: ignore[assignment]


def fit_case(folder: Path, kw: dict[str, Any], spent: list[float]) -> dict[str, Any]:
    truth = np.asarray(json.loads((folder / "scene.json").read_text())["light"]["position"], float)
    scene = rtloop.load_scene(folder / "scene_input.json")
    photo = rtloop.load_image(folder / "objective.png", scene)
    times, held, result = [], [], None
    for _ in range(RUNS):
        spent[0] = 0.0
        t0 = time.perf_counter()
        result = rtloop.fit(scene, photo, uncertainty=False, **kw)
        times.append(time.perf_counter() - t0)
        held.append(spent[0])
    light = np.asarray(result.scene.to_dict()["light"]["position"], float)
    ev = {t: (e["gain"], e.get("held_out", {}).get("gain"), e["selected"]) for t, e in result.model["evidence"].items()}
    return {"case": folder.name, "light_err_mm": 1000 * float(np.linalg.norm(light - truth)),
            "terms": "+".join(result.model["terms"][1:]) or "-", "evidence": ev,
            "fit_ms": 1000 * statistics.median(times), "held_out_ms": 1000 * statistics.median(held)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", nargs="+", help="only these case names")
    p.add_argument("--fit", action="append", default=[], metavar="KEY=VALUE", help="rtloop.fit keywords")
    args = p.parse_args(argv)
    kw = {k: v for k, v in (f.split("=", 1) for f in args.fit)}
    spent = [0.0]
    _timed(spent)
    print("| case | light error (mm) | terms | term: in-sample / held-out gain (%) | fit (ms) | held-out (ms) |")
    print("|---|---:|---|---|---:|---:|")
    for folder in FOLDERS:
        for case in sorted(c for c in folder.iterdir() if (c / "scene_input.json").exists()):
            if args.cases and case.name not in args.cases:
                continue
            r = fit_case(case, kw, spent)
            ev = "; ".join(f"{t}{'*' if s else ''} {100 * g:.1f} / " + ("-" if h is None else f"{100 * h:.1f}")
                           for t, (g, h, s) in r["evidence"].items())
            print(f"| {r['case']} | {r['light_err_mm']:.2f} | {r['terms']} | {ev or '-'} | {r['fit_ms']:.0f} | "
                  f"{r['held_out_ms']:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
