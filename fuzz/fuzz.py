"""A fuzz campaign over the Python API (scenes, render()/fit() arguments, image arrays, CLI arguments via
main() in-process, batch job lines and ids via rtloop-fit --batch, mesh files, EXIF focal tags,
rtloop-insert arguments (those three and the odd values in fuzz/files.py), rtloop-scene's --strict refusal of a field of view estimated from the board alone)
for a developer to run for minutes; prints the counts. ``--only SURFACE[,SURFACE...]`` runs only those
surfaces (``batch``: job lines, ``ids``: job ids, ``mesh``, ``insert``, ``exif``, ``strict``, ``framing``: warped
photos through fit()'s framing check and correction, ``lights``: the lights fit with a rectangle light's size
free, fuzz/lights_size.py, ``default_lights``: the default fit's number of lights on photos with a second
light, fuzz/default_lights.py, ``fitness_spec``: the native fitness spec and the calls that take it,
fuzz/fitness_spec.py), each input on
the next in turn; ``--out FILE`` also writes the counts per surface as markdown headed by the command.

What counts as a finding, by kind: ``data loss`` (a batch that deleted, changed or wrote beside its folder,
rtloop-insert writing beside --out or losing an input, rtloop-scene writing beside --out), ``wrong answers
reported as ok`` (a non-finite or out-of-bounds fit, a non-positive focal length from EXIF, --strict passing a
field of view looser than its target or one the plain estimate refuses, rtloop-scene exiting 0 with
--strict on a board-only estimate looser than the target), ``tracebacks`` (an exception other than
RtloopError, a panic, a command's error that is not one line), ``hangs`` (an input that took longer than
``--bound`` seconds). Not a test: see docs/development.md."""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import math
import os
import platform
import random
import shutil
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

import numpy as np

import rtloop
from rtloop.cli import batch as cli_batch
from rtloop.cli import fit as cli_fit

sys.path.insert(0, str(Path(__file__).resolve().parent))
from default_lights import default_lights  # noqa: E402
from files import ODD, exif, insert_cli, lens, mesh, odd  # noqa: E402
from fitness_spec import fitness_spec  # noqa: E402
from lights_size import lights_size  # noqa: E402

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
    """The base under a `lights` list: its lamp, a sphere fill light, a sun and a window (a rectangle light),
    with their paths freed (the window's centre and size)."""
    d = copy.deepcopy(base)
    lamp = d.pop("light")
    d["lights"] = [{"name": "key", **lamp},
                   {"name": "fill", "type": "sphere", "position": [-2.0, 3.0, -1.0], "radius": 0.3, "intensity": 5.0},
                   {"name": "sun", "type": "directional", "direction": [0.2, 1.0, 0.1], "intensity": 0.2},
                   {"name": "window", "type": "rectangle", "position": [-3.0, 2.0, 1.0], "size": [1.5, 1.0],
                    "normal": [1.0, -0.3, -0.2], "up": [0.0, 1.0, 0.0], "intensity": 4.0}]
    d["fit"]["lights.window.position"] = {"min": [-5, 0.5, -3], "max": [-1, 4, 3]}
    d["fit"]["lights.window.size"] = {"min": 0.3, "max": 3.0}
    d["fit"]["lights.fill.position"] = {"min": [-4, 0.5, -4], "max": [4, 6, 4]}
    d["fit"]["lights.fill.radius"] = {"min": 0.01, "max": 1.0}
    d["fit"]["lights.sun.intensity"] = {"min": 0, "max": 1}
    return d


def _coat_base(base: dict) -> dict:
    """The base with its first object coated (``material.coat``), its roughness and specular weight free."""
    d = copy.deepcopy(base)
    first = d["objects"][0]
    first["material"] = {**first.get("material", {}), "specular": 0.8, "coat": {"roughness": 0.15, "ior": 1.5}}
    d["fit"][f"objects.{first['name']}.roughness"] = {"min": 0.05, "max": 0.5}
    d["fit"][f"objects.{first['name']}.specular"] = {"min": 0, "max": 2}
    return d


BASE = _base()
LIGHTS_BASE = _lights_base(BASE)
COAT_BASE = _coat_base(BASE)
FIT_SCENES = _fit_scenes(BASE)


def _framing_base() -> dict:
    """tests/fixtures/photos/direct-two-balls' scene as a user writes it, at 64 x 48: two outlines."""
    d = json.loads((REPO / "tests" / "fixtures" / "photos" / "direct-two-balls" / "scene.json").read_text())
    d["image"] = {"width": 64, "height": 48}
    return d


