"""``rtloop-fit``: fit a scene to a photo from the command line and keep everything it produced.

    rtloop-fit examples/yellow-ball/scene_input.json examples/yellow-ball/objective.png --out fit-out

The results go into a fresh temporary directory beside the output directory and are moved into place
only when complete, so an interrupted or failed run leaves nothing half-written and an existing output
directory untouched. See ``rtloop-fit --help`` for the options and the files written.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import shutil
import signal
import sys
import threading
import time
from pathlib import Path
from collections.abc import Iterator
from typing import Any

import numpy as np

import rtloop
from rtloop._files import PlaceError, check_out_dir, move_into_place, recover_leftovers, staging_dir
from rtloop.fit import PROTOCOLS
from rtloop.fit.files import fit_inputs, load_inputs
from rtloop.fit.lights import LightsFit
from rtloop.fit.protocol import LIMITS, max_threads
from rtloop.report import truth_errors, truth_values
from rtloop.uncertainty.bootstrap import replicate_of

from .args import Parser, UsageError, choice, float_in, generations, int_at_least, int_in, norm, vignetting
from .lights import LIGHTS_HELP, lights_count, lights_summary, run_lights, uses_lights, write_lights
from .outputs import GenerationLog, input_paths, render_final, set_aside_one_light_log, write_result
from .progress import _Progress
from .summary import duration as _duration, summary as _summary

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
                    scene's size, --final-spp samples in each pixel at an
                    edge or where the shading bends (elsewhere its centre)
  objective.png     the photo as the fit saw it (linearised and resized; saved
                    as sRGB), to compare with final.png and the snapshots
  report.html, report/*.png
                    with --report: one self-contained page (images embedded)
                    opening with the answer (the light's position in mm with
                    its error bar, the colours in %, the verdict, the scene
                    from above and from the side), then the photo beside
                    final.png and their difference, the best render through
                    the stages, the parameters and the fitness against
                    generation, the fitted values and the fit report

with --lights N|auto (or a SCENE with a "lights" list: several lights, a sphere
or a rectangle light), the lights fit: result.json's fit_report lists each light
(position or direction, intensity, their error bars, its share of the light)
and, with auto, the held-out error per number of lights; objective.png and
final.png as above, and with --report a page of the lights and their evidence;
no snapshots or CSV. Without --lights, a one-light fit that does not explain
the photo tries further lights: one kept (on pixels the fit did not see) gives
the lights fit's files, with the test and the evidence in fit_report's
number_of_lights (the one-light search's CSV and snapshots in one_light/); none
kept leaves the one-light files, fit_report.model.lights saying what was tried.
--lights 1 fits one light only.

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
    _add_search_args(p)
    _add_photo_args(p)
    _add_model_args(p)
    _add_lens_args(p)
    _add_output_args(p)
    return p


def _add_search_args(p: Parser) -> None:
    """The search: protocol, population, generations, differential evolution's F and CR, seed, threads."""
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


def _add_photo_args(p: Parser) -> None:
    """How the photo is read and compared: response, crop, norm, loss space."""
    choice(p, "--response", ("srgb", "linear"),
           "how IMAGE's stored values relate to light: 'srgb' (default, cameras and image "
           "editors) or 'linear' (raw linear sensor counts)")
    p.add_argument("--crop", action="store_true",
                   help="centre-crop IMAGE to the scene's aspect ratio (otherwise they must match)")
    p.add_argument("--norm", type=norm, default="auto", metavar="NORM",
                   help="per-pixel penalty of the loss: auto (default: l1, refitted in l2 when IMAGE is a linear "
                   "camera file, --response linear of a 16-bit or 8-bit PNG or TIFF or a RAW, and the l1 fit's "
                   "residual exceeds its own noise at most pixels; fit_report.model.norm says why), l1 (the "
                   "paper's), l2 (Gaussian noise), huber or huber:H (quadratic within H, linear beyond)")
    choice(p, "--loss-space", ("auto", "linear", "srgb"),
           "where --norm compares render and IMAGE: 'auto' (default: linear, and a JPEG that direct "
           "light explains refitted in sRGB where its errors are alike in code values in the dark and "
           "the bright pixels, as a JPEG's own are and a noisy sensor's are not), 'linear' (radiance) "
           "or 'srgb' (both sRGB-encoded, as an "
           "8-bit file stores them: an error in the shadows counts as the file and the eye resolve it)")


