"""The cases whose fits are pinned bit for bit while the core is restructured (one owner for every
formula): the four reference scenes with both protocols and synthetic scenes covering every path of the
fit (matte, glossy, directional, ambient (closed form), the two-stage fallback, sRGB loss, other norms, mask, noise, callbacks).

`python3 tests/pinned_cases.py` records `tests/fixtures/pinned_fits.json` from the code as it is;
`tests/test_pinned_fits.py` compares a fresh run with it. The values are the project's own outputs, pinned
only so that a refactor cannot change them unnoticed: they are not evidence of accuracy (other tests
compare with ground truth). Re-record only for a change that is meant to change results, and say so.
"""

from __future__ import annotations

import copy
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

import rtloop
from conftest import BALL_ON_FLOOR

REPO = Path(__file__).resolve().parents[1]
FIXTURE = REPO / "tests" / "fixtures" / "pinned_fits.json"
SHARED_SCENES = REPO.parent / "shared" / "scenes"
REFERENCE = ("noisy-blue", "red-ball-low-light", "two-balls", "yellow-ball")

BALL = BALL_ON_FLOOR


def _ball(**changes: Any) -> dict:
    d = copy.deepcopy(BALL)
    for key, value in changes.items():
        d[key] = value
    return d


def _start(truth: dict) -> dict:
    """The truth with its free albedos grey and the light moved: what a fit starts from."""
    d = copy.deepcopy(truth)
    for o in d["objects"]:
        if f"objects.{o['name']}.albedo" in d["fit"]:
            o["material"]["albedo"] = [0.5, 0.5, 0.5]
    if "position" in d["light"]:
        d["light"]["position"] = [0.0, 3.0, -2.0]
    return d


def synthetic_cases() -> list[dict]:
    """(id, truth, fit keyword arguments, photo damage) for every pinned synthetic case."""
    glossy = _ball()
    glossy["objects"][0]["material"].update(specular=0.6, shininess=40.0)
    glossy["fit"]["objects.ball.specular"] = {"min": 0, "max": 1}
    glossy["fit"]["objects.ball.shininess"] = {"min": 2, "max": 200}
    known_gloss = _ball()
    known_gloss["objects"][0]["material"].update(specular=0.5, shininess=30.0)
    known_floor = _ball()  # a free intensity over a fixed albedo: still the two-stage fallback
    del known_floor["fit"]["objects.floor.albedo"]
    directional = _ball(light={"type": "directional", "direction": [0.4, 0.8, -0.3], "intensity": 3.0})
    directional["fit"] = {
        "light.direction": {"min": [-1, 0.05, -1], "max": [1, 1, 1]},
        "objects.ball.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]},
        "objects.floor.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]},
    }
    ambient = _ball(ambient=[0.05, 0.05, 0.06])
    ambient["fit"]["ambient"] = {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]}
    two = _ball()
    two["objects"].insert(1, {"name": "small", "shape": "sphere", "center": [1.7, 0.5, 0.4], "radius": 0.5,
                              "material": {"albedo": [0.2, 0.3, 0.9]}})
    two["fit"]["objects.small.albedo"] = {"min": [0, 0, 0], "max": [1, 1, 1]}
    low = _ball(light={"position": [-3.5, 1.2, 0.5], "intensity": 40.0, "color": [1, 0.9, 0.8]})
    bright = _ball(light={"position": [1.0, 3.0, -2.0], "intensity": 160.0, "color": [1, 1, 1]})
    half = np.zeros((48, 64), bool)
    half[:, :40] = True
    return [
        {"id": "matte", "truth": _ball(), "kw": {}},
        {"id": "matte-low-side-light", "truth": low, "kw": {}},
        {"id": "matte-saturated", "truth": bright, "kw": {}},
        {"id": "two-spheres", "truth": two, "kw": {}},
        {"id": "glossy-free", "truth": glossy, "kw": {}},
        {"id": "glossy-known", "truth": known_gloss, "kw": {}},
        {"id": "known-floor-fallback", "truth": known_floor, "kw": {}},
        {"id": "directional", "truth": directional, "kw": {}},
        {"id": "ambient", "truth": ambient, "kw": {}},
        {"id": "srgb-loss", "truth": _ball(), "kw": {"space": "srgb"}, "noise": 0.01},
        {"id": "l2-noise", "truth": _ball(), "kw": {"norm": "l2"}, "noise": 0.02},
        {"id": "huber", "truth": low, "kw": {"norm": "huber:0.05"}, "noise": 0.01},
        {"id": "masked", "truth": _ball(), "kw": {"mask": half}},
        {"id": "de-no-polish", "truth": _ball(), "kw": {"optimizer": "de", "polish": 0}},
        {"id": "no-clip", "truth": bright, "kw": {"clip": False}},
        {"id": "paper", "truth": _ball(), "kw": {"protocol": "paper", "generations": 40}},
        {"id": "paper-srgb", "truth": low, "kw": {"protocol": "paper", "generations": 30, "space": "srgb"}},
        {"id": "callback", "truth": glossy, "kw": {"callback": True}},
        {"id": "callback-fallback", "truth": known_floor, "kw": {"callback": True, "generations": 10}},
    ]