FRAMING_BASE = _framing_base()
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


def _mesh(rng: random.Random, tmp: Path) -> None:
    mesh(rng, tmp, BASE)


JOB_IDS = ["a", "b-1", "keep", "results.jsonl", "../out", "/tmp", ".hidden", "", "a/b", "..", "x" * 129, "ok.1",
           ".rtloop-batch.lock", "f0", 7]
JOB_FIELDS = ["seed", "mask", "protocol", "population", "generations", "f", "cr", "norm", "space", "loss_space",
              "optimizer", "polish", "clip", "uncertainty", "pixels_per_object", "environment", "interreflection",
              "highlights", "footprint", "framing", "vignetting", "tone", "lights", "response", "crop", "grey_card",
              "image",
              "bogus"]
JOB_VALUES = [*ODD, "auto", "on", "off", "silhouette", "srgb", "linear", "paper", "l2", "bootstrap", "check", "correct", 2, 9, [1, 1], [2, "x"], [-0.3, -0.05], [0, 1e400],
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


def run_quietly(main, argv: list[str]) -> tuple[int | str | None, str]:
    """A command line's ``main(argv)`` with its stdout dropped: (exit status, what it wrote on stderr); argparse's
    ``SystemExit`` is its exit status."""
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as e:
            code = e.code
    return code, err.getvalue()


def _tree(root: Path) -> dict:
    return {str(p.relative_to(root)): p.read_bytes() if p.is_file() else None for p in sorted(root.rglob("*"))}


def batch(rng: random.Random, c: Counts, tmp: Path, ids: bool = False) -> None:
    """rtloop-fit --batch on a few random job lines (``ids``: lines that differ in their ids), in a folder with
    a file the batch did not write: it fits or says one line; it writes only inside its output folder and
    deletes or changes nothing else."""
    root = tmp / "batch"
    shutil.rmtree(root, ignore_errors=True)
    (root / "out" / "keep").mkdir(parents=True)
    (root / "out" / "keep" / "notes.txt").write_text("keep me")
    lines = id_lines(rng) if ids else [job_line(rng) for _ in range(rng.randint(1, 3))]
    (root / "jobs.jsonl").write_text("\n".join(lines) + "\n")
    flags = [] if rng.random() < 0.5 else rng.choice([["--warm-start"], ["--retry-failed"], ["--threads", str(odd(rng))],
                        ["--final-spp", str(odd(rng))], ["--population", str(odd(rng))], ["--processes"],
                        ["--processes", "--warm-start"], ["--processes", "--workers", str(odd(rng))]])
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


def id_lines(rng: random.Random) -> list[str]:
    """Job lines that differ in their ids: odd ones, repeated ones, ids that name files or folders."""
    ids = [rng.choice(JOB_IDS) if rng.random() < 0.8 else odd(rng) for _ in range(rng.randint(1, 4))]
    if rng.random() < 0.3:
        ids.append(ids[0])  # a repeated id
    return [json.dumps({"id": i, "scene": "../scene.json", "photo": "../photo.png"}) for i in ids]


STRICT_FLAGS = ["--strict", "--vfov", "--ball", "--ball-radius", "--ball-free", "--force", "--width",
                "--board-thickness"]


def _strict_estimate(rng: random.Random, c: Counts) -> None:
    """The board-only field of view on projected corners (any view, tilt, noise, corners missing): --strict
    passes only an estimate within the target, the plain one's, and refuses whatever the plain one refuses."""
    import cv2

    from rtloop.acquisition import AcquisitionError
    from rtloop.acquisition.boards import BoardDetection
    from rtloop.acquisition.camera import centred_camera_matrix, focal_from_vfov
    from rtloop.acquisition.pose import VFOV_LIMIT_DEG, VFOV_TARGET_DEG, estimate_focal_from_board

    w, h = rng.choice([(800, 600), (64, 48), (4032, 3024), (600, 800)])
    gx, gy = np.meshgrid(np.arange(rng.randint(2, 9)), np.arange(rng.randint(2, 7)))
    obj = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)]) * rng.choice([0.01, 0.06, 0.3])
    keep = sorted(rng.sample(range(len(obj)), rng.randint(min(3, len(obj)), len(obj))))
    tilt = math.radians(rng.choice([0.0, 0.3, rng.uniform(0, 80)]))
    k = centred_camera_matrix(focal_from_vfov(rng.uniform(5, 120), h), w, h)
    img, _ = cv2.projectPoints(obj[keep] - obj.mean(axis=0), np.array([tilt, rng.uniform(-0.3, 0.3), 0.0]),
                               np.array([0.0, 0.0, rng.uniform(0.1, 10)]), k, np.zeros(5))
    noise = rng.choice([0.0, 0.05, 0.3, 1.0, rng.uniform(0, 20)])
    img = img.reshape(-1, 2) + np.random.default_rng(rng.randrange(2**32)).normal(0, noise, (len(keep), 2))
    det = BoardDetection(img.astype(np.float32), obj[keep].astype(np.float32), np.array(keep))
    got = {}
    for strict in (False, True):
        try:
            got[strict] = estimate_focal_from_board(det, w, h, strict=strict)
        except AcquisitionError as e:
            if "\n" in str(e) or "--vfov" not in str(e):
                c.bump("traceback_not_one_line")
            got[strict] = None
    c.bump("strict_used" if got[True] is not None else "strict_refused")
    if got[True] is not None and not (got[True] == got[False] and math.isfinite(got[True][0])
                                      and got[True][0] > 0 and got[True][1] <= VFOV_TARGET_DEG):
        c.bump("wrong_ok")
        print("--strict passed", got, file=sys.stderr)
    if got[False] is not None and not (math.isfinite(got[False][0]) and got[False][1] <= VFOV_LIMIT_DEG):
        c.bump("wrong_ok")


