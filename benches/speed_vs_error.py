"""Speed against error: how long rtloop's fits take and how close they get, per protocol and budget.

For every reference scene (a folder holding ``scene_input.json``, ``objective.png`` and the ground truth
``scene.json``; by default ``../shared/scenes`` next to the repository), every method (a protocol of
``rtloop.fit``: ``paper`` at the paper's budget, ``rtloop`` the default) and every budget fraction, and
for a few seeds, this runs::

    scene = rtloop.load_scene(scene_input.json)
    photo = rtloop.load_image(objective.png, scene)
    result = rtloop.fit(scene, photo, protocol=method, population=..., generations=..., seed=...)

timing load + fit with ``time.perf_counter``, and scores ``rtloop.scene_to_dict(result.scene)`` against
``scene.json`` with ``score()`` from ``../shared/tools/score_result.py``: light position error (m), light
direction error (degrees, seen from the first sphere) and the worst relative error of intensity x albedo
over the objects.

A budget fraction b scales population x generations of the protocol by b: population and every stage's
generations are each scaled by sqrt(b) (population at least 5, generations at least 1). The population
and generations actually used, and the evaluations the fit reports, are in the CSV.

Usage (from the repository root, after ``pip install .[bench]``)::

    python benches/speed_vs_error.py                 # all scenes, paper + rtloop, budgets 0.05 to 1, 2 seeds
    python benches/speed_vs_error.py --quick         # smoke run: 1 seed, smallest budget
    python benches/speed_vs_error.py --scenes DIR --seeds 3 --budgets 0.5 1 --methods rtloop --out /tmp/b

Writes, atomically, to ``--out`` (default ``benches/results/``): ``speed_vs_error.csv`` (one row per run),
``speed_vs_error.md`` (the tables printed) and ``speed_vs_error.png`` (error against seconds, log-log:
light position error and worst product error, one marker per method and budget; needs matplotlib, else
skipped with a message). ``--quick`` writes ``speed_vs_error_quick.*`` instead. Prints a markdown table
(medians over seeds per scene, method and budget), a per-method summary (medians over scenes) and the
machine. Exits 0 with a message when the scenes or the scoring tool are absent.
"""

from __future__ import annotations

import argparse
import csv
import importlib
import importlib.util
import io
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
DEFAULT_SCENES = REPO.parent / "shared" / "scenes"
SCORE_TOOL = REPO.parent / "shared" / "tools" / "score_result.py"
DEFAULT_OUT = REPO / "benches" / "results"
DEFAULT_METHODS = ["paper", "rtloop"]
#: A method name ending in this runs the protocol without its Nelder-Mead polish, giving the polish's
#: evaluations to the search instead (e.g. ``rtloop-nopolish``).
NO_POLISH = "-nopolish"
DEFAULT_BUDGETS = [0.05, 0.1, 0.15, 0.2, 0.25, 0.35, 0.5, 1.0]
SCENE_FILES = ("scene_input.json", "objective.png", "scene.json")
#: Errors are drawn on log axes; exact zeros are drawn at this floor.
LOG_FLOOR = 1e-6

FIELDS = [
    "scene", "method", "budget", "seed", "population", "generations", "evaluations", "seconds",
    "fit_seconds", "light_err_m", "light_dir_err_deg", "product_err_max", "fit_method", "error",
]


