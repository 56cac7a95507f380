"""What ``rtloop-fit`` prints when it is done: the run, the image model, the goodness of fit, the fitted
values with their error bars (and, with --truth, their errors)."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from ..fit.heldout import HELD_OUT_GAIN

__all__ = ["duration", "model_lines", "summary"]


def duration(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.1f}s"
    minutes, s = divmod(int(seconds), 60)
    if minutes < 60:
        return f"{minutes}m{s:02d}s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m{s:02d}s"


def summary(result: Any, out: Path, wall: float, truth: dict[str, Any] | None = None,
             report: Path | None = None) -> str:
    """What rtloop-fit prints after a fit: its cost, the model, the goodness of fit, the determined products
    and absolute values, the fitted parameters with their error bars (and the truth's errors where known),
    the light's distance, and where the results are."""
    stages = len(result.stages)
    lines = [
        f"{stages} stage{'s' if stages != 1 else ''}, {result.evaluations} evaluations, "
        + f"fit {duration(result.seconds)}, wall time {duration(wall)}"
    ]
    lines.extend(model_lines(result.model or {}, dict(result.scene.to_dict())))
    lines += _goodness_lines(result.goodness or {})
    lines += _lights_lines((result.model or {}).get("lights"))
    lines += _products_lines(result)
    lines.append("")
    lines.append(f"fitted parameters ({result.protocol} protocol, seed {result.seed}):")
    width = max((len(n) for n in result.x), default=0)
    if truth is not None:
        lines.append(f"  {'':<{width}}  {'fitted':>12}  {'truth':>12}  {'error':>12}")
    u = result.uncertainty or {}
    robust = u.get("robust") or {}
    reported = u.get("bars") or {}
    bars, bars_note = _error_bars(u)
    lines += _parameter_rows(result.x, width, truth, bars)
    if bars_note:
        lines.append(bars_note)
    if not robust.get("why_none"):  # else the one line above says why there is none
        lines += undetermined_lines(reported.get("not_determined") or {}, set(result.x))
    lines += distance_lines(reported.get("light_distance") or robust.get("light_distance") or u.get("light_distance"))
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


def _lights_lines(tested: dict[str, Any] | None) -> list[str]:
    """Where the one-light fit did not explain the photo: the further lights tried and why one light stays."""
    if not tested:
        return []
    if not tested.get("tried"):
        return [f"a further light: not tried ({tested['why']})"]
    counts = ", ".join(f"{e['lights']}: {e['held_out']:.4g}" for e in tested["evidence"])
    return [f"a further light: tried, refused (held-out squared error per number of lights {counts}): "
            f"{tested['why']}"]


def _goodness_lines(good: dict[str, Any]) -> list[str]:
    """The goodness of fit's lines: its ratio to the noise floor and verdict, the residual by object, and a
    framing correction."""
    lines: list[str] = []
    if good.get("ratio") is not None:
        lines.append(f"goodness of fit: {good['ratio']:.2g}x the photo's noise floor: {good['verdict']}")
    elif good.get("verdict"):
        lines.append(f"goodness of fit: {good['verdict']}")
    if good.get("diagnosis"):
        lines.append(f"  residual by object: {good['diagnosis']}")
    framing = good.get("framing") or {}
    if framing.get("corrected"):
        c, before = framing["correction"], framing["as_given"]
        lines.append(f"framing corrected: the photo resampled into the scene's framing (turned {c['roll_deg']:+.2f} "
                     f"deg, zoomed {c['zoom_percent']:+.2f} %, shifted ({c['shift_px'][0]:+.2f}, "
                     f"{c['shift_px'][1]:+.2f}) px; outlines {before['outline_rms_px']:.2f} px off as given, "
                     f"{framing.get('outline_rms_px', float('nan')):.2f} px after)")
    return lines


def _products_lines(result: Any) -> list[str]:
    """The determined products of a degenerate fit, and the absolute light and albedos from a grey card."""
    lines: list[str] = []
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
    return lines


def _error_bars(u: dict[str, Any]) -> tuple[dict[str, float], str | None]:
    """The error bars to show by parameter (the reported bars, or the block sandwich's, and the bootstrap's
    where it ran) and the line that says what they are (None: no line)."""
    boot = u.get("bootstrap") or {}
    robust = u.get("robust") or {}
    # the reported bars (the block sandwich's, widened by what the model lacks), or the bootstrap's where run
    reported = u.get("bars") or {}
    bars = {k: v for k, v in (reported.get("sigma") or robust.get("sigma") or {}).items() if v is not None}
    bars_note = None
    if not bars and robust.get("why_none") and not boot.get("sigma"):
        bars_note = f"no error bars: {robust['why_none']}"
    elif boot.get("sigma"):
        bars = {**bars, **boot["sigma"]}
        bars_note = (f"error bars (+-): block bootstrap ({boot['replicates']} refits on {boot['block_px']} px blocks, "
                     f"seed {boot['seed']}, {boot['ms']:.0f} ms)")
    elif boot.get("warnings"):
        bars_note = f"error bars (+-): block sandwich (the bootstrap did not run: {boot['warnings'][0]})"
    elif bars:
        shift = robust.get("footprint_shift") or {}
        light = [shift.get(f"light.position.{c}") for c in "xyz"]
        moved = (f", {1e3 * float(np.linalg.norm(light)):.2g} mm on the light" if all(v is not None for v in light)
                 else "")
        bars_note = ("error bars (+-): block sandwich (correlated residuals) plus the pixel footprint's shift "
                     f"(robust.footprint_shift{moved})")
        if reported.get("widened_by", 1.0) > 1.0:
            bars_note += (f", widened {reported['widened_by']:.2g}x for what the model lacks (a smooth residual "
                          f"{reported['model_lacks']:.2g}x the noise floor: see the goodness of fit)")
    if bars_note and reported.get("field_of_view"):
        fov = reported["field_of_view"]
        moved = "" if fov.get("light_shift_m") is None else f"; the light moves {1e3 * fov['light_shift_m']:.3g} mm"
        bars_note += (f"; plus the field of view's uncertainty (no EXIF: {fov['vfov_deg']:.2f} +- {fov['std_deg']:.2f} "
                      f"deg from the board{moved} per sigma of it)")
    return bars, bars_note


def _parameter_rows(x: dict[str, float], width: int, truth: dict[str, Any] | None,
                    bars: dict[str, float]) -> list[str]:
    """One line per fitted parameter: its value, the truth and the error where known, the error bar and the
    error in sigmas."""
    lines: list[str] = []
    for name, value in x.items():
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
    return lines


def undetermined_lines(why: dict[str, str], shown: set[str]) -> list[str]:
    """The fitted parameters the photo does not determine, grouped by the reason."""
    groups: dict[str, list[str]] = {}
    for name, reason in why.items():
        if name in shown or name.startswith("products."):
            groups.setdefault(reason, []).append(name)
    return [f"not determined: {', '.join(names)}: {reason}" for reason, names in groups.items()]


def model_lines(model: dict[str, Any], fitted: dict[str, Any]) -> list[str]:
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
                     + (f"; at most {ev['loss_with_nested']:.4g} with its products' best" if ev.get("raised") else "")
                     + (f", BIC {-bic:+.4g}" if bic is not None else "")
                     + (f"; {100 * ev['earlier_gain']:+.1f}% before them)" if "earlier_gain" in ev else ")"))
        held = ev.get("held_out") or {}
        if "gain" in held:
            lines.append(f"    held out ({held['folds']} folds of {held['block']}x{held['block']}-pixel blocks): "
                         f"{held['loss_without']:.4g} -> {held['loss_with']:.4g} with it, {100 * held['gain']:+.1f}% "
                         f"(at least {100 * HELD_OUT_GAIN:g}% needed)")
        if ev.get("lobe") == "coat":
            lines.append(f"    lobe: a clear coat (GGX roughness {ev['coat']['roughness']:.3g}, IOR {ev['coat']['ior']:g}), "
                         f"its loss {ev['coat']['loss_with']:.4g} against Blinn-Phong's {ev['blinn_phong']['loss_with']:.4g}")
        elif ev.get("lobe"):
            lines.append("    lobe: Blinn-Phong (a clear coat explained the highlight no better)")
    chosen = model.get("norm")
    if chosen and chosen.get("median_z") is not None:
        lines.append(f"  norm: {chosen['used']} (the L1 fit's median residual {chosen['median_z']:.2g}x the photo's "
                     f"own error; {chosen['threshold']:g}x or more is dense and takes l2)")
    if "environment" in terms and fitted.get("environment"):
        lines.append("  environment radiance (r g b): " + "  ".join(f"{v:.4g}" for v in fitted["environment"]))
    return lines + camera_lines(model.get("camera") or {})


