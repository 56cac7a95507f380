"""``rtloop-fit``: fit a scene to a photo from the command line and keep everything it produced.

    rtloop-fit examples/yellow-ball/scene_input.json examples/yellow-ball/objective.png --out fit-out

The results go into a fresh temporary directory beside the output directory and are moved into place
only when complete, so an interrupted or failed run leaves nothing half-written and an existing output
directory untouched. See ``rtloop-fit --help`` for the options and the files written.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import sys
import textwrap
import threading
import time
import warnings
from pathlib import Path
from typing import Any, TextIO

import numpy as np

import rtloop
from rtloop._files import PlaceError, move_into_place, recover_leftovers, staging_dir
from rtloop.fit import PROTOCOLS
from rtloop.fit.protocol import LIMITS, max_threads
from rtloop.report import truth_errors, truth_values

from .args import Parser, UsageError, float_in, generations, int_at_least, int_in, norm
from .outputs import GenerationLog, input_paths, write_result

__all__ = ["main"]

PROG = "rtloop-fit"

DESCRIPTION = """\
Recover a scene's light and colours from one photo by rendering in the loop.

SCENE is a hand-built scene (JSON: camera, spheres, planes, one point light);
IMAGE is a photo of it (the objective). The scene's "fit" section chooses the
free parameters and their search ranges (e.g. "light.position",
"light.intensity", "objects.ball.albedo"); everything else stays as written.
The photo is linearised (sRGB by default) and resized to the scene's image
size, the working resolution. A differential-evolution search then renders
candidate scenes with rtloop's ray tracer and compares them with the photo.

The paper's method ("--protocol paper") runs two stages:
  1. light   frees the light and matches the whole image (sum of absolute RGB
             differences), every other parameter held at the scene's value;
  2. colour  fixes that light and frees the rest (albedos, ...), matching R, G
             and B separately on pixels sampled inside each object's visible,
             lit area.