def _strict_cli(rng: random.Random, c: Counts, tmp: Path) -> None:
    """rtloop-scene on a photo without EXIF, --strict and the other camera and ball flags at random: exit 0, 1
    or 2 with one line, nothing beside --out; a scene made with --strict from the board alone is within the
    target."""
    from rtloop.acquisition.pose import VFOV_TARGET_DEG
    from rtloop.cli.scene import scene_main

    work = tmp / "scn"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    argv = [str(tmp / "board_photo.png"), "--board", SCENE_BOARD, "--ball-radius", "0.08", "--out", str(work / "o"),
            "--width", "80"]
    strict = rng.random() < 0.7
    if strict:
        argv.append("--strict")
    for _ in range(rng.randint(0, 2)):
        flag = rng.choice(STRICT_FLAGS[1:])
        value = rng.choice([str(odd(rng)), "50", "0.08", "400,300,40", "x", "0", "0.5mm"])
        argv += [flag] if flag in ("--force", "--ball-free") else [flag, value]
    code, text = run_quietly(scene_main, argv)
    c.bump(f"scene_exit_{code}")
    if code not in (0, 1, 2) or "Traceback" in text or (code == 1 and len(text.strip().splitlines()) != 1):
        c.bump("traceback_not_one_line")
        print("rtloop-scene:", code, text[:300], file=sys.stderr)
    if set(os.listdir(work)) - {"o"}:
        c.bump("data_loss")
    if code == 0 and strict:
        meta = json.loads((work / "o" / "scene.json").read_text())["meta"]["acquisition"]
        std = (meta.get("pose") or {}).get("vfov_std_deg")
        if meta.get("camera_model") == "board" and not (std is not None and std <= VFOV_TARGET_DEG):
            c.bump("wrong_ok")
            print("--strict made a scene from a loose board estimate:", std, file=sys.stderr)


def _strict(rng: random.Random, c: Counts, tmp: Path) -> None:
    if rng.random() < 0.05:
        _strict_cli(rng, c, tmp)
    else:
        _strict_estimate(rng, c)


def _coat(rng: random.Random, c: Counts) -> None:
    """A coated scene mutated (its coat's fields most often) through load_scene and render, or fitted by
    default (the lobe chosen from the photo) to a render of a coated ball under another light, with noise."""
    d = copy.deepcopy(COAT_BASE)
    coat = d["objects"][0]["material"]["coat"]
    if rng.random() < 0.5:
        for _ in range(rng.randint(1, 3)):
            coat[rng.choice(["roughness", "ior", "other"])] = odd(rng) if rng.random() < 0.6 else rng.uniform(-1, 4)
        if rng.random() < 0.2:
            d = mutate(rng, d)
        img = rtloop.render(rtloop.load_scene(d), width=rng.choice([None, 5]), height=None, spp=1)
        if not finite(img):
            c.bump("nan_or_inf")
        return
    truth = copy.deepcopy(d)
    truth["objects"][0]["material"]["coat"]["roughness"] = rng.choice([0.03, 0.1, 0.3, 0.9])
    box = truth["fit"]["light.position"]
    truth["light"]["position"] = [rng.uniform(lo, hi) for lo, hi in zip(box["min"], box["max"])]
    arr = rtloop.render(d if rng.random() < 0.5 else truth)
    arr = arr + np.random.default_rng(rng.randrange(2**32)).normal(0, rng.choice([0, 0.01]), arr.shape)
    user = copy.deepcopy(BASE)  # the user's scene: a matte ball; the fit tries the coat where it shows
    scene = user if rng.random() < 0.7 else d
    res = rtloop.fit(scene, np.maximum(arr, 0).astype(np.float32), protocol="rtloop", seed=rng.randrange(100),
                     population=8, generations=1)
    check_fit(res, scene, c)


