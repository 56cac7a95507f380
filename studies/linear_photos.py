"""Light-direction accuracy and time of the fit on linear camera files with truth: Mitsuba's coated and matte
balls under 12 far lights (``tools/make_linear_photos.py DIR``), read as ``--response linear --mask`` as a
user reads a RAW or linear 16-bit photo. Each case is fitted with each ``--fit`` variant (default: the
defaults, ``norm=l1`` and ``norm=l2``) and scored by the angle between the fitted light's position seen from
the ball's centre and ``truth.json``'s direction; printed as a markdown table per material and variant.

    python tools/make_linear_photos.py /tmp/linear
    python studies/linear_photos.py /tmp/linear
    python studies/linear_photos.py /tmp/linear --bars --per-case [--held off] [--sandwich-form cr1]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

import rtloop

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_photos import angle_deg, parse_fit  # noqa: E402


def fit_case(case: Path, options: dict[str, Any], bars: bool = False) -> dict[str, Any]:
    scene = rtloop.load_scene(case / "scene_input.json")
    photo = rtloop.load_image(case / "objective.png", scene, response="linear")
    mask = rtloop.load_mask(case / "mask.png", scene)
    truth = json.loads((case / "truth.json").read_text())
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        result = rtloop.fit(scene, photo, mask=mask, uncertainty=bars, **options)
    seconds = time.perf_counter() - t
    lobe = result.model.get("evidence", {}).get("specular", {})
    row = {"case": case.name, "material": truth.get("material", case.name.split("-")[0]),
           "error_deg": angle_deg(result.scene.to_dict()["light"]["position"], truth["direction"]),
           "ms": 1e3 * seconds, "norm": (result.model.get("norm") or {}).get("used", result.settings.get("norm")),
           "lobe": lobe.get("lobe", "-") if "specular" in result.model.get("terms", []) else "-"}
    if bars:  # the reported direction bar (bars.light_distance), as studies/real_photos.py --bars
        u = result.uncertainty or {}
        row["sigma_deg"] = ((u.get("bars") or {}).get("light_distance") or {}).get("direction_sigma_deg")
        row["sandwich_sigma_deg"] = ((u.get("robust") or {}).get("light_distance") or {}).get("direction_sigma_deg")
        row["widened_by"] = (u.get("bars") or {}).get("widened_by")
    return row


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("dir", type=Path, help="a folder made by tools/make_linear_photos.py")
    p.add_argument("--fit", type=parse_fit, action="append", metavar="KEY=VALUE",
                   help="a variant (rtloop.fit keywords; repeat for more); default: the defaults, norm=l1, norm=l2")
    p.add_argument("--per-case", action="store_true", help="a row per case as well")
    p.add_argument("--bars", action="store_true", help="the defaults alone, with their error bars: how often the true "
                   "direction lies within 1 and 3 sigma of the reported direction bar")
    p.add_argument("--sandwich-form", choices=("cr2", "cr1"), default="cr2",
                   help="with --bars: the block sandwich's form (cr1: the plain one, as before)")
    p.add_argument("--held", choices=("on", "off"), default="on",
                   help="with --bars: whether the bars carry the coat roughness the fit chose (off: held as known, as before)")
    args = p.parse_args(argv)
    from rtloop.uncertainty import nuisance, sandwich

    sandwich.BIAS_REDUCED = args.sandwich_form == "cr2"
    nuisance.HELD_TERMS = args.held == "on"
    cases = sorted(c for c in args.dir.iterdir() if (c / "truth.json").is_file())
    if not cases:
        print(f"linear_photos.py: no cases in {args.dir} (make them with tools/make_linear_photos.py)", file=sys.stderr)
        return 2
    variants = [("defaults", {})] + [(f"{k}={v}", {k: v}) for k, v in (args.fit or ([] if args.bars else
                                                                                     [("norm", "l1"), ("norm", "l2")]))]
    rows = {name: [fit_case(c, options, args.bars) for c in cases] for name, options in variants}
    print(f"`python studies/linear_photos.py {' '.join(sys.argv[1:])}`\n")
    print("| material | fit | mean (deg) | median (deg) | max (deg) | L2 chosen | coat chosen | time per fit (ms, median) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for material in sorted({r["material"] for r in rows["defaults"]}):
        for name, rs in rows.items():
            r = [x for x in rs if x["material"] == material]
            e = np.array([x["error_deg"] for x in r])
            print(f"| {material} | {name} | {e.mean():.3f} | {np.median(e):.3f} | {e.max():.3f} | "
                  f"{sum(x['norm'] == 'l2' for x in r)}/{len(r)} | {sum(x['lobe'] == 'coat' for x in r)}/{len(r)} | "
                  f"{np.median([x['ms'] for x in r]):.0f} |")
    if args.bars:
        print("\nThe reported direction bar (bars.light_distance.direction_sigma_deg) and the sandwich's alone:\n")
        print("| material | fit | bar | median sigma (deg) | median error / sigma | within 1 sigma | within 3 sigma |")
        print("|---|---|---|---:|---:|---:|---:|")
        for material in sorted({r["material"] for r in rows["defaults"]}):
            for name, rs in rows.items():
                r = [x for x in rs if x["material"] == material]
                for what, key in (("reported", "sigma_deg"), ("sandwich", "sandwich_sigma_deg")):
                    z = np.array([x["error_deg"] / x[key] if x.get(key) else np.inf for x in r])
                    print(f"| {material} | {name} | {what} | {np.median([x.get(key) or np.inf for x in r]):.3f} | "
                          f"{np.median(z):.2f} | {100 * np.mean(z <= 1):.0f} % | {100 * np.mean(z <= 3):.0f} % |")
    if args.per_case:
        print("\n| case | " + " | ".join(rows) + " |\n|---|" + "---:|" * len(rows))
        for i, c in enumerate(cases):
            print(f"| {c.name} | " + " | ".join(
                f"{rows[n][i]['error_deg']:.3f}" + (f" ({rows[n][i]['error_deg'] / rows[n][i]['sigma_deg']:.1f} sigma)"
                                                    if rows[n][i].get("sigma_deg") else "") for n in rows) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