The default protocol "rtloop", for a scene without ambient light, runs one
stage, light+colour, that searches the light's position (and any free
shininess) and solves the colours (and intensity x specular of glossy objects)
in closed form; other scenes get the two stages plus a refine pass
(light-refine, colour-refine).
The first number of --generations applies to the light stages (and
light+colour), the second to the colour stages.
"""

EPILOG = """\
files written into DIR:
  result.json       the fitted scene in the same format as SCENE (load it with
                    rtloop.load_scene), plus "fit_report": settings, fitness,
                    evaluations and time per stage, the fitted values, the
                    determined products and the input paths
  best_per_generation.csv
                    one row per generation of every stage: stage, generation,
                    evaluations, fitness, then every fit parameter's value in
                    the best individual
  snapshots/<stage>_gen<NNNN>.bmp
                    the best individual rendered at the working resolution
                    every --snapshot-every generations of every stage,
                    generation 0 included
  final.png         the fitted scene rendered at --final-scale times the
                    scene's size, --final-spp samples per pixel
  objective.png     the photo as the fit saw it (linearised and resized; saved
                    as sRGB), to compare with final.png and the snapshots
  report.html, report/*.png
                    with --report: one self-contained page (images embedded)
                    showing the objective, the fit and their difference, the
                    best render through the stages, the parameters and the
                    fitness against generation, and the fit report

Everything is written into a temporary directory beside DIR and moved into
place when complete: a failed or interrupted run leaves no partial results. An
existing, non-empty DIR is replaced only with --force, and only at the end.

example:
  rtloop-fit examples/yellow-ball/scene_input.json \\
      examples/yellow-ball/objective.png --out yellow-ball-fit --seed 1

many photos: rtloop-fit --batch JOBS.jsonl --out DIR (see rtloop-fit --batch
  --help): one job a line, in-process or on Ray (--ray), resumable.

exit status: 0 done, 1 bad input or failed run, 2 bad command line,
130 interrupted (Ctrl-C), 143 terminated (SIGTERM).
"""


def _protocol_help() -> str:
    parts = []
    def two_stage(pop: int, g: Any, refine: bool) -> str:
        gens = f"{g[0]} + {g[1]}" if isinstance(g, (tuple, list)) else str(g)
        return f"population {pop}, {gens} generations{', then a refine pass' if refine else ''}"

    for name, p in PROTOCOLS.items():
        if p.get("projected"):
            g = p["generations"]
            g0 = g[0] if isinstance(g, (tuple, list)) else g
            fallback = two_stage(p.get("fallback_population", p["population"]),
                                 p.get("fallback_generations", g), bool(p.get("refine")))
            parts.append(f"'{name}' (closed form: L-SHADE, population {p['population']}, "
                         f"{p['population'] * (g0 + 1)} evaluations, then a Nelder-Mead polish of up to "
                         f"{p.get('polish', 0)}; where it does not apply, two stages: {fallback})")
        else:
            parts.append(f"'{name}' ({two_stage(p['population'], p['generations'], bool(p.get('refine')))})")
    return "named settings: " + "; ".join(parts) + " (default: rtloop)"


class _Failure(Exception):
    """A problem with the input or the output directory (exit status 1), reported as one line."""


class _Interrupted(Exception):
    """Raised inside the fit's callback to stop the search after Ctrl-C."""


#: The largest side of a rendered image, as of a scene's (docs/scene-format.md: "Input limits").
MAX_SIZE = 16384


class _Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C (clean up, nothing half-written) but reported as such."""


def _build_parser() -> Parser:
    p = Parser(
        prog=PROG,
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("scene", metavar="SCENE", help="scene JSON file; its 'fit' section chooses the free parameters")
    p.add_argument("image", metavar="IMAGE", help="the photo to fit (PNG, JPEG, BMP, TIFF, ...)")
    p.add_argument("--out", "-o", metavar="DIR", required=True, help="output directory (created)")
    p.add_argument(
        "--protocol", choices=sorted(PROTOCOLS), default="rtloop",
        help=_protocol_help(),
    )
    p.add_argument("--population", type=int_in(*LIMITS["population"]), metavar="N",
                   help="individuals per generation (default: the protocol's)")
    p.add_argument("--generations", type=generations, metavar="N|N1,N2",
                   help="generations per stage: one number for every stage, or N1 for the light stages "
                   "and N2 for the colour stages (default: the protocol's)")
    p.add_argument("--f", type=float_in(0.0, 2.0, True, "a number in (0, 2]"), metavar="F",
                   help="DE differential weight (default: the protocol's)")
    p.add_argument("--cr", type=float_in(0.0, 1.0, False, "a number in [0, 1]"), metavar="CR",
                   help="DE crossover probability (default: the protocol's)")
    p.add_argument("--seed", type=int_in(*LIMITS["seed"]), default=0,
                   help="random seed; the result is the same for any --threads (default 0)")
    p.add_argument("--threads", type=int_in(1, max_threads()), metavar="N",
                   help="worker threads (default: all cores)")
    p.add_argument("--response", choices=("srgb", "linear"), default="srgb",
                   help="how IMAGE's stored values relate to light: 'srgb' (default, cameras and image "
                   "editors) or 'linear' (raw linear sensor counts)")
    p.add_argument("--crop", action="store_true",
                   help="centre-crop IMAGE to the scene's aspect ratio (otherwise they must match)")
    p.add_argument("--norm", type=norm, default="l1", metavar="NORM",
                   help="per-pixel penalty of the loss: l1 (the paper's, default), l2 (Gaussian noise), "
                   "huber or huber:H (quadratic within H, linear beyond; robust to unmodelled pixels)")
    p.add_argument("--loss-space", choices=("auto", "linear", "srgb"), default="auto",
                   help="where --norm compares render and IMAGE: 'auto' (default: linear, and a JPEG that direct "
                   "light explains refitted in sRGB), 'linear' (radiance) or 'srgb' (both sRGB-encoded, as an "
                   "8-bit file stores them: an error in the shadows counts as the file and the eye resolve it)")
    p.add_argument("--environment", choices=("auto", "on", "off"), default="auto",
                   help="the occluded environment term (a room's light from every direction, darker under and "
                   "between the objects): 'auto' (default) adds it when the photo shows it and says why in "
                   "result.json's fit_report.model, 'on' always fits it, 'off' never")
    p.add_argument("--interreflection", choices=("auto", "on", "off"), default="auto",
                   help="one diffuse bounce between the objects (the floor lighting a ball's underside, a red ball "
                   "tinting the floor): 'auto' (default) adds it when the photo shows it, 'on', 'off'; with it the "
                   "fit also estimates the light's absolute intensity (a bounce is as bright as the albedos are)")
    p.add_argument("--footprint", nargs="?", choices=("auto", "on", "off"), default="auto", const="on",
                   help="integrate each pixel over its area where a sphere's shadow edge or terminator crosses "
                   "it, as a camera does, instead of shading pixel centres: 'auto' (default) in the closed-form "
                   "polish, products and loss (the search finds the basin at pixel centres), 'on' (or the bare "
                   "flag) in every search too, 'off' pixel centres only (on the Mitsuba test photos: median light error 1.8 mm against 2.8 mm at pixel centres, for about 1.1x the CPU time)")
    p.add_argument("--uncertainty", choices=("default", "bootstrap", "off"), default="default",
                   help="error bars: 'default' (Gauss-Newton and the block sandwich, a few ms), 'bootstrap' "
                   "(also a spatial block bootstrap: 30 closed-form refits on resampled image blocks, seeded by "
                   "--seed; about 1 s on a 128x96 direct-light photo, a minute or two with interreflection; "
                   "its sigma is printed), 'off' (none)")
    p.add_argument("--highlights", choices=("auto", "off"), default="auto",
                   help="'auto' (default): a sphere the scene gives as matte gets a fitted specular lobe "
                   "(specular and shininess) when the photo shows a highlight the diffuse model cannot explain; "
                   "'off': never")
    p.add_argument("--mask", type=Path, metavar="PNG",
                   help="an image of IMAGE's size (or the scene's): white where the scene models the photo, "
                   "black where it does not (another object, a reflection); black pixels are left out of the fit (default: the mask the scene names, "
                   "which rtloop-scene writes to leave the board out)")
    p.add_argument("--snapshot-every", type=int_at_least(0, "a whole number >= 0"), default=5, metavar="N",
                   help="render the best individual every N generations of every stage into snapshots/ "
                   "(default 5; 0 disables)")
    p.add_argument("--final-scale", type=int_in(1, MAX_SIZE), default=4, metavar="K",
                   help=f"final.png is K times the scene's width and height, at most {MAX_SIZE} pixels (default 4)")
    p.add_argument("--final-spp", type=int_in(1, rtloop.MAX_SPP), default=16, metavar="S",
                   help=f"samples per pixel of final.png, 1 to {rtloop.MAX_SPP} (default 16)")
    p.add_argument("--force", action="store_true",
                   help="replace DIR if it exists and is not empty (only after the new results are complete)")
    p.add_argument("--report", action="store_true",
                   help="also write DIR/report.html, a self-contained page that shows the search (PNGs in "
                   "DIR/report/)")
    p.add_argument("--speed-plot", type=Path, metavar="PNG",
                   help="with --report: a speed-against-error plot to include (e.g. "
                   "benches/results/speed_vs_error.png)")
    p.add_argument("--truth", metavar="SCENE",
                   help="the true scene (JSON, e.g. a reference scene's scene.json): print the errors of the "
                   "fitted values and draw the truth in the report")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    return p


# --- progress --------------------------------------------------------------------------------------------


def _duration(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.1f}s"
    minutes, s = divmod(int(seconds), 60)
    if minutes < 60:
        return f"{minutes}m{s:02d}s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m{s:02d}s"


class _Progress:
    """Progress lines on stderr: one per stage start, then every 10 generations (or one updating line
    on a terminal)."""

    EVERY = 10
    TTY_INTERVAL = 0.1

    def __init__(self, stream: TextIO, enabled: bool, generations: tuple[int, int]):
        self.stream = stream
        self.enabled = enabled
        self.tty = enabled and bool(getattr(stream, "isatty", lambda: False)())
        self.generations = generations
        self.start = time.perf_counter()
        self.stage: str | None = None
        self.stages = 0
        self.open_line = 0  # length of the unfinished \r line, if any
        self.last_draw = 0.0

    def total(self, stage: str) -> int:
        return self.generations[0] if stage.startswith("light") else self.generations[1]

    def message(self, text: str) -> None:
        if not self.enabled:
            return
        self.end_line()
        print(text, file=self.stream, flush=True)

    def end_line(self) -> None:
        if self.open_line:
            self.stream.write("\n")
            self.stream.flush()
            self.open_line = 0

    def generation(self, info: Any) -> None:
        if not self.enabled:
            return
        total = self.total(info.stage)
        # The closed-form stages (the fit, and a refit with the terms the photo selected or in sRGB, named
        # "light+colour+..." and "light+colour (srgb)") search with L-SHADE: the budget is population x (N + 1)
        # evaluations over more, shrinking generations (plus a polish, logged as one more), so no generation
        # count is known.
        counted = not info.stage.startswith("light+colour")
        if info.stage != self.stage:
            self.stage = info.stage
            self.stages += 1
            what = f"{total} generations" if counted else "L-SHADE, then a Nelder-Mead polish"
            self.message(f"stage {self.stages} '{info.stage}': {what}")
        now = time.perf_counter()
        of = f"/{total}" if counted else ""
        line = (
            f"  {info.stage}  gen {info.generation}{of}  best {info.fitness:.6g}  "
            f"evals {info.evaluations}  {_duration(now - self.start)}"
        )
        last = counted and info.generation >= total
        if self.tty:
            if last or info.generation == 0 or now - self.last_draw >= self.TTY_INTERVAL:
                pad = max(0, self.open_line - len(line))
                self.stream.write("\r" + line + " " * pad)
                self.stream.flush()
                self.open_line = len(line)
                self.last_draw = now
                if last:
                    self.end_line()
        elif info.generation % self.EVERY == 0 or last:
            print(line, file=self.stream, flush=True)


# --- output directory ------------------------------------------------------------------------------------


def _check_out(out: Path, force: bool, inputs: list[Path]) -> bool:
    """Fail early if DIR cannot be (re)placed; True if something is there to replace at the end."""
    if not os.path.lexists(out):
        return False
    if out.is_symlink():
        raise _Failure(f"{out}: is a symbolic link; give the directory it points to, or another name")
    if not out.is_dir():
        raise _Failure(f"{out}: exists and is not a directory")
    cwd = Path.cwd().resolve()
    if out.resolve() == cwd or out.resolve() in cwd.parents:
        raise _Failure(f"{out}: refusing to replace the current directory (or one above it)")
    try:
        empty = not any(out.iterdir())
    except OSError as e:
        raise _Failure(f"{out}: cannot read directory ({e.strerror or e})") from None
    if empty:
        return True
    if not force:
        raise _Failure(f"{out}: output directory exists and is not empty (use --force to replace it)")
    resolved = out.resolve()
    for p in inputs:
        if resolved in p.resolve().parents:
            raise _Failure(f"{out}: refusing to replace it with --force: it contains {p}")
    return True


def _commit(tmp: Path, out: Path, replace: bool) -> None:
    """Move the finished results into place; an old DIR is renamed aside first and deleted last."""
    try:
        left = move_into_place(tmp, out, replace, "rtloop")
    except PlaceError as e:
        raise _Failure(f"{out}: {e}") from None
    if left is not None:
        print(f"{PROG}: warning: could not delete the old results in {left}", file=sys.stderr)


# --- the run ---------------------------------------------------------------------------------------------


def scene_mask(scene_path: Path) -> Path | None:
    """The mask a scene names (``meta.acquisition.mask``, written by rtloop-scene), relative to the scene's
    folder; None when it names none."""
    import json

    try:
        meta = json.loads(Path(scene_path).read_text()).get("meta") or {}
    except (OSError, ValueError, AttributeError):
        return None  # load_scene has read it already: not a JSON object we can look into
    name = (meta.get("acquisition") or {}).get("mask") if isinstance(meta, dict) else None
    if not isinstance(name, str):
        return None
    path = Path(scene_path).parent / name
    if not path.is_file():
        raise _Failure(f"{scene_path}: meta.acquisition.mask names {name}, but {path} is not a file; "
                       "put it back, or pass --mask")
    return path


def scene_card(scene_path: Path) -> tuple[Path, float] | None:
    """The grey card a scene names (``meta.acquisition.grey_card``: ``mask``, a PNG white inside the card,
    relative to the scene's folder, and ``reflectance``), written by rtloop-scene --grey-card-reflectance."""
    import json

    try:
        meta = json.loads(Path(scene_path).read_text()).get("meta") or {}
        card = (meta.get("acquisition") or {}).get("grey_card") or {}
        name, reflectance = card.get("mask"), card.get("reflectance")
    except (OSError, ValueError, AttributeError):
        return None
    if not isinstance(name, str):
        return None
    if not isinstance(reflectance, (int, float)) or isinstance(reflectance, bool):
        raise _Failure(f"{scene_path}: meta.acquisition.grey_card.reflectance must be a number (e.g. 0.18)")
    path = Path(scene_path).parent / name
    if not path.is_file():
        raise _Failure(f"{scene_path}: meta.acquisition.grey_card.mask names {name}, but {path} is not a file")
    return path, float(reflectance)


class _Run:
    def __init__(self, args: argparse.Namespace, progress: _Progress, stop: threading.Event):
        self.args = args
        self.progress = progress
        self.stop = stop
        self.truth_errors: dict[str, Any] | None = None

    def check_stop(self) -> None:
        if self.stop.is_set():
            raise _Interrupted()

    def __call__(self, tmp: Path) -> Any:
        """Load, fit and write everything into ``tmp``; returns the FitResult."""
        args = self.args
        scene = rtloop.load_scene(args.scene)
        if args.mask is None:
            args.mask = scene_mask(args.scene)
        k = args.final_scale
        if max(scene.width, scene.height) * k > MAX_SIZE:
            raise _Failure(f"--final-scale {k}: final.png would be {scene.width * k}x{scene.height * k}, more "
                           f"than {MAX_SIZE} pixels on a side; use --final-scale "
                           f"{max(1, MAX_SIZE // max(scene.width, scene.height))} or less")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            image = rtloop.load_image(args.image, scene, response=args.response, crop=args.crop)
            mask = None if args.mask is None else rtloop.load_mask(args.mask, scene, crop=args.crop)
            card = scene_card(args.scene)
            reference = None if card is None else (rtloop.load_mask(card[0], scene, crop=args.crop), card[1])
        for w in caught:
            print(f"{PROG}: warning: {' '.join(str(w.message).split())}", file=sys.stderr)
        self.check_stop()
        names = scene.param_names()
        if not names:
            raise _Failure(f"{args.scene}: the scene's fit section names no free parameters")
        truth = None
        if args.truth is not None:
            truth = rtloop.load_scene(args.truth)
            try:
                truth_values(scene, truth)
            except rtloop.RtloopError as e:
                raise _Failure(f"{args.truth}: does not match {args.scene}: {e}") from None
        if args.speed_plot is not None and not args.speed_plot.is_file():
            raise _Failure(f"--speed-plot: {args.speed_plot}: no such file")
        self.progress.message(
            f"{PROG}: fitting {len(names)} parameters of {args.scene} to {args.image} "
            f"({scene.width}x{scene.height}, {args.protocol} protocol)"
        )

        rtloop.save_image(tmp / "objective.png", image)
        rows: list[tuple[str, int, float, np.ndarray]] = []

        with GenerationLog(tmp, scene, args.snapshot_every) as log:

            def callback(info: Any) -> None:
                if self.stop.is_set():
                    raise _Interrupted()
                params = log(info)
                rows.append((info.stage, info.generation, float(info.fitness), params))
                self.progress.generation(info)

            with warnings.catch_warnings():
                warnings.simplefilter("ignore", rtloop.RtloopWarning)  # printed below from result.warnings
                result = rtloop.fit(
                    scene, image, protocol=args.protocol, seed=args.seed, population=args.population,
                    generations=args.generations, f=args.f, cr=args.cr, threads=args.threads,
                    callback=callback, mask=mask, norm=args.norm, space=args.loss_space,
                    environment=args.environment, interreflection=args.interreflection,
                    highlights=args.highlights, reference=reference, footprint=args.footprint,
                    uncertainty={"default": True, "bootstrap": "bootstrap", "off": False}[args.uncertainty],
                )
        self.progress.end_line()
        for w in result.warnings:
            print(f"{PROG}: warning: {w}", file=sys.stderr)
        good = result.goodness or {}
        if (good.get("ratio") or 0.0) >= good.get("explained_below", float("inf")):
            print(f"{PROG}: warning: {good['verdict']}", file=sys.stderr)
        self.check_stop()

        write_result(tmp, result, input_paths(args.scene, args.image, args.response, args.crop, args.mask))

        k = args.final_scale
        self.progress.message(
            f"rendering final.png ({scene.width * k}x{scene.height * k}, {args.final_spp} spp)"
        )
        final = rtloop.render(result.scene, scene.width * k, scene.height * k, args.final_spp)
        self.check_stop()
        rtloop.save_image(tmp / "final.png", final)
        if truth is not None:
            self.truth_errors = truth_errors(result, truth)
        if args.report:
            self.progress.message("writing report.html")
            rtloop.report(result, tmp / "report.html", objective=image, truth=truth, generations=rows,
                          speed_plot=args.speed_plot)
            self.check_stop()
        return result


def _summary(result: Any, out: Path, wall: float, truth: dict[str, Any] | None = None,
             report: Path | None = None) -> str:
    stages = len(result.stages)
    lines = [
        f"{stages} stage{'s' if stages != 1 else ''}, {result.evaluations} evaluations, "
        + f"fit {_duration(result.seconds)}, wall time {_duration(wall)}"
    ]
    lines.extend(_model_lines(result.model or {}, dict(result.scene.to_dict())))
    good = result.goodness or {}
    if good.get("ratio") is not None:
        lines.append(f"goodness of fit: {good['ratio']:.2g}x the photo's noise floor: {good['verdict']}")
    elif good.get("verdict"):
        lines.append(f"goodness of fit: {good['verdict']}")
    ident = result.identifiability or {}
    if ident.get("degenerate"):
        lines.append("")
        lines.append("determined products (light intensity x light colour x albedo x exposure), r g b:")
        if result.products:
            w = max(len(n) for n in result.products)
            for obj, rgb in result.products.items():
                lines.append(f"  {obj:<{w}}  " + "  ".join(f"{v:12.6g}" for v in rgb))
        if ident.get("note"):
            lines.extend(textwrap.wrap(f"note: {ident['note']}", 78, initial_indent="  ",
                                       subsequent_indent="  "))
    ref = result.reference
    if ref:
        lines.append("")
        lines.append(f"absolute, from the grey card of reflectance {ref['reflectance']:g} ({ref['pixels']} px): "
                     f"light {ref['light_intensity_w_sr']:.4g} W/sr; albedos r g b:")
        w = max(len(n) for n in ref["albedos"])
        for obj, rgb in ref["albedos"].items():
            lines.append(f"  {obj:<{w}}  " + "  ".join(f"{v:8.4f}" for v in rgb))
    lines.append("")
    lines.append(f"fitted parameters ({result.protocol} protocol, seed {result.seed}):")
    width = max((len(n) for n in result.x), default=0)
    if truth is not None:
        lines.append(f"  {'':<{width}}  {'fitted':>12}  {'truth':>12}  {'error':>12}")
    u = result.uncertainty or {}
    boot = u.get("bootstrap") or {}
    bars = (u.get("robust") or {}).get("sigma") or {}  # the block sandwich's, or the bootstrap's where run
    bars_note = None
    if boot.get("sigma"):
        bars = {**bars, **boot["sigma"]}
        bars_note = (f"error bars (+-): block bootstrap ({boot['replicates']} refits on {boot['block_px']} px blocks, "
                     f"seed {boot['seed']}, {boot['ms']:.0f} ms)")
    elif boot.get("warnings"):
        bars_note = f"error bars (+-): block sandwich (the bootstrap did not run: {boot['warnings'][0]})"
    elif bars:
        shift = (u.get("robust") or {}).get("footprint_shift") or {}
        light = [shift.get(f"light.position.{c}") for c in "xyz"]
        moved = (f", {1e3 * float(np.linalg.norm(light)):.2g} mm on the light" if all(v is not None for v in light)
                 else "")
        bars_note = ("error bars (+-): block sandwich (correlated residuals) plus the pixel footprint's shift "
                     f"(robust.footprint_shift{moved})")
    for name, value in result.x.items():
        row = f"  {name:<{width}}  {value:12.6g}"
        split = truth is not None and name in truth.get("split_convention", [])
        if truth is not None and name in truth["values"]:
            error = f"{'(split)':>12}" if split else f"{truth['errors'][name]:+12.4g}"
            row += f"  {truth['values'][name]:12.6g}  {error}"
        if bars.get(name):
            row += f"  +- {bars[name]:.3g}"
            if truth is not None and name in truth["errors"] and not split:
                row += f" ({truth['errors'][name] / bars[name]:+.1f} sigma)"
        lines.append(row)
    if bars_note:
        lines.append(bars_note)
    if truth is not None and truth.get("split_convention"):
        lines.append("  (split): the photo fixes only the products of these, not each one: their errors "
                     "say how the fit split the products (see the product errors below)")
    if truth is not None:
        if "light_position_m" in truth:
            lines.append(f"light position error: {truth['light_position_m']:.4g} m")
        if truth.get("product_relative"):
            lines.append("product relative error: " + ", ".join(
                f"{obj} {100 * rel:.3g}%" for obj, rel in truth["product_relative"].items()))
    lines.append(f"results in {out}")
    if report is not None:
        lines.append(f"report: {report}")
    return "\n".join(lines)


def _model_lines(model: dict[str, Any], fitted: dict[str, Any]) -> list[str]:
    """The image terms the fit used and the evidence for each it considered."""
    terms = model.get("terms") or ["direct"]
    lines = [f"image model: {' + '.join(terms)}"]
    res = model.get("residual")
    if res:
        lines.append(f"  residual: {res['ratio']:.2g}x the size of the photo's 8-bit rounding error"
                     + (" (explained: no further term tested)" if "skipped" in model else ""))
    for term, ev in (model.get("evidence") or {}).items():
        verdict = "added" if ev.get("selected") else "not added"
        bic = ev.get("delta_bic")
        on_top = ev.get("tested_with") or []
        lines.append(f"  {term}: {verdict} (loss at the light found without it"
                     + (f", with {' and '.join(on_top)}" if on_top else "")
                     + f" {ev['loss_without']:.4g} -> {ev['loss_with']:.4g} with it, {100 * ev['gain']:+.1f}%"
                     + (f", BIC {-bic:+.4g}" if bic is not None else "")
                     + (f"; {100 * ev['earlier_gain']:+.1f}% before them)" if "earlier_gain" in ev else ")"))
    if "environment" in terms and fitted.get("environment"):
        lines.append("  environment radiance (r g b): " + "  ".join(f"{v:.4g}" for v in fitted["environment"]))
    return lines


def _error(message: str) -> None:
    print(f"{PROG}: error: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


def _run_interruptibly(work: Any, stop: threading.Event) -> Any:
    """Run ``work()`` in a thread so that Ctrl-C reaches the main thread at once (the fit's callback
    runs on a worker thread, where Python delivers no signals); on Ctrl-C ask it to stop and wait."""
    box: dict[str, Any] = {}
    done = threading.Event()

    def target() -> None:
        try:
            box["value"] = work()
        except BaseException as e:  # noqa: BLE001 - handed to the main thread
            box["error"] = e
        finally:
            done.set()

    thread = threading.Thread(target=target, name="rtloop-fit", daemon=True)
    thread.start()
    interrupt: KeyboardInterrupt | None = None
    # Poll an Event rather than Thread.join(timeout): an exception that interrupts join() can leave the
    # thread looking finished while it still runs.
    while not done.is_set():
        try:
            done.wait(0.1)
        except KeyboardInterrupt as e:
            interrupt = interrupt or e
            stop.set()
    if interrupt is not None and "error" in box:
        raise interrupt
    if "error" in box:
        raise box["error"]
    return box.get("value")


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``rtloop-fit``; returns the exit status (0 done, 1 bad input or failed run, 2 bad
    command line, 130 interrupted, 143 terminated). With ``--batch JOBS`` it is :mod:`.batch`'s."""
    args = sys.argv[1:] if argv is None else argv
    if any(a == "--batch" or a.startswith("--batch=") for a in args):
        from .batch import main as batch_main

        return batch_main(list(args))
    t0 = time.perf_counter()
    previous_term = None
    if threading.current_thread() is threading.main_thread():
        previous_term = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        return _main(argv, t0)
    except KeyboardInterrupt:  # outside the run (which handles its own): nothing to clean up
        print(f"{PROG}: interrupted", file=sys.stderr, flush=True)
        return 130
    finally:
        if previous_term is not None:
            signal.signal(signal.SIGTERM, previous_term)


def _on_sigterm(signum: int, frame: Any) -> None:
    raise _Terminated()


def _main(argv: list[str] | None, t0: float) -> int:
    parser = _build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as e:
        _error(e)
        return 2
    except SystemExit as e:  # --help
        return int(e.code or 0)
    if args.speed_plot is not None and not args.report:
        _error("--speed-plot: only with --report")
        return 2

    proto = PROTOCOLS[args.protocol]
    # Generations shown per stage: the closed-form stage has an evaluation budget instead (see _Progress),
    # and the two-stage fallback of a protocol may use its own generations.
    gens = args.generations if args.generations is not None else proto.get("fallback_generations", proto["generations"])
    gens = (gens, gens) if isinstance(gens, int) else (int(gens[0]), int(gens[1]))
    progress = _Progress(sys.stderr, not args.quiet, gens)
    stop = threading.Event()
    out = Path(os.path.abspath(args.out))  # normalised: "." and "x/.." have a name and a parent
    tmp: Path | None = None
    try:
        for line in recover_leftovers(out):  # what killed runs left beside DIR
            print(f"{PROG}: {line}", file=sys.stderr)
        replace = _check_out(out, args.force, [Path(args.scene), Path(args.image)])
        try:
            tmp = staging_dir(out, "rtloop-tmp")
        except OSError as e:
            raise _Failure(f"{out}: cannot create the output directory ({e.strerror or e})") from None
        run = _Run(args, progress, stop)

        def work() -> Any:
            result = run(tmp)
            run.check_stop()
            _commit(tmp, out, replace)  # once begun, finished even if Ctrl-C comes meanwhile
            return result

        result = _run_interruptibly(work, stop)
    except _Terminated:
        progress.end_line()
        print(f"{PROG}: terminated", file=sys.stderr, flush=True)
        return 128 + signal.SIGTERM
    except (KeyboardInterrupt, _Interrupted):
        progress.end_line()
        print(f"{PROG}: interrupted", file=sys.stderr, flush=True)
        return 130
    except (rtloop.RtloopError, _Failure) as e:
        progress.end_line()
        _error(e)
        return 1
    except OSError as e:
        progress.end_line()
        where = f"{e.filename}: " if e.filename else ""
        _error(f"{where}{e.strerror or e}")
        return 1
    finally:
        if tmp is not None and os.path.lexists(tmp):
            shutil.rmtree(tmp, ignore_errors=True)

    print(_summary(result, out, time.perf_counter() - t0, truth=run.truth_errors,
                   report=out / "report.html" if args.report else None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