def _add_model_args(p: Parser) -> None:
    """What the model holds and checks: environment, interreflection, pixel footprint, error bars, highlights, framing."""
    choice(p, "--environment", ("auto", "on", "off"),
           "the occluded environment term (a room's light from every direction, darker under and "
           "between the objects): 'auto' (default) adds it when the photo shows it and says why in "
           "result.json's fit_report.model, 'on' always fits it, 'off' never")
    choice(p, "--interreflection", ("auto", "on", "off"),
           "one diffuse bounce between the objects (the floor lighting a ball's underside, a red ball "
           "tinting the floor): 'auto' (default) adds it when the photo shows it, 'on', 'off'; with it the "
           "fit also estimates the light's absolute intensity (a bounce is as bright as the albedos are)")
    choice(p, "--footprint", ("auto", "silhouette", "on", "off"), nargs="?", const="on",
           help="integrate each pixel over its area where a sphere's shadow edge or terminator crosses "
           "it, as a camera does, instead of shading pixel centres: 'auto' (default) in the closed-form "
           "polish, products and loss (the search finds the basin at pixel centres; the outline pixels "
           "averaged over sub-pixel rays where the photo needs it), 'silhouette' that with the outlines always "
           "averaged, 'on' (or the bare "
           "flag) in every search too, 'off' pixel centres only (on the Mitsuba test photos: median light error 1.8 mm against 2.8 mm at pixel centres, for about 1.1x the CPU time)")
    choice(p, "--uncertainty", ("default", "bootstrap", "off"),
           "error bars: 'default' (Gauss-Newton and the block sandwich, a few ms), 'bootstrap' "
           "(also a spatial block bootstrap: 30 closed-form refits on resampled image blocks, seeded by "
           "--seed; about 1 s on a 128x96 direct-light photo, 40-115 s with interreflection, 9 minutes "
           "for 50 balls with the environment and interreflection; each refit is shown, and Ctrl-C "
           "stops within a generation; its sigma is printed), 'off' (none)")
    choice(p, "--highlights", ("auto", "off"),
           "'auto' (default): a sphere the scene gives as matte gets a fitted specular lobe "
           "(Blinn-Phong, or a clear coat with its roughness where that explains it better) when the "
           "photo shows a highlight the diffuse model cannot explain; 'off': never")
    choice(p, "--framing", ("check", "correct", "off"),
           "whether IMAGE is framed as the scene's camera frames it (the objects' outlines against "
           "the fitted render): 'check' (default) says so in the verdict where the outlines are 0.5 px "
           "or more off (a cropped, rotated or resized photo, or a wrong field of view), 'correct' "
           "resamples IMAGE into the scene's framing by the roll, zoom and shift its outlines give and "
           "fits again (objective.png is then the resampled photo), 'off'")


def _add_lens_args(p: Parser) -> None:
    """The lens and the pixels used: vignetting, a flat field, the tone curve, the mask."""
    p.add_argument("--vignetting", type=vignetting, default="auto", metavar="auto|on|off|K1,K2",
                   help="the lens's falloff cos^4 x (1 + k1 r^2 + k2 r^4) (r = 1 at the corner): 'auto' (default) "
                   "fits it with the light when held-out pixels show it, 'on', 'off', or K1,K2 to give it "
                   "(with an '=' when K1 is negative: --vignetting=-0.3,-0.1; docs/camera.md)")
    p.add_argument("--flat-field", metavar="FILE",
                   help="a photo of a flat white target through the same lens and settings: the falloff it shows "
                   "divides IMAGE (instead of --vignetting)")
    choice(p, "--tone-curve", ("auto", "on", "off"),
           "'auto' (default): where IMAGE is an 8-bit file whose tone curve is not sRGB (held-out "
           "pixels show it), a monotone curve is fitted with the light; 'on', 'off'; with --response linear "
           "the image is declared linear: no curve, and no doubt that it is sRGB-encoded")
    p.add_argument("--mask", type=Path, metavar="PNG",
                   help="an image of IMAGE's size (or the scene's): white where the scene models the photo, "
                   "black where it does not (another object, a reflection); black pixels are left out of the fit (default: the mask the scene names, "
                   "which rtloop-scene writes to leave the board out)")


