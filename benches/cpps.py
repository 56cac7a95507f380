"""Fitness throughput in candidate-pixels per second (CPPS), against a vectorised NumPy implementation.

    python benches/cpps.py [--out benches/results] [--quick]

Measured in one run on this machine, so the ratios stand even when absolute times are noisy:
  1. CPPS of rtloop's fused stage-1 fitness (render + L1 against the objective, whole population in one
     call into Rust) on 1 thread and on all threads, on the paper's yellow-ball scene at 128x96;
  2. the same fitness written the way a competent NumPy user would (first hits precomputed once,
     broadcasting over the population and the pixels, no Python loop over pixels) -> the speed-up ratio;
  3. the whole paper protocol (60 x (200 + 200)) through ``rtloop.fit`` with its wall time, the errors it
     reached against the ground truth, and the default protocol for comparison;
  4. memory: resident set size during a long fit (flat: nothing grows per generation) and peak RSS;
  5. cost against pixels x candidates: 128x96, 256x192 and 640x480 with 1, 3 and 8 spheres.
Writes ``cpps.md`` (the tables) into ``--out``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np

import rtloop
from rtloop import _native
from rtloop._files import write_text

REPO = Path(__file__).resolve().parents[1]
SCENE = REPO / "examples" / "yellow-ball"
SHARED = REPO.parent / "shared"


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


# ----------------------------------------------------------------------------------- NumPy reference


class NumpyFitness:
    """Stage-1 fitness (light position + intensity free, albedos fixed) for a whole population in NumPy."""

    def __init__(self, scene: dict, target: np.ndarray):
        h, w = scene["image"]["height"], scene["image"]["width"]
        cam = scene["camera"]
        pos = np.array(cam["position"], float)
        fwd = np.array(cam["look_at"], float) - pos
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, cam.get("up", [0, 1, 0]))
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        th = np.tan(np.radians(cam["vfov_deg"]) / 2)
        i, j = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        x = (2 * i / w - 1) * th * w / h
        y = (1 - 2 * j / h) * th
        d = fwd + x[..., None] * right + y[..., None] * up
        d = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
        # First hits, once per fit (not timed).
        t_best = np.full(len(d), np.inf)
        obj = np.full(len(d), -1)
        normal = np.zeros_like(d)
        for k, o in enumerate(scene["objects"]):
            if o["shape"] == "sphere":
                oc = pos - np.array(o["center"], float)
                b = d @ oc
                c = oc @ oc - o["radius"] ** 2
                disc = b * b - c
                t = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
                t = np.where(t > 0, t, np.inf)
            else:
                n = np.array(o["normal"], float)
                n /= np.linalg.norm(n)
                den = d @ n
                with np.errstate(divide="ignore", invalid="ignore"):
                    t = (np.array(o["point"], float) - pos) @ n / den
                t = np.where((t > 0) & np.isfinite(t), t, np.inf)
            closer = t < t_best
            t_best = np.where(closer, t, t_best)
            obj = np.where(closer, k, obj)
        hit = obj >= 0
        p = pos + d * t_best[:, None]
        for k, o in enumerate(scene["objects"]):
            m = obj == k
            if o["shape"] == "sphere":
                normal[m] = (p[m] - np.array(o["center"], float)) / o["radius"]
            else:
                n = np.array(o["normal"], float) / np.linalg.norm(o["normal"])
                normal[m] = np.where((d[m] @ n)[:, None] > 0, -n, n)
        self.p, self.n, self.obj = p[hit].astype(np.float32), normal[hit].astype(np.float32), obj[hit]
        self.albedo = np.array([o["material"]["albedo"] for o in scene["objects"]], np.float32)[self.obj]
        self.target = target.reshape(-1, 3)[hit]
        self.background_loss = np.abs(target.reshape(-1, 3)[~hit]).sum()
        self.spheres = [(np.array(o["center"], np.float32), o["radius"], k)
                        for k, o in enumerate(scene["objects"]) if o["shape"] == "sphere"]
        self.planes = [(np.array(o["normal"], np.float32) / np.linalg.norm(o["normal"]),
                        np.array(o["point"], np.float32), k)
                       for k, o in enumerate(scene["objects"]) if o["shape"] == "plane"]

    def __call__(self, pop: np.ndarray) -> np.ndarray:
        light = pop[:, None, :3].astype(np.float32)                  # (N, 1, 3)
        intensity = pop[:, None, 3:4].astype(np.float32)             # (N, 1, 1)
        dv = light - self.p[None]                                    # (N, P, 3)
        d2 = np.einsum("npk,npk->np", dv, dv)
        nl = np.maximum(np.einsum("npk,pk->np", dv, self.n), 0)
        e = nl / (d2 * np.sqrt(d2))
        for c, r, k in self.spheres:                                 # shadow rays (segment vs sphere)
            oc = self.p - c
            b = np.einsum("npk,pk->np", dv, oc)
            cc = np.einsum("pk,pk->p", oc, oc) - r * r
            disc = b * b - d2 * cc
            ab = d2 + b
            hit = (disc >= 0) & ((b < 0) | (cc < 0)) & ((ab > 0) | (disc > ab * ab)) & (self.obj != k)
            e = np.where(hit, 0, e)
        for n, q, k in self.planes:
            side_p = (self.p - q) @ n
            side_l = (light[:, 0] - q) @ n
            e = np.where((side_p[None] * side_l[:, None] < 0) & (self.obj != k), 0, e)
        m = np.minimum(intensity * e[..., None] * self.albedo[None] / np.pi, 1)
        return np.abs(m - self.target[None]).sum(axis=(1, 2)) + self.background_loss


# ----------------------------------------------------------------------------------------- helpers


def scene_with_spheres(k: int, width: int, height: int) -> dict:
    d = json.loads((SCENE / "scene.json").read_text())
    d["image"] = {"width": width, "height": height}
    ball = d["objects"][0]
    spheres = []
    for s in range(k):
        a = 2 * np.pi * s / k
        r = 1.0 if k == 1 else 0.45
        centre = [0.0, 1.0, 0.0] if k == 1 else [1.5 * np.cos(a), r, 1.5 * np.sin(a)]
        spheres.append({**ball, "name": f"ball{s}", "center": centre, "radius": r})
    d["objects"] = spheres + d["objects"][1:]
    d["fit"] = {"light.position": d["fit"]["light.position"], "light.intensity": d["fit"]["light.intensity"]}
    return d


def population(scene, n: int, seed: int = 1) -> np.ndarray:
    b = np.array(scene.bounds())
    return b[:, 0] + (b[:, 1] - b[:, 0]) * np.random.default_rng(seed).random((n, len(b)))


def rtloop_cpps(scene, target, pop, threads: int, repeats: int) -> float:
    spec = _native.FitnessSpec(scene.fit_paths)
    secs = best_of(lambda: _native.evaluate(scene, target, pop, spec, threads=threads), repeats)
    return len(pop) * scene.width * scene.height / secs


def score(result_scene, truth_path: Path) -> dict:
    spec = importlib.util.spec_from_file_location("score_result", SHARED / "tools" / "score_result.py")
    if spec is None or not (SHARED / "tools" / "score_result.py").is_file():
        return {}
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.score(result_scene.to_dict(), json.loads(truth_path.read_text()))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=REPO / "benches" / "results")
    ap.add_argument("--quick", action="store_true", help="fewer repeats, no 640x480 row")
    args = ap.parse_args(argv)
    repeats = 3 if args.quick else 7
    threads_all = os.cpu_count() or 1
    lines = [(f"machine: {platform.machine()} {platform.processor() or ''}, {threads_all} logical CPUs, "
             f"Python {platform.python_version()}, numpy {np.__version__}, rtloop {rtloop.__version__}"), ""]

    def say(s=""):
        print(s, flush=True)
        lines.append(s)

    # 1-2. CPPS against NumPy, one run.
    truth = json.loads((SCENE / "scene.json").read_text())
    scene = rtloop.load_scene(truth)
    fit_paths = ["light.position", "light.intensity"]
    stage1 = rtloop.load_scene({**truth, "fit": {p: truth["fit"][p] for p in fit_paths}})
    target = np.minimum(rtloop.render(scene), 1).astype(np.float32)
    pop = population(stage1, 600)
    np_fit = NumpyFitness(truth, target)
    ours = _native.evaluate(stage1, target, pop[:60], _native.FitnessSpec(fit_paths), threads=1)[:, 0]
    theirs = np_fit(pop[:60])
    agree = float(np.max(np.abs(ours - theirs) / np.maximum(theirs, 1)))
    pixels = scene.width * scene.height
    np_secs = best_of(lambda: np_fit(pop[:60]), repeats)
    np_cpps = 60 * pixels / np_secs
    c1 = rtloop_cpps(stage1, target, pop, 1, repeats)
    cn = rtloop_cpps(stage1, target, pop, threads_all, repeats)
    say("## Stage-1 fitness, yellow-ball 128x96, population evaluated in one call")
    say()
    say("| implementation | threads | CPPS | us per candidate | vs NumPy |")
    say("|---|---|---|---|---|")
    say(f"| NumPy (vectorised over population and pixels) | 1 | {np_cpps:.3g} | {1e6 * pixels / np_cpps:.0f} | 1x |")
    say(f"| rtloop | 1 | {c1:.3g} | {1e6 * pixels / c1:.1f} | {c1 / np_cpps:.0f}x |")
    say(f"| rtloop | {threads_all} | {cn:.3g} | {1e6 * pixels / cn:.1f} | {cn / np_cpps:.0f}x |")
    say()
    say(f"Largest relative difference between the two implementations' losses: {agree:.1e}.")
    say()

    # 3. Whole protocols with their errors; 4. memory.
    say("## Whole fits on the yellow-ball example (objective.png, Mitsuba 3 render), rtloop.fit")
    say()
    say("| protocol | evaluations | wall s | light error m | product error (max) | peak RSS MB |")
    say("|---|---|---|---|---|---|")
    photo_scene = rtloop.load_scene(SCENE / "scene_input.json")
    photo = rtloop.load_image(SCENE / "objective.png", photo_scene)
    for protocol in ("paper", "rtloop"):
        rtloop.fit(photo_scene, photo, protocol=protocol, generations=2)  # warm up
        t = time.perf_counter()
        r = rtloop.fit(photo_scene, photo, protocol=protocol, seed=0)
        wall = time.perf_counter() - t
        s = score(r.scene, SCENE / "scene.json")
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        err = f"{s['light_err_m']:.4f}" if s else "n/a"
        perr = f"{max(s['product_rel_err'].values()):.4f}" if s else "n/a"
        say(f"| {protocol} | {r.evaluations} | {wall:.3f} | {err} | {perr} | {peak:.0f} |")
    say()
    samples = []
    rtloop.fit(photo_scene, photo, protocol="paper", generations=(1000, 10),
               callback=lambda g: samples.append(rss_mb()) if g.generation % 100 == 0 else None)
    say(f"RSS during a 1000-generation stage 1 (sampled every 100 generations): "
        f"{', '.join(f'{v:.1f}' for v in samples[:11])} MB (growth {samples[-1] - samples[1]:+.1f} MB).")
    say()

    # 5. Scaling.
    say("## Cost against pixels x candidates (stage-1 fitness, all threads)")
    say()
    say("| image | spheres | candidate-pixels / s | us per candidate | ns per candidate-pixel |")
    say("|---|---|---|---|---|")
    sizes = [(128, 96), (256, 192)] + ([] if args.quick else [(640, 480)])
    for w, h in sizes:
        for k in (1, 3, 8):
            d = scene_with_spheres(k, w, h)
            s = rtloop.load_scene(d)
            t = np.minimum(rtloop.render(s), 1).astype(np.float32)
            n = max(60, int(600 * 12288 / (w * h)))
            cpps = rtloop_cpps(s, t, population(s, n), threads_all, repeats)
            say(f"| {w}x{h} | {k} | {cpps:.3g} | {1e6 * w * h / cpps:.0f} | {1e9 / cpps:.2f} |")
    out = args.out / ("cpps_quick.md" if args.quick else "cpps.md")
    write_text(out, "\n".join(lines) + "\n", parents=True)
    print(f"\nwrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
