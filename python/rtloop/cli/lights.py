"""``rtloop-fit --lights N|auto``, and a scene with a ``lights`` list: the lights fit from the command
line (:mod:`rtloop.fit.lights`). It writes result.json (the fitted scene and a ``fit_report`` listing each
light with its position, intensity and error bars, and, with ``auto``, the held-out error per number of
lights), objective.png and final.png, and prints a summary."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

import rtloop
from rtloop.fit.files import fit_inputs
from rtloop.fit.lights import AUTO_GAIN, AUTO_LIMIT, size_text
from rtloop.fit.more_lights import MIN_ANGLE_DEG, MIN_SHARE

from rtloop._files import write_json

from .outputs import render_final

__all__ = ["LIGHTS_HELP", "lights_count", "lights_document", "lights_summary", "run_lights", "uses_lights",
           "write_lights"]

LIGHTS_HELP = (
    "fit several lights: N (1 to 8) lights, or 'auto' to choose how many from pixels the fit did not see "
    f"(one light, then one more while it cuts their error by {AUTO_GAIN:.0%}% or more, up to {AUTO_LIMIT}). "
    "Added lights are point lights searched in the first light's position box. A scene with a 'lights' "
    "list (several lights, a sphere or a rectangle light) takes this fit without the flag, its own lights "
    "kept. Without the flag, a one-light scene takes the ordinary fit and, only where it does not explain "
    "the photo, further lights are tried and kept where held-out pixels ask for them (result.json says what "
    "was tried); --lights 1 fits one light only. Objects are taken as matte, under the fit's "
    "own loss: --norm, --loss-space, the term and camera flags are refused with it; result.json lists each "
    "light with its error bars"
)


#: What the default fit adds to the rule (:mod:`rtloop.fit.more_lights`).
_DEFAULT_RULE = (f" than the one-light fit's (or the fewer lights'), carrying {MIN_SHARE:.0%} of the light "
                 f"{MIN_ANGLE_DEG:g} degrees from the others at least; tried only where the one-light fit does not "
                 "explain the photo (gate)")


def lights_count(text: str) -> int | str:
    """``--lights``: a whole number of lights from 1 to 8, or ``auto``."""
    if text == "auto":
        return text
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of lights from 1 to 8 or 'auto', got {text!r}") from None
    if not 1 <= value <= 8:
        raise argparse.ArgumentTypeError(f"expected a number of lights from 1 to 8 or 'auto', got {value}")
    return value


def uses_lights(args: argparse.Namespace, scene: Any) -> bool:
    """True when the run is the lights fit: the scene has a ``lights`` list (several lights, a sphere or a
    rectangle light), or ``--lights`` asks for more than its one light (``--lights 1`` on a one-light scene
    is the ordinary fit, as ``rtloop.fit(..., lights=1)``)."""
    return "lights" in scene.to_dict() or args.lights not in (None, 1)


def _round(v: Any) -> Any:
    if isinstance(v, float):
        return float(f"{v:.6g}")
    if isinstance(v, list):
        return [_round(u) for u in v]
    return v


def run_lights(args: argparse.Namespace, inputs: Any, tmp: Path, refuse: Any, options: dict[str, Any]) -> Any:
    """Fit, then write result.json, objective.png and final.png into ``tmp``; returns the LightsFit.
    ``options`` are the command line's :func:`rtloop.fit` arguments (one the lights fit does not take, given
    other than its default, is refused there); ``refuse(message)`` raises the command's one-line failure for
    the options only the command has."""
    for flag, given in (("--truth", args.truth is not None),
                        ("--uncertainty bootstrap", args.uncertainty == "bootstrap"),
                        ("--generations N1,N2", isinstance(args.generations, tuple))):
        if given:
            refuse(f"{flag}: not with the lights fit (--lights, or a scene with a 'lights' list)")
    fit = fit_inputs(inputs, seed=args.seed, threads=args.threads, lights=args.lights, **options)
    write_lights(tmp, fit, inputs.image, asked=args.lights, seed=args.seed, final_scale=args.final_scale,
                 final_spp=args.final_spp, report=bool(args.report))
    return fit


def lights_document(fit: Any, *, asked: Any, seed: int) -> dict[str, Any]:
    """result.json of a lights fit: the fitted scene and a ``fit_report`` listing each light with its error
    bars, the products, and the held-out error per number of lights (``asked``: the ``lights`` argument)."""
    doc = dict(fit.scene.to_dict())
    doc["fit_report"] = {
        "method": "lights",
        "lights": [{k: _round(v) for k, v in light.items()} for light in fit.lights],
        "products": {k: _round(v) for k, v in fit.products.items()},
        "loss": fit.loss,
        "evaluations": fit.evaluations,
        "seconds": fit.seconds,
        "number_of_lights": {"asked": asked, "evidence": fit.evidence,
                             "rule": f"a further light is kept when it lowers the held-out squared error by "
                                     f"{AUTO_GAIN:.0%} or more" + (_DEFAULT_RULE if fit.gate else ""),
                             **({"gate": fit.gate} if fit.gate else {})},
        "seed": seed,
    }
    return doc


def write_lights(tmp: Path, fit: Any, image: np.ndarray, *, asked: Any, seed: int, final_scale: int,
                 final_spp: int, report: bool = False, images: bool = True) -> None:
    """Write a lights fit's result.json and, with ``images``, objective.png (``image``) and final.png (and,
    with ``report``, report.html) into ``tmp``: what ``rtloop-fit --lights`` and a batch's lights job write."""
    write_json(tmp / "result.json", lights_document(fit, asked=asked, seed=seed))
    if not images:
        return
    rtloop.save_image(tmp / "objective.png", image)
    final = render_final(fit.scene, final_scale, final_spp)
    rtloop.save_image(tmp / "final.png", final)
    if report:
        rtloop.report(fit, tmp / "report.html", objective=image, final=final)


