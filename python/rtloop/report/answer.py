"""The answer a report opens with: where the light is (in mm, with its error bar), what the photo fixes
of the colours (in %), the verdict, and a picture of the scene from above and from the side with the
fitted light and its error ellipse. :func:`answer` gathers the numbers, :func:`scene_views` draws."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["answer", "colour_rows", "light_sentence", "scene_views", "split_names", "verdict_sentence"]

_XYZ = ("x", "y", "z")
#: The views: (title, horizontal axis, vertical axis) as indices into x, y, z.
VIEWS = (("from above (x, z)", 0, 2), ("from the side (z, y)", 2, 1))
#: The error ellipse is drawn magnified (by a whole factor, said in the legend) until its long axis spans at
#: least this fraction of its view.
MIN_ELLIPSE = 0.1


def split_names(result: Any) -> list[str]:
    """The fit parameters the photo does not fix one by one (the factors of a determined product, such as
    the light's intensity and the albedos without ambient light): their values are a convention."""
    ident = getattr(result, "identifiability", None) or {}
    if not ident.get("degenerate"):
        return []
    factors = {p for term in ident.get("determined", []) if "*" in term for p in term.split("*")}
    return [n for n in result.scene.param_names() if any(n == p or n.startswith(p + ".") for p in factors)]


def _sigmas(unc: dict[str, Any]) -> tuple[dict[str, float], str]:
    """Per name, the error bar the fit reports (its reported bars, ``u["bars"]``: the block sandwich's widened
    by what the model lacks, none where the photo does not determine it; else the sandwich's where it ran,
    else Gauss-Newton's), and which it is."""
    reported = unc.get("bars") or {}
    if any(v is not None for v in (reported.get("sigma") or {}).values()):
        w = float(reported.get("widened_by") or 1.0)
        return ({k: v for k, v in reported["sigma"].items() if v is not None},
                "block sandwich (correlated residuals)" + (f", widened {w:.2g}× for what the model lacks"
                                                             if w > 1 else ""))
    robust = (unc.get("robust") or {}).get("sigma") or {}
    plain = unc.get("sigma") if isinstance(unc.get("sigma"), dict) else {}
    if any(v is not None for v in robust.values()):
        return {k: v for k, v in robust.items() if v is not None}, "block sandwich (correlated residuals)"
    return {k: v for k, v in plain.items() if v is not None}, "Gauss-Newton"


def _light_covariance(unc: dict[str, Any], sigma: dict[str, float]) -> np.ndarray | None:
    """The light position's 3x3 covariance (m^2): the fit's correlations scaled by ``sigma``."""
    names = unc.get("names") or []
    corr = unc.get("correlation")
    want = [f"light.position.{c}" for c in _XYZ]
    if corr is None or not all(n in names and sigma.get(n) for n in want):
        return None
    idx = [names.index(n) for n in want]
    c = np.asarray(corr, float)[np.ix_(idx, idx)]
    s = np.array([sigma[n] for n in want])
    cov = c * np.outer(s, s)
    return cov if np.all(np.isfinite(cov)) else None


def answer(result: Any, terr: dict[str, Any] | None = None) -> dict[str, Any]:
    """The numbers the report opens with: ``light`` (``kind``, and for a point light ``position_mm``,
    ``sigma_mm`` per axis, ``worse_axis_mm``, ``covariance_m2``, ``error_mm`` against a truth), ``colours``
    (per object: ``what`` ("product" or "albedo"), R, G, B ``values``, ``sigma_percent`` and, with a
    truth, ``error_percent``), ``verdict`` and ``ratio`` (the residual against the photo's noise floor),
    ``diagnosis`` (what the residual is made of, per object), ``not_determined`` (name: why), ``bars`` (which
    error bars), ``sigmas`` (theirs, per parameter) and ``split`` (:func:`split_names`)."""
    unc = getattr(result, "uncertainty", None) or {}
    sigma, bars = _sigmas(unc)
    d = result.scene.to_dict()
    light: dict[str, Any] = {"kind": d["light"].get("type", "point")}
    if "position" in d["light"]:
        pos = np.asarray(d["light"]["position"], float)
        light["position_mm"] = (1000 * pos).tolist()
        light["sigma_mm"] = [1000 * sigma[n] if sigma.get(n) else None for n in
                             (f"light.position.{c}" for c in _XYZ)]
        worse = (unc.get("robust") or {}).get("light_position_m")
        light["worse_axis_mm"] = None if worse is None else 1000 * float(worse)
        cov = _light_covariance(unc, sigma)
        light["covariance_m2"] = None if cov is None else cov.tolist()
        if terr is not None and "light_position_m" in terr:
            light["error_mm"] = 1000 * float(terr["light_position_m"])
    elif "direction" in d["light"]:
        light["direction"] = list(map(float, d["light"]["direction"]))
        cone = unc.get("light_direction") or {}
        light["sigma_deg"] = (unc.get("robust") or {}).get("light_direction_deg") or cone.get("angle_deg")
    good = getattr(result, "goodness", None) or {}
    return {"light": light, "colours": _colours(result, d, unc, terr), "verdict": good.get("verdict"),
            "ratio": good.get("ratio"), "diagnosis": good.get("diagnosis"), "bars": bars, "sigmas": sigma,
            "not_determined": (unc.get("bars") or {}).get("not_determined", {}), "split": split_names(result)}


def _colours(result: Any, d: dict[str, Any], unc: dict[str, Any], terr: dict[str, Any] | None) -> dict[str, Any]:
    """Per object, the colour numbers the photo fixes: the products where only they are determined, else
    the albedos; with their relative error bars and, against a truth, their relative errors (in %)."""
    products = getattr(result, "products", None) or {}
    degenerate = bool((getattr(result, "identifiability", None) or {}).get("degenerate"))
    robust = (unc.get("robust") or {}).get("product_sigma") or {}
    plain = unc.get("product_sigma") if isinstance(unc.get("product_sigma"), dict) else {}
    sig = {**plain, **{k: v for k, v in robust.items() if v is not None}}
    if (unc.get("bars") or {}).get("sigma"):  # the reported bars: none where not determined
        sig = dict(unc["bars"]["sigma"])
    bars = _sigmas(unc)[0]
    out: dict[str, Any] = {}
    for obj in d["objects"]:
        name = obj["name"]
        if degenerate and name in products:
            values = [float(v) for v in products[name]][:3]
            sigmas = [sig.get(f"products.{name}.{c}") for c in "rgb"]
            what = "product"
            err = None if terr is None else terr.get("product_relative", {}).get(name)
        else:
            albedo = (obj.get("material") or {}).get("albedo")
            if albedo is None or not any(f"objects.{name}.albedo.{c}" in result.x for c in "rgb"):
                continue
            values = [float(v) for v in albedo]
            sigmas = [bars.get(f"objects.{name}.albedo.{c}") for c in "rgb"]
            what = "albedo"
            err = None
            if terr is not None:
                true = [terr["values"].get(f"objects.{name}.albedo.{c}") for c in "rgb"]
                if all(t is not None for t in true) and np.linalg.norm(true) > 0:
                    err = float(np.linalg.norm(np.subtract(values, true)) / np.linalg.norm(true))
        out[name] = {
            "what": what, "values": values,
            "sigma_percent": [None if s is None or v == 0 else 100 * float(s) / abs(v) for s, v in zip(sigmas, values)],
            "error_percent": None if err is None or not math.isfinite(err) else 100 * err,
        }
    return out


# --- the picture ---------------------------------------------------------------------------------------------


def _camera_frame(cam: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    eye = np.asarray(cam["position"], float)
    fwd = np.asarray(cam["look_at"], float) - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(cam.get("up", [0, 1, 0]), float))
    right /= np.linalg.norm(right) or 1.0
    up = np.cross(right, fwd)
    return eye, fwd, right, up


def _extent(d: dict[str, Any], light: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The box the views show: the camera, the spheres, mesh positions and the light, with a margin."""
    pts = [np.asarray(d["camera"]["position"], float), np.asarray(d["camera"]["look_at"], float)]
    for o in d["objects"]:
        if o.get("shape") == "sphere":
            c, r = np.asarray(o["center"], float), float(o["radius"])
            pts += [c - r, c + r]
        elif "position" in o:
            pts.append(np.asarray(o["position"], float))
    if light is not None:
        pts.append(light)
    lo, hi = np.min(pts, axis=0), np.max(pts, axis=0)
    pad = 0.12 * max(float(np.max(hi - lo)), 1e-3)
    return lo - pad, hi + pad


def _ellipse(cov2: np.ndarray) -> tuple[float, float, float]:
    """(width, height, angle in degrees) of the 1-sigma ellipse of a 2x2 covariance."""
    vals, vecs = np.linalg.eigh(cov2)
    vals = np.clip(vals, 0.0, None)
    major = vecs[:, 1]
    return 2 * math.sqrt(vals[1]), 2 * math.sqrt(vals[0]), math.degrees(math.atan2(major[1], major[0]))


def scene_views(result: Any, info: dict[str, Any], truth_light: list[float] | None = None) -> tuple[Any, dict[str, Any]]:
    """A figure of two views of the fitted scene (from above, from the side): the camera and its field of
    view, the spheres, the planes where they cross the view, the fitted light with its 1-sigma error
    ellipse (magnified to be seen, by the factor in the legend) and the true light when known. Returns the
    Figure and what it drew per view: ``light`` (m), ``ellipse`` (width, height, angle; m, m, degrees, not
    magnified), ``magnified``."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Ellipse

    d = result.scene.to_dict()
    light = np.asarray(d["light"]["position"], float) if "position" in d["light"] else None
    cov = None if info["light"].get("covariance_m2") is None else np.asarray(info["light"]["covariance_m2"])
    lo, hi = _extent(d, light)
    eye, fwd, right, up = _camera_frame(d["camera"])
    fig = Figure(figsize=(9.6, 4.6))
    axes = fig.subplots(1, 2)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.2, top=0.92, wspace=0.18)
    drawn: dict[str, Any] = {}
    for ax, (title, a, b) in zip(axes, VIEWS):
        ax.set_title(title, fontsize=10)
        ax.set_xlabel(f"{_XYZ[a]} (m)", fontsize=8)
        ax.set_ylabel(f"{_XYZ[b]} (m)", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.set_aspect("equal", adjustable="box")
        ax.grid(alpha=0.2)
        span = float(max(hi[a] - lo[a], hi[b] - lo[b]))
        for o in d["objects"]:
            if o.get("shape") == "sphere":
                c = o["center"]
                ax.add_patch(Circle((c[a], c[b]), o["radius"], facecolor=_face(o), edgecolor="0.3", lw=0.8))
                ax.text(c[a], c[b], o["name"], fontsize=7, ha="center", va="center", color="0.1")
            elif o.get("shape") == "plane":
                _plane(ax, o, a, b, lo, hi)
            elif "position" in o:
                p = o["position"]
                ax.plot([p[a]], [p[b]], marker="s", color="0.4", ms=6)
                ax.text(p[a], p[b], " " + o["name"], fontsize=7, va="center")
        # The camera: its position and the four edges of its field of view, seen in this view.
        tv = math.tan(math.radians(float(d["camera"]["vfov_deg"])) / 2)
        th = tv * d["image"]["width"] / d["image"]["height"]
        for sx in (-1, 1):
            for sy in (-1, 1):
                ray = fwd + sx * th * right + sy * tv * up
                end = eye + 0.9 * span * ray / np.linalg.norm(ray)
                ax.plot([eye[a], end[a]], [eye[b], end[b]], color="0.45", lw=0.8, ls="--")
        ax.plot([eye[a]], [eye[b]], marker="^", color="0.15", ms=8, label="camera")
        view: dict[str, Any] = {}
        if light is not None:
            ax.plot([light[a]], [light[b]], marker="*", color="#e08a00", ms=10, mec="0.2", label="fitted light",
                    zorder=5)
            view["light"] = [float(light[a]), float(light[b])]
            if cov is not None:
                w, h, ang = _ellipse(cov[np.ix_([a, b], [a, b])])
                k = max(1, math.ceil(MIN_ELLIPSE * span / max(w, 1e-12))) if w > 0 else 1
                ax.add_patch(Ellipse((light[a], light[b]), k * w, k * h, angle=ang, fill=False, color="#c23b22",
                                     lw=1.8, zorder=8, label="1σ error" + (f" (drawn ×{k})" if k > 1 else "")))
                view.update(ellipse=[w, h, ang], magnified=k)
        if truth_light is not None:
            t = truth_light
            ax.plot([t[a]], [t[b]], marker="x", color="0.1", ms=9, mew=1.8, label="true light", zorder=7)
        ax.set_xlim(lo[a], hi[a])
        ax.set_ylim(lo[b], hi[b])
        drawn[title] = view
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
    return fig, drawn


def _face(o: dict[str, Any]) -> tuple[float, float, float, float]:
    albedo = np.clip(np.asarray((o.get("material") or {}).get("albedo", [0.7, 0.7, 0.7]), float), 0, 1)
    return (*(albedo / max(float(albedo.max()), 1e-6) * 0.85 + 0.1), 0.75)


def _plane(ax: Any, o: dict[str, Any], a: int, b: int, lo: np.ndarray, hi: np.ndarray) -> None:
    """A plane where it crosses the view's plane through its own point, or shaded when it is the view's."""
    n, p = np.asarray(o["normal"], float), np.asarray(o["point"], float)
    if abs(n[a]) < 1e-9 and abs(n[b]) < 1e-9:  # seen face on: say so
        ax.text(0.01, 0.01, f"{o['name']}: the plane of this view", transform=ax.transAxes, fontsize=7,
                color="0.4")
        return
    if abs(n[b]) >= abs(n[a]):
        xs = np.array([lo[a], hi[a]])
        ys = p[b] - n[a] * (xs - p[a]) / n[b]
    else:
        ys = np.array([lo[b], hi[b]])
        xs = p[a] - n[b] * (ys - p[b]) / n[a]
    ax.plot(xs, ys, color="0.35", lw=2.0, solid_capstyle="butt")
    ax.text(xs[0], ys[0], f" {o['name']}", fontsize=7, color="0.3", va="bottom")


# --- the words ---------------------------------------------------------------------------------------------


def _num(v: float, digits: int = 4) -> str:
    return f"{v:.{digits}g}"


def _pct(v: float | None) -> str:
    if v is None:
        return ""
    return f"{v:.2g} %" if v < 10 else f"{v:.0f} %"


def light_sentence(info: dict[str, Any]) -> str:
    """One line: where the light is, with its error bars (mm), and against the truth when known."""
    light = info["light"]
    if "position_mm" in light:
        parts = []
        for c, v, s in zip(_XYZ, light["position_mm"], light["sigma_mm"]):
            parts.append(f"{c} {v:.1f}" + ("" if s is None else f" ± {s:.2g}"))
        text = "Light at " + ", ".join(parts) + " mm"
        if any(s is not None for s in light["sigma_mm"]):
            text += f" (1σ, {info['bars']}"
            text += (f"; ± {light['worse_axis_mm']:.2g} mm along its worse axis)" if light.get("worse_axis_mm")
                     else ")")
        if light.get("error_mm") is not None:
            text += f"; {light['error_mm']:.2g} mm from the true light"
        return text + "."
    if "direction" in light:
        text = "Light from direction " + ", ".join(f"{v:.4f}" for v in light["direction"])
        if light.get("sigma_deg"):
            text += f" (± {light['sigma_deg']:.2g}° along its worse axis, 1σ)"
        return text + "."
    return f"Light: {light['kind']} (its position is not fitted)."


def colour_rows(info: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """The colours table: per object, what the photo fixes (R, G, B with their 1σ in %), and against the
    truth its relative error in %."""
    truth = any(c["error_percent"] is not None for c in info["colours"].values())
    header = ["object", "the photo fixes", "R", "G", "B"] + (["error against the truth"] if truth else [])
    body = []
    for name, c in info["colours"].items():
        if c["what"] == "product":
            what = "light intensity × albedo (W/sr)"
            cells = [_num(v) + ("" if s is None else f" ± {_pct(s)}") for v, s in zip(c["values"], c["sigma_percent"])]
        else:
            what = "albedo"
            cells = [f"{100 * v:.1f} %" + ("" if s is None else f" ± {_pct(s)}")
                     for v, s in zip(c["values"], c["sigma_percent"])]
        row = [name, what, *cells]
        if truth:
            row.append("" if c["error_percent"] is None else _pct(c["error_percent"]))
        body.append(row)
    return header, body


def verdict_sentence(info: dict[str, Any]) -> str | None:
    if not info.get("verdict"):
        return None
    how = "" if info.get("ratio") is None else f" (residual {info['ratio']:.2g}× the photo's noise floor)"
    why = f" By object: {info['diagnosis']}." if info.get("diagnosis") else ""
    return f"Verdict: {info['verdict']}{how}.{why}"
