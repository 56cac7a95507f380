"""The camera's field of view as an uncertainty of the fit. A photo without EXIF gets its field of view from
the board (and the ball resting on the floor): rtloop-scene records it with the board's standard deviation
and the scene it builds at one standard deviation either side (``meta.acquisition.field_of_view``). The
fit is repeated on those two scenes (camera and ball posed at that field of view, the same photo, options and
seed); half the difference of each fitted value is its shift per standard deviation of the field of view,
added to its error bar in quadrature (a systematic error the residuals cannot show: docs/uncertainty.md)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from ..errors import RtloopError

__all__ = ["carry_field_of_view", "check_field_of_view", "flat_values"]

_CAMERA_KEYS = ("position", "look_at", "up", "vfov_deg")


def _number(value: Any, where: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or (
            positive and not value > 0):
        raise RtloopError(f"{where} must be a finite {'positive ' if positive else ''}number, got {_short(value)}")
    return float(value)


def _vector(value: Any, where: str) -> list[float]:
    if not isinstance(value, list) or len(value) != 3:
        raise RtloopError(f"{where} must be a list of 3 numbers, got {_short(value)}")
    return [_number(v, f"{where}[{i}]") for i, v in enumerate(value)]


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_field_of_view(record: Any, spheres: set[str], where: str) -> dict[str, Any] | None:
    """``meta.acquisition.field_of_view`` checked (``where`` names it in errors; ``spheres``: the names of
    the scene's spheres, which the alternates may move); None where it is absent or holds no alternates."""
    if record is None:
        return None
    if not isinstance(record, dict):
        raise RtloopError(f"{where} must be an object, got {_short(record)}")
    _number(record.get("vfov_deg"), f"{where}.vfov_deg", positive=True)
    _number(record.get("std_deg"), f"{where}.std_deg", positive=True)
    alternates = record.get("alternates", [])
    if not isinstance(alternates, list) or len(alternates) not in (0, 2):
        raise RtloopError(f"{where}.alternates must be a list of the 2 scenes at -1 and +1 standard deviation")
    checked = []
    for i, alt in enumerate(alternates):
        at = f"{where}.alternates[{i}]"
        if not isinstance(alt, dict) or not isinstance(alt.get("camera"), dict) or not isinstance(
                alt.get("objects", {}), dict):
            raise RtloopError(f"{at} must be an object with a camera and objects")
        camera = {k: (_number(alt["camera"].get(k), f"{at}.camera.{k}", positive=True) if k == "vfov_deg"
                      else _vector(alt["camera"].get(k), f"{at}.camera.{k}")) for k in _CAMERA_KEYS}
        if not camera["vfov_deg"] < 180:
            raise RtloopError(f"{at}.camera.vfov_deg must be under 180, got {camera['vfov_deg']}")
        objects = {}
        for name, obj in alt.get("objects", {}).items():
            if name not in spheres:
                raise RtloopError(f"{at}.objects: {_short(name)} is not a sphere of the scene")
            if not isinstance(obj, dict) or set(obj) != {"center"}:
                raise RtloopError(f"{at}.objects.{name} must be an object with a center")
            objects[name] = {"center": _vector(obj["center"], f"{at}.objects.{name}.center")}
        checked.append({"vfov_deg": _number(alt.get("vfov_deg", camera["vfov_deg"]), f"{at}.vfov_deg", positive=True),
                        "camera": camera, "objects": objects})
    if not checked:
        return None
    return {"vfov_deg": float(record["vfov_deg"]), "std_deg": float(record["std_deg"]), "alternates": checked}


def alternate_scene(scene: dict[str, Any], alternate: dict[str, Any]) -> dict[str, Any]:
    """The scene dict with the alternate's camera and sphere centres."""
    objects = [{**o, **alternate["objects"].get(o.get("name"), {})} for o in scene["objects"]]
    return {**scene, "camera": {**scene["camera"], **alternate["camera"]}, "objects": objects}


def flat_values(result: Any) -> dict[str, float]:
    """A fit's values by the names its error bars use: its parameters and ``products.<object>.<r|g|b>``."""
    values = dict(result.x)
    for obj, rgb in (result.products or {}).items():
        values.update({f"products.{obj}.{c}": float(v) for c, v in zip("rgb", rgb)})
    return values


def carry_field_of_view(result: Any, record: dict[str, Any], refit: Callable[[dict[str, Any]], Any],
                        scene: dict[str, Any]) -> dict[str, Any] | None:
    """Add the field of view's uncertainty to ``result``'s error bars (``uncertainty["bars"]``, and the
    bootstrap's sigma where it ran): each value's shift per standard deviation of the field of view, from
    ``refit`` (the fit, without uncertainty, of a scene dict) on the two alternates of ``record`` built from
    ``scene`` (the scene as given). Returns the record put in ``bars["field_of_view"]`` (None where the fit
    has no bars)."""
    u = result.uncertainty
    if not u or not isinstance(u.get("bars"), dict):
        return None
    low, high = (flat_values(refit(alternate_scene(scene, alt))) for alt in record["alternates"])
    shift = {n: 0.5 * (high[n] - low[n]) for n in flat_values(result) if n in low and n in high}
    light = [shift.get(f"light.position.{c}") for c in "xyz"]
    carried = {"vfov_deg": record["vfov_deg"], "std_deg": record["std_deg"], "shift": shift,
               "light_shift_m": math.sqrt(sum(v * v for v in light)) if all(v is not None for v in light) else None,
               "rule": "each sigma is sqrt(sigma^2 + shift^2): shift is half the change of the value between "
                       "the scenes rtloop-scene built at -1 and +1 standard deviation of the field of view"}
    for sigma in (u["bars"].get("sigma"), (u.get("bootstrap") or {}).get("sigma")):
        if isinstance(sigma, dict):
            for name, s in sigma.items():
                if s is not None and name in shift:
                    sigma[name] = math.hypot(float(s), shift[name])
    u["bars"]["field_of_view"] = carried
    return carried