def _digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:32]


def _strip_seconds(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _strip_seconds(v) for k, v in value.items() if k != "seconds"}
    if isinstance(value, list):
        return [_strip_seconds(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value


def summarise(result: rtloop.FitResult, rows: list | None = None) -> dict:
    """Everything a fit returns but its timings, as JSON-able values (floats round-trip exactly)."""
    out = {
        "report": _strip_seconds(result.report()),
        "scene": result.scene.to_dict(),
        "history": [[[g, f, list(o), np.asarray(x).tolist()] for g, f, o, x in s.history] for s in result.stages],
        "stage_products": [_strip_seconds(s.products) for s in result.stages],
        "lit_pixels": [s.lit_pixels for s in result.stages],
    }
    if rows is not None:
        out["callback"] = [[r.stage, r.generation, r.fitness, list(r.objectives), r.params.tolist(),
                            r.evaluations] for r in rows]
    return json.loads(json.dumps(out))


def run_synthetic(case: dict) -> dict:
    truth = case["truth"]
    photo = rtloop.render(truth)
    out: dict[str, Any] = {"render": _digest(photo), "render_spp4": _digest(rtloop.render(truth, 96, 72, 4)),
                           "ids": _digest(rtloop.object_ids(truth))}
    if case.get("noise"):
        rng = np.random.default_rng(7)
        photo = np.clip(photo + rng.normal(0, case["noise"], photo.shape), 0, None).astype(np.float32)
    kw = dict(case["kw"])
    rows: list | None = None
    if kw.pop("callback", False):
        rows = []
        kw["callback"] = rows.append
    result = rtloop.fit(_start(truth), photo, seed=3, **kw)
    out["fit"] = summarise(result, rows)
    return out


def run_reference(name: str, protocol: str) -> dict:
    case = SHARED_SCENES / name
    scene = rtloop.load_scene(case / "scene_input.json")
    photo = rtloop.load_image(case / "objective.png", scene)
    return {"photo": _digest(photo), "fit": summarise(rtloop.fit(scene, photo, protocol=protocol, seed=1))}


def record() -> dict:
    data: dict[str, Any] = {"synthetic": {c["id"]: run_synthetic(c) for c in synthetic_cases()}, "reference": {}}
    if SHARED_SCENES.is_dir():
        for name in REFERENCE:
            for protocol in ("rtloop", "paper"):
                data["reference"][f"{name}/{protocol}"] = run_reference(name, protocol)
    return data


if __name__ == "__main__":
    FIXTURE.parent.mkdir(parents=True, exist_ok=True)
    data = record()
    if not data["reference"]:
        sys.exit(f"{SHARED_SCENES} not found: record with the reference scenes beside the repo")
    FIXTURE.write_text(json.dumps(data, indent=None, separators=(",", ":")) + "\n")
    print(f"wrote {FIXTURE} ({len(data['synthetic'])} synthetic, {len(data['reference'])} reference fits)")
