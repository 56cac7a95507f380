"""A fuzz campaign over the Python API (scenes, render()/fit() arguments, image arrays, CLI arguments via
main() in-process) for a developer to run for minutes; prints the counts. Not a test: see
docs/development.md."""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import math
import random
import sys
import tempfile
import traceback
import warnings
from pathlib import Path

import numpy as np

import rtloop
from rtloop.cli import fit as cli_fit

REPO = Path(__file__).resolve().parents[1]


def _base() -> dict:
    """The shipped example's scene at 12 x 9 pixels with a little ambient light (the closed form's constant
    column): fits take milliseconds."""
    d = json.loads((REPO / "examples" / "yellow-ball" / "scene_input.json").read_text())
    d["image"] = {"width": 12, "height": 9}
    d["ambient"] = [0.02, 0.02, 0.02]
    return d


def _fit_scenes(base: dict) -> list[dict]:
    """The base and variants that reach each way a fit goes: a fixed albedo under a free intensity (the
    two-stage fallback), a free light colour and exposure (held for the closed form), a lit background
    with a free exposure (measured from it), a known highlight (it measures the intensity)."""
    objects = [o["name"] for o in base["objects"]]
    fixed = copy.deepcopy(base)
    fixed["fit"].pop(f"objects.{objects[-1]}.albedo", None)
    gauges = copy.deepcopy(base)
    gauges["fit"]["light.color"] = {"min": [0.2, 0.2, 0.2], "max": [1, 1, 1]}
    gauges["fit"]["exposure"] = {"min": 0.3, "max": 3}
    lit = copy.deepcopy(gauges)
    lit["background"] = [0.3, 0.4, 0.5]
    known = copy.deepcopy(base)
    known["ambient"] = [0.0, 0.0, 0.0]
    known["objects"][0]["material"].update(specular=0.3, shininess=20.0)
    return [base, fixed, gauges, lit, known]


BASE = _base()
FIT_SCENES = _fit_scenes(BASE)
ODD = [
    None,
    True,
    0,
    -1,
    1e300,
    -1e-300,
    float("nan"),
    float("inf"),
    "",
    "x",
    [],
    {},
    [1, 2],
    [0, 0, 0],
    {"min": 1, "max": 0},
    2**70,
]


def odd(rng: random.Random):
    return copy.deepcopy(rng.choice(ODD)) if rng.random() < 0.7 else rng.uniform(-1e3, 1e3)


def mutate(rng: random.Random, d) -> dict:
    d = copy.deepcopy(d)
    for _ in range(rng.randint(1, 3)):
        node, key = d, None
        while True:
            keys = list(node.keys()) if isinstance(node, dict) else list(range(len(node)))
            if not keys:
                break
            key = rng.choice(keys)
            child = node[key]
            if not isinstance(child, (dict, list)) or not child or rng.random() < 0.3:
                break
            node = child
        if key is None:
            continue
        if isinstance(node, dict) and rng.random() < 0.2:
            del node[key]
        else:
            node[key] = odd(rng)
    return d


class Counts(dict):
    def bump(self, k, n=1):
        self[k] = self.get(k, 0) + n


def finite(a) -> bool:
    return bool(np.all(np.isfinite(np.asarray(a, dtype=float))))


def check_fit(res, scene_dict, c: Counts) -> None:
    c.bump("fits")
    c.bump(f"fits_{res.settings['method']}")
    for name, v in res.x.items():
        if not math.isfinite(v):
            c.bump("nan_or_inf")
        base, _, comp = name.rpartition(".")
        spec = scene_dict["fit"].get(base) or scene_dict["fit"].get(name)
        if not isinstance(spec, dict):
            continue
        i = "xyz".find(comp) if base in scene_dict["fit"] else 0
        lo, hi = spec["min"], spec["max"]
        lo = lo[i] if isinstance(lo, list) else lo
        hi = hi[i] if isinstance(hi, list) else hi
        if not lo - 1e-12 <= v <= hi + 1e-12:
            c.bump("out_of_bounds")
            print("out of bounds:", name, v, (lo, hi), file=sys.stderr)