def load_score(path: Path):
    """``score(result_dict, truth_dict)`` from the shared scoring tool, imported by path."""
    spec = importlib.util.spec_from_file_location("rtloop_bench_score_result", path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.score


def find_scenes(root: Path) -> list[Path]:
    return sorted(d for d in root.iterdir() if d.is_dir() and all((d / f).is_file() for f in SCENE_FILES))


def scaled_budget(proto: dict[str, Any], fraction: float) -> tuple[int, tuple[int, int], int | None]:
    """Population, per-stage generations and polish evaluations with population x generations (and the
    polish) scaled by ``fraction``; polish None where the protocol has none."""
    k = math.sqrt(fraction)
    population = max(5, round(proto["population"] * k))
    gens = proto["generations"]
    gens = (gens, gens) if isinstance(gens, int) else tuple(gens)
    polish = max(10, round(proto["polish"] * fraction)) if proto.get("polish") else None
    return population, (max(1, round(gens[0] * k)), max(1, round(gens[1] * k))), polish


def run_one(rtloop, score, scene_dir: Path, truth: dict, method: str, population: int,
            generations: tuple[int, int], seed: int, threads: int | None, polish: int | None = None,
            uncertainty: bool = False) -> dict[str, Any]:
    t0 = time.perf_counter()
    scene = rtloop.load_scene(scene_dir / "scene_input.json")
    photo = rtloop.load_image(scene_dir / "objective.png", scene)
    result = rtloop.fit(scene, photo, protocol=method.removesuffix(NO_POLISH), population=population,
                        generations=generations, seed=seed, threads=threads, polish=polish,
                        uncertainty=uncertainty)
    seconds = time.perf_counter() - t0
    s = score(rtloop.scene_to_dict(result.scene), truth)
    return {
        "evaluations": int(result.evaluations),
        "seconds": seconds,
        "fit_seconds": float(result.seconds),
        "light_err_m": s["light_err_m"],
        "light_dir_err_deg": s.get("light_dir_err_deg", float("nan")),
        "product_err_max": max(s["product_rel_err"].values(), default=float("nan")),
        "fit_method": result.settings.get("method", ""),
        "error": "",
    }


def median(values: list[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return statistics.median(finite) if finite else float("nan")


def group(rows: list[dict[str, Any]], keys: tuple[str, ...]) -> dict[tuple, list[dict[str, Any]]]:
    out: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        out.setdefault(tuple(r[k] for k in keys), []).append(r)
    return out


def fmt(v: float, digits: int = 3) -> str:
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    return f"{v:.{digits}g}"


def per_scene_medians(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for (scene, method, budget), rs in group(rows, ("scene", "method", "budget")).items():
        out.append({
            "scene": scene, "method": method, "budget": budget,
            "population": rs[0]["population"], "generations": rs[0]["generations"],
            "evaluations": median([float(r["evaluations"]) for r in rs]),
            "seconds": median([r["seconds"] for r in rs]),
            "light_err_m": median([r["light_err_m"] for r in rs]),
            "light_dir_err_deg": median([r["light_dir_err_deg"] for r in rs]),
            "product_err_max": median([r["product_err_max"] for r in rs]),
            "runs": len(rs),
        })
    return out


def tables(rows: list[dict[str, Any]], machine: str) -> str:
    med = per_scene_medians(rows)
    buf = io.StringIO()
    buf.write("| scene | method | budget | pop x gens | evaluations | seconds (median) | "
              "light error m (median) | light dir deg (median) | product error (median) |\n")
    buf.write("|---|---|---|---|---|---|---|---|---|\n")
    for m in med:
        buf.write(f"| {m['scene']} | {m['method']} | {m['budget']:g} | {m['population']} x {m['generations']} "
                  f"| {m['evaluations']:.0f} | {fmt(m['seconds'])} | {fmt(m['light_err_m'])} "
                  f"| {fmt(m['light_dir_err_deg'])} | {fmt(m['product_err_max'])} |\n")
    buf.write("\nPer method (median over scenes of the per-scene medians):\n\n")
    buf.write("| method | budget | scenes | seconds | light error m | light dir deg | product error |\n")
    buf.write("|---|---|---|---|---|---|---|\n")
    for (method, budget), ms in group(med, ("method", "budget")).items():
        buf.write(f"| {method} | {budget:g} | {len(ms)} | {fmt(median([m['seconds'] for m in ms]))} "
                  f"| {fmt(median([m['light_err_m'] for m in ms]))} "
                  f"| {fmt(median([m['light_dir_err_deg'] for m in ms]))} "
                  f"| {fmt(median([m['product_err_max'] for m in ms]))} |\n")
    buf.write(reach_table(med))
    buf.write(f"\n{machine}\n")
    return buf.getvalue()


def reach_table(med: list[dict[str, Any]], reference: str = "paper", method: str = "rtloop") -> str:
    """Per scene: the reference protocol at its full budget, and the cheapest budget of ``method`` whose
    median light error and product error are both at most the reference's, with the speed-up."""
    ref = {m["scene"]: m for m in med if m["method"] == reference and m["budget"] == 1.0}
    if not ref:
        return ""
    buf = io.StringIO()
    buf.write(f"\nTime for {method} to reach {reference}'s error (full budget), per scene:\n\n")
    buf.write(f"| scene | {reference} seconds | {reference} light m | {reference} product | {method} budget "
              f"| evaluations | seconds | light m | product | speed-up |\n")
    buf.write("|---|---|---|---|---|---|---|---|---|---|\n")
    for scene, r in ref.items():
        ok = sorted((m for m in med if m["scene"] == scene and m["method"] == method
                     and m["light_err_m"] <= r["light_err_m"] and m["product_err_max"] <= r["product_err_max"]),
                    key=lambda m: m["seconds"])
        head = f"| {scene} | {fmt(r['seconds'])} | {fmt(r['light_err_m'])} | {fmt(r['product_err_max'])} "
        if not ok:
            buf.write(head + "| not reached | | | | | |\n")
            continue
        m = ok[0]
        buf.write(head + f"| {m['budget']:g} | {m['evaluations']:.0f} | {fmt(m['seconds'])} "
                  f"| {fmt(m['light_err_m'])} | {fmt(m['product_err_max'])} | {r['seconds'] / m['seconds']:.1f}x |\n")
    return buf.getvalue()


def success_runs(rtloop, score, scene_dir: Path, truth: dict, seeds: int, max_evals: int, threshold: float,
                 threads: int | None) -> tuple[str, list[dict[str, Any]]]:
    """The default method on one scene within ``max_evals`` candidate evaluations, over ``seeds`` seeds:
    how often the light lands within ``threshold`` metres."""
    proto = importlib.import_module("rtloop.fit").PROTOCOLS["rtloop"]
    pop, polish = proto["population"], proto["polish"]
    gens = (max_evals - polish) // pop - 1  # L-SHADE spends population x (generations + 1), then the polish
    rows = []
    for seed in range(seeds):
        r = run_one(rtloop, score, scene_dir, truth, "rtloop", pop, (gens, proto["generations"][1]), seed,
                    threads, polish)
        rows.append({"seed": seed, **r})
    hits = sum(1 for r in rows if r["light_err_m"] < threshold)
    worst = max(r["evaluations"] for r in rows)
    errs = sorted(r["light_err_m"] for r in rows)
    text = (f"\nSuccess rate, {scene_dir.name}, default method at most {max_evals} evaluations "
            f"(population {pop} x {gens + 1} generations + {polish} polish; at most {worst} used): light within "
            f"{threshold * 100:g} cm in {hits} of {seeds} seeds; light error median {fmt(median(errs))} m, "
            f"worst {fmt(errs[-1])} m; median {fmt(median([r['seconds'] for r in rows]))} s per fit.\n")
    return text, rows


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    from rtloop._files import write_text

    fh = io.StringIO(newline="")
    w = csv.DictWriter(fh, fieldnames=FIELDS)
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{r[k]:.6g}" if isinstance(r[k], float) else r[k]) for k in FIELDS})
    write_text(path, fh.getvalue(), parents=True)


def write_plot(path: Path, rows: list[dict[str, Any]], title: str) -> bool:
    try:
        import matplotlib
    except ImportError:
        print("matplotlib is not installed (pip install matplotlib, or .[bench]): no plot", file=sys.stderr)
        return False
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

    med = per_scene_medians(rows)
    methods = list(dict.fromkeys(m["method"] for m in med))
    budgets = sorted({m["budget"] for m in med})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    markers = ["o", "s", "^", "D", "v", "P", "X", "*"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    panels = [("light_err_m", "light position error (m)"), ("product_err_max", "max product relative error")]
    for ax, (key, label) in zip(axes, panels):
        for i, method in enumerate(methods):
            colour = colours[i % len(colours)]
            line_x, line_y = [], []
            for j, budget in enumerate(budgets):
                ms = [m for m in med if m["method"] == method and m["budget"] == budget]
                if not ms:
                    continue
                marker = markers[j % len(markers)]
                xs = [m["seconds"] for m in ms]
                ys = [max(m[key], LOG_FLOOR) for m in ms]
                # Each scene's median over seeds, faint; the median over scenes, bold.
                ax.scatter(xs, ys, color=colour, marker=marker, alpha=0.3, s=25)
                x, y = median(xs), median(ys)
                ax.scatter([x], [y], color=colour, marker=marker, s=90, edgecolors="black",
                           label=f"{method}, budget {budget:g}")
                line_x.append(x)
                line_y.append(y)
            ax.plot(line_x, line_y, color=colour, alpha=0.6)
        ax.set_xscale("log")
        ax.set_yscale("log")
        # Readable seconds: 1-2-5 ticks labelled plainly, unlabelled minor ticks.
        lo, hi = ax.get_xlim()
        ticks = [m * 10.0**e for e in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1)
                 for m in (1, 2, 5) if lo <= m * 10.0**e <= hi]
        if len(ticks) >= 2:
            ax.xaxis.set_major_locator(FixedLocator(ticks))
            ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("seconds (load + fit)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=9)

    from rtloop._files import write_bytes

    try:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=120)
        write_bytes(path, buf.getvalue(), parents=True)
    finally:
        plt.close(fig)
    return True


def machine_line(rtloop) -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            model = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")), "")
        if model:
            cpu = f"{cpu} ({model})" if cpu else model
    except OSError:
        pass
    return (f"machine: {cpu}, {os.cpu_count()} logical CPUs, {platform.system()} {platform.release()}; "
            f"Python {platform.python_version()}; rtloop {rtloop.__version__}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", type=Path, default=DEFAULT_SCENES, help="folder of scene folders")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="where to write CSV, markdown and PNG")
    ap.add_argument("--seeds", type=int, default=2, help="seeds per configuration (0, 1, ...)")
    ap.add_argument("--methods", nargs="+", default=DEFAULT_METHODS,
                    help=f"protocols of rtloop.fit; PROTOCOL{NO_POLISH} runs it without its polish, at equal cost")
    ap.add_argument("--budgets", nargs="+", type=float, default=DEFAULT_BUDGETS,
                    help="fractions of each protocol's population x generations")
    ap.add_argument("--threads", type=int, default=None, help="threads for rtloop.fit (default: all)")
    ap.add_argument("--quick", action="store_true", help="smoke run: 1 seed, smallest budget only")
    ap.add_argument("--uncertainty", action="store_true",
                    help="time the fits with their uncertainty estimate (off: the search alone, as the paper's)")
    ap.add_argument("--success-scene", default="yellow-ball",
                    help="scene for the success-rate run ('' to skip): light within --success-threshold")
    ap.add_argument("--success-seeds", type=int, default=20, help="seeds for the success-rate run")
    ap.add_argument("--success-evals", type=int, default=1200, help="evaluation budget of the success-rate run")
    ap.add_argument("--success-threshold", type=float, default=0.01, help="light error counted a success (m)")
    args = ap.parse_args(argv)

    if not args.scenes.is_dir():
        print(f"no scenes at {args.scenes}: nothing to benchmark (pass --scenes DIR)")
        return 0
    scenes = find_scenes(args.scenes)
    if not scenes:
        print(f"no scene folders with {', '.join(SCENE_FILES)} in {args.scenes}: nothing to benchmark")
        return 0
    if not SCORE_TOOL.is_file():
        print(f"scoring tool {SCORE_TOOL} is absent: nothing to benchmark")
        return 0
    if args.seeds < 1 or any(not b > 0 for b in args.budgets):
        ap.error("--seeds must be >= 1 and every budget > 0")

    import json

    import rtloop
    from rtloop._files import write_text

    protocols = importlib.import_module("rtloop.fit").PROTOCOLS
    unknown = [m for m in args.methods if m.removesuffix(NO_POLISH) not in protocols]
    if unknown:
        ap.error(f"unknown method(s) {', '.join(unknown)} (known: {', '.join(protocols)})")
    score = load_score(SCORE_TOOL)
    seeds = [0] if args.quick else list(range(args.seeds))
    budgets = [min(args.budgets)] if args.quick else sorted(set(args.budgets))
    stem = "speed_vs_error_quick" if args.quick else "speed_vs_error"
    machine = machine_line(rtloop)
    total = len(scenes) * len(args.methods) * len(budgets) * len(seeds)
    print(f"{total} fits: {len(scenes)} scenes x methods {args.methods} x budgets {budgets} x seeds {seeds}",
          file=sys.stderr)

    rows: list[dict[str, Any]] = []
    done = 0
    for scene_dir in scenes:
        truth = json.loads((scene_dir / "scene.json").read_text())
        for method in args.methods:
            for budget in budgets:
                population, generations, polish = scaled_budget(protocols[method.removesuffix(NO_POLISH)],
                                                                budget)
                if method.endswith(NO_POLISH) and polish:
                    # The polish's evaluations go to the search instead: what the polish buys at equal cost.
                    generations = (generations[0] + round(polish / population), generations[1])
                    polish = 0
                for seed in seeds:
                    row: dict[str, Any] = {
                        "scene": scene_dir.name, "method": method, "budget": budget, "seed": seed,
                        "population": population, "generations": f"{generations[0]}+{generations[1]}",
                    }
                    try:
                        row.update(run_one(rtloop, score, scene_dir, truth, method, population, generations,
                                           seed, args.threads, polish, args.uncertainty))
                    except (rtloop.RtloopError, OSError, ValueError, KeyError, RuntimeError) as exc:
                        # One failing fit should not lose the others.
                        nan = float("nan")
                        row.update(evaluations=0, seconds=nan, fit_seconds=nan, light_err_m=nan,
                                   light_dir_err_deg=nan, product_err_max=nan, fit_method="",
                                   error=f"{type(exc).__name__}: {exc}")
                    rows.append(row)
                    done += 1
                    print(f"[{done}/{total}] {row['scene']} {method} budget {budget:g} seed {seed}: "
                          f"{fmt(row['seconds'])} s, {row['evaluations']} evals, light {fmt(row['light_err_m'])} m, "
                          f"product {fmt(row['product_err_max'])}" + (f"  ERROR {row['error']}" if row["error"] else ""),
                          file=sys.stderr, flush=True)

    out = args.out
    write_csv(out / f"{stem}.csv", rows)
    text = tables(rows, machine)
    success_dir = args.scenes / args.success_scene
    if args.success_scene and not args.quick and (success_dir / "scene.json").is_file():
        print(f"success-rate run: {args.success_scene}, {args.success_seeds} seeds", file=sys.stderr)
        truth = json.loads((success_dir / "scene.json").read_text())
        line, _ = success_runs(rtloop, score, success_dir, truth, args.success_seeds, args.success_evals,
                               args.success_threshold, args.threads)
        text = text.replace(f"\n{machine}\n", line + f"\n{machine}\n")
    write_text(out / f"{stem}.md", text, parents=True)
    plotted = write_plot(out / f"{stem}.png", rows, f"rtloop speed against error; {machine}")
    print(text)
    written = [f"{stem}.csv", f"{stem}.md"] + ([f"{stem}.png"] if plotted else [])
    print(f"wrote {', '.join(str(out / w) for w in written)}")
    failed = sum(1 for r in rows if r["error"])
    if failed:
        print(f"{failed} of {len(rows)} fits failed (see the 'error' column)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
