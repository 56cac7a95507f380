"""A fuzz campaign over the Python API (scenes, render()/fit() arguments, image arrays, CLI arguments via
main() in-process, batch job lines and ids via rtloop-fit --batch, mesh files, EXIF focal tags,
rtloop-insert arguments) for a developer to run for minutes; prints the counts (--only batch: job lines
alone). Not a test: see docs/development.md."""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import math
import os
import random
import shutil
import sys
import tempfile
import traceback
import warnings
from pathlib import Path

import numpy as np

import rtloop
from rtloop.cli import batch as cli_batch
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


def _lights_base(base: dict) -> dict:
    """The base under a `lights` list: its lamp, a sphere fill light and a sun, with their paths freed."""
    d = copy.deepcopy(base)
    lamp = d.pop("light")
    d["lights"] = [{"name": "key", **lamp},
                   {"name": "fill", "type": "sphere", "position": [-2.0, 3.0, -1.0], "radius": 0.3, "intensity": 5.0},
                   {"name": "sun", "type": "directional", "direction": [0.2, 1.0, 0.1], "intensity": 0.2}]
    d["fit"]["lights.fill.position"] = {"min": [-4, 0.5, -4], "max": [4, 6, 4]}
    d["fit"]["lights.fill.radius"] = {"min": 0.01, "max": 1.0}
    d["fit"]["lights.sun.intensity"] = {"min": 0, "max": 1}
    return d


BASE = _base()
LIGHTS_BASE = _lights_base(BASE)
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
    if hasattr(res, "lights"):  # the lights fit
        c.bump("fits_lights")
        values = [v for light in res.lights for key in ("position", "direction") for v in light.get(key, [])]
        values += [v for rows in res.products.values() for row in rows for v in row]
        if not finite(values) or not finite([light["intensity"] for light in res.lights]):
            c.bump("nan_or_inf")
        return
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


MESH_HEADS = [
    "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
    "element face {m}\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty double x\nproperty double y\n"
    "property double z\nelement face {m}\nproperty list uint int vertex_indices\nend_header\n",
    "v 0 0 0\nv 1e300 0 0\nv 0 1 0\nf 1 2 {m}\nmtllib /dev/zero\n",
]


def _mesh(rng: random.Random, tmp: Path) -> None:
    """A mesh file: a header with odd counts and a mutated body (bytes flipped, cut, repeated)."""
    data = bytearray(rng.choice(MESH_HEADS).format(n=rng.choice([0, 3, 2**31, 10**12, -1]),
                                                    m=rng.choice([0, 1, 9, 2**32])).encode())
    for _ in range(rng.randint(0, 4)):
        if data:
            data[rng.randrange(len(data))] = rng.randrange(256)
    data += bytes(rng.randrange(256) for _ in range(rng.randint(0, 64)))
    path = tmp / f"m.{rng.choice(['ply', 'obj', 'PLY'])}"
    path.write_bytes(bytes(data[: rng.randint(0, len(data))] if rng.random() < 0.2 else data))
    scene = copy.deepcopy(BASE)
    scene["objects"].append({"name": "m", "shape": "mesh", "file": str(path), "scale": rng.choice([1, 1e-9, 1e9])})
    rtloop.render(rtloop.load_scene(scene), 6, 4, 1)


def _exif(rng: random.Random, tmp: Path) -> None:
    from PIL import Image

    from rtloop.acquisition.exif import exif_exposure, exif_focal

    exif = Image.Exif()
    exif[0x0112] = rng.randint(-1, 10)
    tags = {t: odd(rng) if rng.random() < 0.5 else rng.choice([4.0, 28, 1600.0, 3, (1, 0), 1e9, 1e-9])
            for t in rng.sample([0x920A, 0xA405, 0xA20E, 0xA210, 0x829A, 0x829D, 0x8827], rng.randint(1, 5))}
    try:
        exif.get_ifd(0x8769).update(tags)
        Image.new("RGB", (8, 6)).save(tmp / "e.jpg", exif=exif)
    except Exception:  # noqa: BLE001 - a value Pillow cannot write
        return
    found = exif_focal(tmp / "e.jpg", rng.choice([8, 6, 1000]), 6)
    if found is not None and not (math.isfinite(found.focal_px) and found.focal_px > 0):
        raise AssertionError(f"focal_px {found.focal_px}")
    exif_exposure(tmp / "e.jpg")