def _framing(rng: random.Random, c: Counts) -> None:
    """A photo of the two-ball scene turned, zoomed and shifted by a random warp (or noise, or a constant),
    fitted with a random framing mode: it fits (finite, within bounds, the framing's numbers finite) or
    says one line."""
    import cv2

    scene = copy.deepcopy(FRAMING_BASE)
    photo = rtloop.render(scene, spp=4)
    h, w = photo.shape[:2]
    kind = rng.random()
    if kind < 0.7:
        turn, zoom = rng.uniform(-8, 8), math.exp(rng.uniform(-0.2, 0.2))
        m = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), turn, zoom)
        m[:, 2] += [rng.uniform(-6, 6), rng.uniform(-6, 6)]
        photo = cv2.warpAffine(photo, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    elif kind < 0.85:
        photo = np.random.default_rng(rng.randrange(2**32)).uniform(0, 1, photo.shape).astype(np.float32)
    else:
        photo = np.full(photo.shape, rng.choice([0.0, 0.5, 1.0]), np.float32)
    mode = rng.choice(["check", "correct", "correct", "off", "bogus"])
    res = rtloop.fit(scene, np.ascontiguousarray(photo, np.float32), framing=mode, population=8,
                     generations=rng.choice([1, 3]), polish=20, uncertainty=rng.choice([False, True]))
    check_fit(res, scene, c)
    f = res.goodness.get("framing", {})
    numbers = [v for k in ("outline_rms_px", "outline_rms_se_px", "roll_deg", "zoom_percent") if k in f for v in [f[k]]]
    numbers += list(f.get("shift_px", []))
    if not finite(numbers):
        c.bump("nan_or_inf")
    if f.get("corrected") and not finite(res.reframed[0]):
        c.bump("nan_or_inf")


def fov_record(base: dict) -> dict:
    """A scene's ``meta.acquisition.field_of_view`` as rtloop-scene writes it: the camera and the ball's
    centre at one standard deviation either side of the field of view."""
    cam, ball = base["camera"], base["objects"][0]
    return {"vfov_deg": cam["vfov_deg"], "std_deg": 1.0, "alternates": [
        {"vfov_deg": cam["vfov_deg"] + k, "camera": {**cam, "vfov_deg": cam["vfov_deg"] + k,
                                                    "position": [v * (1 + 0.02 * k) for v in cam["position"]]},
         "objects": {ball["name"]: {"center": [v + 0.01 * k for v in ball["center"]]}}} for k in (-1, 1)]}


def _fov(rng: random.Random, c: Counts, tmp: Path) -> None:
    """A scene file whose field-of-view record (rtloop-scene's, for a photo without EXIF) is mutated, fitted
    from files as rtloop-fit fits it: the bars finite (or None) with the field of view carried, or one line."""
    from rtloop.fit.files import fit_inputs, load_inputs

    record = fov_record(BASE)
    if rng.random() < 0.8:
        record = mutate(rng, {"field_of_view": record}).get("field_of_view") if rng.random() < 0.9 else odd(rng)
    path = tmp / "fov-scene.json"
    path.write_text(json.dumps({**BASE, "meta": {"acquisition": {"field_of_view": record}}}))
    res = fit_inputs(load_inputs(path, tmp / "photo.png"), seed=rng.randrange(100), population=8,
                     generations=1, uncertainty=rng.random() < 0.8)
    check_fit(res, BASE, c)
    bars = (res.uncertainty or {}).get("bars") or {}
    values = [v for v in (bars.get("sigma") or {}).values() if v is not None]
    values += list(((bars.get("field_of_view") or {}).get("shift") or {}).values())
    if not finite(values):
        c.bump("nan_or_inf")


SURFACES = ("batch", "ids", "mesh", "insert", "exif", "strict", "framing", "coat", "fov", "lens", "lights",
            "default_lights", "fitness_spec")


def one(rng: random.Random, c: Counts, tmp: Path, first: dict, only: str | None = None) -> None:
    if only is not None:
        c.bump(f"inputs_{only}")
        if only in ("batch", "ids"):
            batch(rng, c, tmp, ids=only == "ids")
        else:
            {"mesh": _mesh, "insert": insert_cli, "exif": exif, "strict": lambda r, t: _strict(r, c, t),
             "framing": lambda r, t: _framing(r, c),
             "coat": lambda r, t: _coat(r, c), "fov": lambda r, t: _fov(r, c, t),
             "lens": lens,
             "lights": lambda r, t: lights_size(r, c, LIGHTS_BASE, mutate, odd, check_fit),
             "default_lights": lambda r, t: default_lights(r, c, FIT_SCENES, mutate, check_fit, finite),
             "fitness_spec": lambda r, t: fitness_spec(r, c, FIT_SCENES, odd, finite),
             }[only](rng, tmp)
        c.bump("ok")
        return
    if rng.random() < 0.03:
        batch(rng, c, tmp)
        c.bump("ok")
        return
    kind = rng.random()
    if kind < 0.1:  # mesh files, EXIF tags, rtloop-insert arguments
        [_mesh, exif, insert_cli][int(kind * 30)](rng, tmp)
    elif kind < 0.13:  # the native fitness spec and the calls that take it
        fitness_spec(rng, c, FIT_SCENES, odd, finite)
    elif kind < 0.55:  # scenes
        scene = rtloop.load_scene(mutate(rng, rng.choice([BASE, LIGHTS_BASE, COAT_BASE])))
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
            # the framing check and its correction, and bad values
            "framing": rng.choice(["check", "check", "check", "correct", "off", "CHECK", None, 1]),
        }
        # the camera (one fit in five): the photo's choice, forced, off, a given falloff, and bad ones
        if rng.random() < 0.2:
            opts["vignetting"] = rng.choice(["on", "on", "off", (-0.3, -0.05), (0.0, 0.0), (-3.0, 0.0),
                                             (math.nan, 0.0), "0.1,0.2", None])
        if rng.random() < 0.2:
            opts["tone"] = rng.choice(["on", "on", "off", "linear", "srgb", None])
        if rng.random() < 0.2:  # the pixel footprint: the outline gate's choice, forced, the others, bad ones
            opts["footprint"] = rng.choice(["auto", "silhouette", "silhouette", "on", "off", True, "SILHOUETTE", 2])
        if opts["lights"] not in (None, 1) and rng.random() < 0.7:  # mostly the options the lights fit takes
            for key in ("norm", "vignetting", "tone"):
                opts.pop(key, None)
        if shape[:2] == (9, 12) and rng.random() < 0.1:
            flat = np.random.default_rng(rng.randrange(2**32)).uniform(-0.1, 1.2, (9, 12, 3))
            opts["flat_field"] = flat.astype(rng.choice([np.float32, np.float64, np.uint8]))
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
            if rng.random() < 0.5:  # as a linear 16-bit file stores it: the default norm's L2 refit
                arr = (np.round(np.clip(arr, 0.0, 1.0) * 65535) / 65535).astype(np.float32)
        res = rtloop.fit(scene, arr, protocol="rtloop", **opts)
        check_fit(res, scene, c)
    else:  # CLI arguments via main()
        argv = [str(tmp / "scene.json"), str(tmp / "photo.png"), "--out", str(tmp / "out")]
        flags = ["--seed", "--population", "--generations", "--threads", "--norm", "--space", "--protocol",
                 "--framing", "--vignetting", "--tone-curve", "--flat-field"]
        for _ in range(rng.randint(0, 3)):
            argv += [rng.choice(flags), str(odd(rng))]
        if rng.random() < 0.2:  # the lights fit: counts, "auto" and bad ones
            argv += ["--lights", rng.choice(["1", "2", "auto", "0", "9", "x", "2.5", "", str(odd(rng))])]
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            try:
                cli_fit.main(argv)
            except SystemExit as e:  # argparse's usage errors exit 2
                if e.code not in (0, 1, 2):
                    raise
    c.bump("ok")