def one(rng: random.Random, c: Counts, tmp: Path, first: dict) -> None:
    kind = rng.random()
    if kind < 0.55:  # scenes
        scene = rtloop.load_scene(mutate(rng, BASE))
        img = rtloop.render(scene, width=rng.choice([None, 4, 7]), height=None, spp=1)
        if not finite(img):
            c.bump("nan_or_inf")
    elif kind < 0.8:  # render()/object_ids() arguments
        args = [odd(rng) if rng.random() < 0.5 else rng.randint(1, 9) for _ in range(3)]
        img = rtloop.render(BASE, width=args[0], height=args[1], spp=args[2])
        if not finite(img):
            c.bump("nan_or_inf")
    elif kind < 0.98:  # image arrays into fit()
        shape = rng.choice([(9, 12, 3), (9, 12), (9, 12, 4), (0, 12, 3), (12, 9, 3), (9, 12, 3, 1)])
        arr = np.asarray(np.random.default_rng(rng.randrange(2**32)).uniform(-0.5, 2.0, shape), np.float32)
        if arr.size and rng.random() < 0.3:
            arr.flat[rng.randrange(max(arr.size, 1))] = (
                rng.choice([np.nan, np.inf, -np.inf]) if arr.size else 0
            )
        if rng.random() < 0.2:
            arr = arr.astype(rng.choice([np.float64, np.uint8, np.int32, bool]))
        opts = {
            "seed": rng.randrange(100),
            "population": rng.choice([8, 0, -1, 10**9]) if rng.random() < 0.2 else 8,
            "generations": rng.choice([1, 2, 0, -3, (1, 1), "x"]) if rng.random() < 0.2 else 1,
        }
        scene = rng.choice(FIT_SCENES)
        if rng.random() < 0.1:
            scene = mutate(rng, scene)
        elif shape == (9, 12, 3) and rng.random() < 0.4:
            # a photo the model can explain: the scene under another light in its box, scaled, with noise
            truth = copy.deepcopy(scene)
            box = truth["fit"]["light.position"]
            truth["light"]["position"] = [rng.uniform(lo, hi) for lo, hi in zip(box["min"], box["max"])]
            truth["exposure"] = truth.get("exposure", 1.0) * rng.uniform(0.3, 3.0)
            noise = np.random.default_rng(rng.randrange(2**32)).normal(0, rng.choice([0, 0.01, 0.05]), shape)
            arr = np.minimum(rtloop.render(truth), 1.0) + noise.astype(np.float32)
        res = rtloop.fit(scene, arr, protocol="rtloop", **opts)
        check_fit(res, scene, c)
    else:  # CLI arguments via main()
        argv = [str(tmp / "scene.json"), str(tmp / "photo.png"), "--out", str(tmp / "out")]
        flags = ["--seed", "--population", "--generations", "--threads", "--norm", "--space", "--protocol"]
        for _ in range(rng.randint(0, 3)):
            argv += [rng.choice(flags), str(odd(rng))]
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            try:
                cli_fit.main(argv)
            except SystemExit as e:  # argparse's usage errors exit 2
                if e.code not in (0, 1, 2):
                    raise
    c.bump("ok")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--inputs", type=int, default=100_000, help="generated inputs (default 100000)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    warnings.simplefilter("ignore")  # the library's warnings on odd images are expected here
    rng, c = random.Random(a.seed), Counts()
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        (tmp / "scene.json").write_text(json.dumps(BASE))
        rtloop.save_image(tmp / "photo.png", rtloop.render(BASE))
        first: dict = {}
        for _ in range(a.inputs):
            c.bump("inputs")
            try:
                one(rng, c, tmp, first)
            except rtloop.RtloopError:
                c.bump("rtloop_errors")
            except KeyboardInterrupt:
                raise
            except BaseException as e:  # noqa: BLE001 (the point of a fuzz run) a Rust panic reaches Python as PanicException (a BaseException)
                name = type(e).__name__
                c.bump("panics" if "Panic" in name else "non_rtloop_exceptions")
                key = (name, str(e)[:80])
                if key not in first:
                    first[key] = traceback.format_exc()
                    print(f"== {name}: {e}", file=sys.stderr)
                    print(first[key], file=sys.stderr)
    for k in [
        "inputs",
        "ok",
        "fits",
        "fits_projected",
        "fits_two-stage",
        "rtloop_errors",
        "panics",
        "non_rtloop_exceptions",
        "nan_or_inf",
        "out_of_bounds",
    ]:
        print(f"{k}: {c.get(k, 0)}")
    bad = sum(c.get(k, 0) for k in ["panics", "non_rtloop_exceptions", "nan_or_inf", "out_of_bounds"])
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