def camera_lines(camera: dict[str, Any]) -> list[str]:
    """The camera terms (vignetting, tone curve) the fit used, and the held-out evidence for each."""
    if not camera:
        return []
    terms = camera.get("terms") or []
    lines = [f"camera: {' + '.join(terms) if terms else 'sRGB, no vignetting'}"]
    if "not_tested" in camera:
        lines.append(f"  not tested: {camera['not_tested']}")
    for term, ev in (camera.get("evidence") or {}).items():
        lines.append(f"  {term}: {'added' if ev['selected'] else 'not added'} (held-out L1 residual "
                     f"{ev['held_out_l1_without']:.4g} -> {ev['held_out_l1']:.4g} with it, {100 * ev['gain']:+.1f}%)")
    v = camera.get("vignetting")
    if v:
        lines.append("  vignetting: " + ("from the flat field" if v.get("source") == "flat field" else
                                         f"cos^4 x (1 + {v['k1']:.3g} r^2 + {v['k2']:.3g} r^4)")
                     + (f", corners at {100 * v['corner']:.0f}% of the centre" if "corner" in v else ""))
    if camera.get("tone"):
        lines.append("  tone curve (linear at the file's values " + ", ".join(f"{k:g}" for k in camera["tone"]["knots"])
                     + "): " + " ".join(f"{x:.3g}" for x in camera["tone"]["linear_at_knots"]))
    return lines


def distance_lines(distance: dict[str, Any] | None) -> list[str]:
    """The light as the photo fixes it: its direction from the subject and its distance, each +- sigma, or
    the distance as not determined with the reason (:mod:`rtloop.uncertainty.light`)."""
    if not distance or distance.get("direction_sigma_deg") is None:
        return []
    line = (f"light from the subject: direction +- {distance['direction_sigma_deg']:.2g} deg, distance "
            f"{distance['distance_m']:.4g} m")
    if distance["distance_determined"]:
        return [line + f" +- {distance['distance_sigma_m']:.2g} m"]
    return [line + " not determined", f"  ({distance['why']})"]