def _pm(v: Any, e: Any, unit: str = "") -> str:
    if isinstance(v, list):
        vals = ", ".join(f"{a:.3f}" for a in v)
        if e is None:
            return f"({vals}){unit}"
        return f"({vals}){unit} +- {float(np.linalg.norm(e)) * 100:.1f} cm"
    return f"{v:.4g}" + ("" if e is None else f" +- {e:.2g}") + unit


def lights_summary(fit: Any, out: Path, wall: float, duration: Any) -> str:
    """What ``rtloop-fit`` prints after the lights fit."""
    lines = [f"lights fit: {len(fit.lights)} light{'s' if len(fit.lights) != 1 else ''}, {fit.evaluations} "
             f"evaluations, fit {duration(fit.seconds)}, wall time {duration(wall)}"]
    for light in fit.lights:
        where = ("direction " + _pm(light["direction"], light.get("direction_error"))) if "direction" in light \
            else ("at " + _pm(light["position"], light.get("position_error"), " m"))
        extra = f", radius {_pm(light['radius'], light.get('radius_error'), ' m')}" if "radius" in light else ""
        if "size" in light:
            extra += f", {size_text(light)}"
        held = " (held: sets the albedos' scale)" if light.get("intensity_error") is None else ""
        lines.append(f"  {light['name']} ({light['kind']}) {where}{extra}, intensity "
                     f"{_pm(light['intensity'], light.get('intensity_error'))}{held}, {light['share']:.0%} of the light")
        if "size_note" in light:
            lines.append(f"    {light['name']}: {light['size_note']}")
    if fit.evidence:
        counts = ", ".join(f"{e['lights']}: {e['held_out']:.4g}" for e in fit.evidence)
        lines.append(f"held-out error per number of lights: {counts}; kept {len(fit.lights)} (a further light "
                     f"must cut it by {AUTO_GAIN:.0%})")
    if fit.gate:
        lines.append(f"lights chosen from the photo: the one-light fit left {fit.gate['ratio']:.2g}x the noise "
                     f"floor, so further lights were tried (--lights 1 fits one light)")
    lines.append(f"results in {out}/ (result.json, final.png, objective.png)")
    return "\n".join(lines)