SCENE_BOARD = "6x4,70mm,52mm,DICT_5X5_100"


def _board_photo(path: Path) -> None:
    """A photo without EXIF of a ball beside a ChArUco board on the floor (rtloop-scene's input)."""
    from rtloop.acquisition import PinholeCamera
    from rtloop.acquisition._common import write_png16_srgb
    from rtloop.acquisition.boards import parse_board
    from rtloop.acquisition.synthetic import paste_board_on_floor

    w, h = 800, 600
    scene = {"image": {"width": w, "height": h},
             "camera": {"position": [0.25, 0.6, -0.8], "look_at": [0.08, 0.0, 0.05], "vfov_deg": 50},
             "light": {"position": [-0.5, 1.4, -0.6], "intensity": 4.0}, "ambient": [0.03] * 3,
             "objects": [{"name": "ball", "shape": "sphere", "center": [0.36, 0.08, 0.12], "radius": 0.08,
                          "material": {"albedo": [0.8, 0.6, 0.1]}},
                         {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
                          "material": {"albedo": [0.45, 0.45, 0.45]}}]}
    render = rtloop.render(scene, spp=4)
    cam = PinholeCamera.from_scene_camera(scene["camera"], w, h)
    write_png16_srgb(path, paste_board_on_floor(render, rtloop.object_ids(scene) == 1, 0.45,
                                                parse_board(SCENE_BOARD), cam))