def _add_output_args(p: Parser) -> None:
    """What is written and shown: snapshots, final.png, --force, the report, the truth, lights, quiet."""
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
    p.add_argument("--lights", type=lights_count, metavar="N|auto", help=LIGHTS_HELP)
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")


# --- output directory ------------------------------------------------------------------------------------


def _commit(tmp: Path, out: Path, replace: bool) -> None:
    """Move the finished results into place; an old DIR is renamed aside first and deleted last."""
    try:
        left = move_into_place(tmp, out, replace, "rtloop")
    except PlaceError as e:
        raise _Failure(f"{out}: {e}") from None
    if left is not None:
        print(f"{PROG}: warning: could not delete the old results in {left}", file=sys.stderr)


# --- the run ---------------------------------------------------------------------------------------------


def fit_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of :func:`rtloop.fit` the command line gives (a batch job's own options)."""
    return {"protocol": args.protocol, "population": args.population, "generations": args.generations,
            "f": args.f, "cr": args.cr, "norm": args.norm, "space": args.loss_space,
            "environment": args.environment, "interreflection": args.interreflection,
            "highlights": args.highlights, "footprint": args.footprint, "framing": args.framing,
            "vignetting": args.vignetting,
            "tone": args.tone_curve,
            **({"flat_field": (args.flat_field, args.response)} if args.flat_field is not None else {}),
            "uncertainty": {"default": True, "bootstrap": "bootstrap", "off": False}[args.uncertainty]}


def _head(path: str, n: int = 64) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(n)
    except OSError:
        return b""  # reported when it is read


def _is_text(data: bytes) -> bool:
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as e:
        return e.start >= len(data) - 3  # cut inside a character at the end
    return b"\0" not in data


@contextlib.contextmanager
def _cli_words() -> Iterator[None]:
    """Errors of the readers in the command line's words: the option ``--crop``, not ``crop=True``."""
    try:
        yield
    except rtloop.RtloopError as e:
        text = str(e)
        if "crop=True" not in text:
            raise
        raise _Failure(text.replace("pass crop=True", "pass --crop").replace("crop=True", "--crop")) from None


def _check_order(scene: str, image: str) -> None:
    """A SCENE that is not text (an image) is one clear line, not a decoding error: with IMAGE a JSON text
    the two were given the wrong way round."""
    head = _head(scene)
    if not head or _is_text(head):
        return
    if _head(image).lstrip().startswith(b"{"):
        raise _Failure(f"{scene}: is not a scene (JSON) but {image} is: SCENE and IMAGE swapped? "
                       f"(usage: {PROG} SCENE IMAGE --out DIR)")
    raise _Failure(f"{scene}: is not a scene file (JSON text); SCENE comes first, then IMAGE")


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
        inputs = _load(args)
        scene, image = inputs.scene, inputs.image
        self.check_stop()
        names = scene.param_names()
        if not names:
            raise _Failure(f"{args.scene}: the scene's fit section names no free parameters")
        if uses_lights(args, scene):
            self.progress.message(f"{PROG}: fitting the lights of {args.scene} to {args.image} "
                                  f"({scene.width}x{scene.height}, {args.lights or 'its own'} lights)")

            def refuse(message: str) -> None:
                raise _Failure(message)

            return run_lights(args, inputs, tmp, refuse, fit_options(args))
        truth = _load_truth(args, scene)
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
                refit = replicate_of(info.stage)
                if refit is not None:  # the bootstrap's refits: progress only (not the fit's search)
                    self.progress.refit(*refit, info.generation)
                    return
                params = log(info)
                rows.append((info.stage, info.generation, float(info.fitness), params))
                self.progress.generation(info)

            result = fit_inputs(inputs, seed=args.seed, threads=args.threads, callback=callback,
                                lights=args.lights, **fit_options(args))
        self.progress.end_line()
        if isinstance(result, LightsFit):  # the default fit kept a further light: the lights fit's outputs
            set_aside_one_light_log(tmp)
            if truth is not None:
                print(f"{PROG}: warning: --truth: not compared: the fit kept {len(result.lights)} lights "
                      "(see result.json's fit_report.number_of_lights)", file=sys.stderr)
            write_lights(tmp, result, image, asked=args.lights, seed=args.seed, final_scale=args.final_scale,
                         final_spp=args.final_spp, report=bool(args.report))
            return result
        for w in result.warnings:
            print(f"{PROG}: warning: {w}", file=sys.stderr)
        _warn_goodness(result.goodness or {})
        self.check_stop()

        self._write(tmp, result, inputs, image, truth, rows)
        return result

    def _write(self, tmp: Path, result: Any, inputs: Any, image: np.ndarray, truth: Any,
               rows: list[tuple[str, int, float, np.ndarray]]) -> None:
        """Write the fit's results into ``tmp``: result.json and the rest, the objective as the fit saw it
        (reframed with --framing correct), final.png, and with --report the page; the truth's errors kept."""
        args = self.args
        scene = inputs.scene
        write_result(tmp, result, input_paths(args.scene, args.image, args.response, args.crop, inputs.mask_path))
        if getattr(result, "reframed", None) is not None:  # --framing correct: the photo as the fit saw it
            image = result.reframed[0]
            rtloop.save_image(tmp / "objective.png", image)

        k = args.final_scale
        self.progress.message(
            f"rendering final.png ({scene.width * k}x{scene.height * k}, {args.final_spp} spp)"
        )
        final = render_final(result.scene, k, args.final_spp)
        self.check_stop()
        rtloop.save_image(tmp / "final.png", final)
        if truth is not None:
            self.truth_errors = truth_errors(result, truth)
        if args.report:
            self.progress.message("writing report.html")
            rtloop.report(result, tmp / "report.html", objective=image, truth=truth, generations=rows,
                          speed_plot=args.speed_plot, final=final)
            self.check_stop()


def _load(args: argparse.Namespace) -> Any:
    """The scene, the photo and the mask (:func:`load_inputs`), checked for the size of final.png; the
    loading's warnings printed."""
    _check_order(args.scene, args.image)
    with _cli_words():
        inputs = load_inputs(args.scene, args.image, mask=args.mask, response=args.response, crop=args.crop)
    scene = inputs.scene
    k = args.final_scale
    if max(scene.width, scene.height) * k > MAX_SIZE:
        raise _Failure(f"--final-scale {k}: final.png would be {scene.width * k}x{scene.height * k}, more "
                       f"than {MAX_SIZE} pixels on a side; use --final-scale "
                       f"{max(1, MAX_SIZE // max(scene.width, scene.height))} or less")
    for w in inputs.warnings:
        print(f"{PROG}: warning: {' '.join(w.split())}", file=sys.stderr)
    return inputs


def _load_truth(args: argparse.Namespace, scene: Any) -> Any:
    """The true scene of --truth (None without it), checked against the scene; --speed-plot checked."""
    truth = None
    if args.truth is not None:
        truth = rtloop.load_scene(args.truth)
        try:
            truth_values(scene, truth)
        except rtloop.RtloopError as e:
            raise _Failure(f"{args.truth}: does not match {args.scene}: {e}") from None
    if args.speed_plot is not None and not args.speed_plot.is_file():
        raise _Failure(f"--speed-plot: {args.speed_plot}: no such file")
    return truth


def _warn_goodness(good: dict[str, Any]) -> None:
    """A warning with the verdict (and the residual by object) where the model does not explain the photo (a
    residual over the noise floor that is not all texture or noise) or the framing does not match."""
    if (good.get("ratio") or 0.0) >= good.get("explained_below", float("inf")) and not good.get("fine_only") or \
            (good.get("framing") or {}).get("mismatch"):
        print(f"{PROG}: warning: {good['verdict']}", file=sys.stderr)
        if good.get("diagnosis"):
            print(f"{PROG}: residual by object: {good['diagnosis']}", file=sys.stderr)


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
    if argv is None:  # run as the program: what is imported lives until exit, so no collection scans it
        gc.freeze()  # (about 15 ms of a one-photo run, most of it the collection at exit)
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
        inputs = [Path(p) for p in (args.scene, args.image, args.mask, args.truth) if p is not None]
        replace = check_out_dir(out, args.force, inputs)
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

    if isinstance(result, LightsFit):
        print(lights_summary(result, out, time.perf_counter() - t0, _duration))
        return 0
    print(_summary(result, out, time.perf_counter() - t0, truth=run.truth_errors,
                   report=out / "report.html" if args.report else None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