def _insert_cli(rng: random.Random, tmp: Path) -> None:
    from rtloop.cli.insert import insert_main

    work = tmp / "ins"
    work.mkdir(exist_ok=True)
    before = sorted(p.name for p in work.iterdir())
    argv = [str(tmp / "scene.json"), str(tmp / "photo.png"), "--add", str(tmp / "objects.json"),
            "--out", str(work / "out")]
    for _ in range(rng.randint(0, 3)):
        flag = rng.choice(["--spp", "--response", "--out", "--force", "--uniform"])
        argv += [flag] if flag in ("--force", "--uniform") else [flag, str(odd(rng))]
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()), \
            contextlib.chdir(work):  # a relative --out stays inside the sandbox
        try:
            insert_main(argv)
        except SystemExit as e:
            if e.code not in (0, 1, 2):
                raise
    outs = {argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--out"}
    made = sorted(p.name for p in work.iterdir() if p.name not in before and p.name not in outs | {"out"})
    if made or not (tmp / "photo.png").is_file() or not (tmp / "objects.json").is_file():
        raise AssertionError(f"rtloop-insert wrote beside --out or lost an input: {made}")


JOB_IDS = ["a", "b-1", "keep", "results.jsonl", "../out", "/tmp", ".hidden", "", "a/b", "..", "x" * 129, "ok.1",
           ".rtloop-batch.lock", "f0", 7]
JOB_FIELDS = ["seed", "mask", "protocol", "population", "generations", "f", "cr", "norm", "space", "loss_space",
              "optimizer", "polish", "clip", "uncertainty", "pixels_per_object", "environment", "interreflection",
              "highlights", "footprint", "response", "crop", "grey_card", "image", "bogus"]
JOB_VALUES = [*ODD, "auto", "on", "off", "srgb", "linear", "paper", "l2", "bootstrap", [1, 1], [2, "x"],
              {"mask": "photo.png", "reflectance": 0.18}, {"mask": "../scene.json", "reflectance": 2}, 10**40]
RAW_LINES = ["[" * 100_000 + "]" * 100_000, '{"id": "a", "id": "b", "scene": "s", "photo": "p"}', "{", "null",
             '{"id": "a", "seed": 1' + "0" * 5000 + "}", "# comment", "\ufeff{}", "\x00"]


def job_line(rng: random.Random) -> str:
    if rng.random() < 0.1:
        return rng.choice(RAW_LINES)
    d: dict = {}
    if rng.random() < 0.9:
        d["id"] = rng.choice(JOB_IDS) if rng.random() < 0.7 else odd(rng)
    for key, good in (("scene", "../scene.json"), ("photo", "../photo.png")):
        if rng.random() < 0.9:
            d[key] = good if rng.random() < 0.85 else odd(rng)
    for key in rng.sample(JOB_FIELDS, rng.choice([0, 0, 1, 2, 3])):
        d[key] = copy.deepcopy(rng.choice(JOB_VALUES)) if rng.random() < 0.7 else odd(rng)
    return json.dumps(d)


def _tree(root: Path) -> dict:
    return {str(p.relative_to(root)): p.read_bytes() if p.is_file() else None for p in sorted(root.rglob("*"))}


def batch(rng: random.Random, c: Counts, tmp: Path) -> None:
    """rtloop-fit --batch on a few random job lines, in a folder with a file the batch did not write: it fits
    or says one line; it writes only inside its output folder and deletes or changes nothing else."""
    root = tmp / "batch"
    shutil.rmtree(root, ignore_errors=True)
    (root / "out" / "keep").mkdir(parents=True)
    (root / "out" / "keep" / "notes.txt").write_text("keep me")
    (root / "jobs.jsonl").write_text("\n".join(job_line(rng) for _ in range(rng.randint(1, 3))) + "\n")
    flags = [] if rng.random() < 0.5 else rng.choice([["--warm-start"], ["--retry-failed"], ["--threads", str(odd(rng))],
                        ["--final-spp", str(odd(rng))], ["--population", str(odd(rng))]])
    before, top = {**_tree(tmp / "outside"), **_tree(root)}, set(os.listdir(tmp))
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = cli_batch.main(["--batch", str(root / "jobs.jsonl"), "--out", str(root / "out"), "--no-images",
                               "-q", "--generations", "1", "--population", "4", "--no-uncertainty", *flags])
    c.bump("batches")
    c.bump(f"batch_exit_{code}")
    if code not in (0, 1, 2) or len(err.getvalue().splitlines()) > 1 or "Traceback" in err.getvalue():
        c.bump("batch_not_one_line")
        print("batch output:", err.getvalue()[:300], file=sys.stderr)
    after = {**_tree(tmp / "outside"), **_tree(root)}
    if any(after.get(k, "gone") != v for k, v in before.items()):
        c.bump("batch_lost_files")
    if any(not k.startswith("out/") for k in set(after) - set(before)):
        c.bump("batch_wrote_outside")
    if set(os.listdir(tmp)) != top:
        c.bump("batch_wrote_outside")


def one(rng: random.Random, c: Counts, tmp: Path, first: dict, only: str | None = None) -> None:
    if only == "batch" or rng.random() < 0.03:
        batch(rng, c, tmp)
        c.bump("ok")
        return
    kind = rng.random()
    if kind < 0.1:  # mesh files, EXIF tags, rtloop-insert arguments
        [_mesh, _exif, _insert_cli][int(kind * 30)](rng, tmp)
    elif kind < 0.55:  # scenes
        scene = rtloop.load_scene(mutate(rng, rng.choice([BASE, LIGHTS_BASE])))
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
            # the norm: the photo's choice (its L2 refit on a noisy photo), the others, and bad ones
            "norm": rng.choice(["auto", "auto", "l1", "l2", "huber:0.05", "huber:-1", "L1", None]),
            # the number of lights: the one-light fit, the lights fit, the choice, and bad ones
            "lights": rng.choice([None, None, None, 1, 2, "auto", 0, 9, "2", 1.5]),
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
    ap.add_argument("--only", choices=["batch"], help="only job lines of rtloop-fit --batch")
    a = ap.parse_args()
    warnings.simplefilter("ignore")  # the library's warnings on odd images are expected here
    rng, c = random.Random(a.seed), Counts()
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        (tmp / "scene.json").write_text(json.dumps(BASE))
        rtloop.save_image(tmp / "photo.png", rtloop.render(BASE))
        (tmp / "outside").mkdir()  # the batch's neighbour: nothing in it may change
        (tmp / "outside" / "data.txt").write_text("keep me")
        (tmp / "objects.json").write_text(json.dumps([{"name": "b2", "shape": "sphere", "center": [0.3, 0.2, 0],
                                                       "radius": 0.2}]))
        first: dict = {}
        for _ in range(a.inputs):
            c.bump("inputs")
            try:
                one(rng, c, tmp, first, a.only)
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
        "batches",
        "batch_exit_0",
        "batch_exit_1",
        "batch_exit_2",
        "batch_not_one_line",
        "batch_lost_files",
        "batch_wrote_outside",
    ]:
        print(f"{k}: {c.get(k, 0)}")
    bad = sum(c.get(k, 0) for k in ["panics", "non_rtloop_exceptions", "nan_or_inf", "out_of_bounds",
                                    "batch_not_one_line", "batch_lost_files", "batch_wrote_outside"])
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