#: The kinds of finding (the counts summed into each; all must be 0).
FINDINGS = {
    "data loss": ["batch_lost_files", "batch_wrote_outside", "data_loss"],
    "wrong answers reported as ok": ["nan_or_inf", "out_of_bounds", "wrong_ok"],
    "tracebacks": ["panics", "non_rtloop_exceptions", "batch_not_one_line", "traceback_not_one_line"],
    "hangs": ["hangs"],
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--inputs", type=int, default=100_000, help="generated inputs (default 100000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", metavar="SURFACE[,SURFACE...]",
                    help=f"only these surfaces, in turn: {', '.join(SURFACES)} (batch: job lines of rtloop-fit "
                    "--batch; ids: their job ids; strict: rtloop-scene's --strict; coat: coated scenes and fits)")
    ap.add_argument("--bound", type=float, default=60.0,
                    help="seconds past which one input counts as a hang (default 60)")
    ap.add_argument("--out", type=Path, metavar="FILE", help="also write the counts as markdown (e.g. "
                    "fuzz/results/fuzz.md), headed by the command")
    a = ap.parse_args()
    only = None if a.only is None else a.only.split(",")
    if only is not None and not set(only) <= set(SURFACES):
        ap.error(f"--only: surfaces are {', '.join(SURFACES)} (got {a.only})")
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
        _board_photo(tmp / "board_photo.png")
        first: dict = {}
        for i in range(a.inputs):
            c.bump("inputs")
            t0 = time.perf_counter()
            try:
                one(rng, c, tmp, first, None if only is None else only[i % len(only)])
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
            if time.perf_counter() - t0 > a.bound:
                c.bump("hangs")
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
        *(f"inputs_{s}" for s in SURFACES),
        "strict_used",
        "strict_refused",
        "scene_exit_0",
        "scene_exit_1",
        "scene_exit_2",
        "data_loss",
        "wrong_ok",
        "traceback_not_one_line",
        "hangs",
    ]:
        print(f"{k}: {c.get(k, 0)}")
    kinds = {kind: sum(c.get(k, 0) for k in keys) for kind, keys in FINDINGS.items()}
    if a.out is not None:
        _write_markdown(a.out, c, kinds, a.bound)
    return 1 if any(kinds.values()) else 0


def _write_markdown(path: Path, c: Counts, kinds: dict[str, int], bound: float) -> None:
    command = " ".join(["python", "fuzz/fuzz.py", *sys.argv[1:]])
    rows = [f"| {s} | {c.get(f'inputs_{s}', 0)} |" for s in SURFACES if c.get(f"inputs_{s}")]
    if not rows:
        rows = [f"| all (mixed) | {c.get('inputs', 0)} |"]
    text = "\n".join([
        f"# The fuzz campaign (`{command}`)",
        "",
        f"Machine: {platform.machine()}, {os.cpu_count()} logical CPUs, shared. Every input is checked as"
        " fuzz/fuzz.py's docstring says; a hang is an input that took more than"
        f" {bound:g} s.",
        "",
        "| surface | inputs |",
        "|---|---|",
        *rows,
        f"| **all** | {c.get('inputs', 0)} |",
        "",
        "| finding | count |",
        "|---|---|",
        *(f"| {kind} | {n} |" for kind, n in kinds.items()),
        "",
        "Outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(c.items()) if not k.startswith("inputs")) + ".",
        "",
    ])
    path.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    raise SystemExit(main())
