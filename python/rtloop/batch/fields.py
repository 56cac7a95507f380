"""The fields of a job line and of the options every job shares: each one's kind checked where the job is
read, so that a wrong kind (``"crop": "no"``, ``"scene": null``, an id that is a path) is one line naming the
field, not a fit that runs with it misread. Values in range are :func:`rtloop.fit`'s to check (a job error)."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable
from typing import Any

from ..errors import RtloopError
from ..fit.protocol import LIMITS

__all__ = ["FIT_OPTIONS", "OPTIONS", "READ_OPTIONS", "RESERVED", "check_id", "check_options", "check_seed"]

#: Per-job options passed on to :func:`rtloop.fit` (``loss_space`` is the CLI's name for ``space``).
FIT_OPTIONS = ("protocol", "population", "generations", "f", "cr", "norm", "space", "optimizer", "polish",
               "clip", "uncertainty", "pixels_per_object", "environment", "interreflection",
               "highlights", "footprint", "framing", "vignetting", "tone", "lights")
#: Per-job options of which files are read and how: :func:`rtloop.fit.files.load_inputs`.
READ_OPTIONS = ("response", "crop", "grey_card")
OPTIONS = FIT_OPTIONS + READ_OPTIONS
#: Names in the output folder that are the batch's own: no job may be called so.
RESERVED = frozenset({"results.jsonl"})

_ID = re.compile(r"[A-Za-z0-9_+-][A-Za-z0-9._+-]{0,127}")


def check_id(jid: Any, where: str) -> str:
    """A job id, which names its output folder: 1-128 letters, digits, '_', '+', '-' or '.', not starting
    with '.', and not one of the batch's own files."""
    if isinstance(jid, int) and not isinstance(jid, bool):
        jid = str(jid)
    if not isinstance(jid, str) or not _ID.fullmatch(jid):
        raise RtloopError(f"{where}: id {_short(jid)} must be 1-128 letters, digits, '_', '+', '-' or '.' "
                          "(not starting with '.'): it names the job's output directory")
    if jid in RESERVED:
        raise RtloopError(f"{where}: id {jid!r} is the name of the batch's own file in the output directory")
    return jid


def check_seed(seed: Any, where: str) -> int:
    lo, hi = LIMITS["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or not lo <= seed <= hi:
        raise RtloopError(f"{where}: 'seed' must be a whole number from {lo} to {hi}, got {_short(seed)}")
    return seed


def check_path(value: Any, where: str, key: str, optional: bool = False) -> str | None:
    if value is None and optional:
        return None
    if not isinstance(value, (str, os.PathLike)) or not str(value):
        raise RtloopError(f"{where}: '{key}' must be a path (a non-empty string), got {_short(value)}")
    return str(value)


def _short(value: Any) -> str:
    text = repr(value) if not isinstance(value, int) or abs(value) < 10**30 else "a huge number"
    return text if len(text) <= 60 else text[:57] + "..."


def _choice(*allowed: Any) -> Callable[[Any, str], Any]:
    def check(value: Any, name: str) -> Any:
        if isinstance(value, bool) and True not in allowed or not any(
                value == a and type(value) is type(a) for a in allowed):
            raise ValueError(f"one of {', '.join(map(repr, allowed))}")
        return value

    return check


def _kind(*kinds: type, what: str) -> Callable[[Any, str], Any]:
    def check(value: Any, name: str) -> Any:
        if isinstance(value, bool) and bool not in kinds or not isinstance(value, kinds):
            raise ValueError(what)
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(what)
        return value

    return check


def _generations(value: Any, name: str) -> Any:
    whole = _kind(int, what="a whole number or a pair of whole numbers")
    if isinstance(value, (list, tuple)):
        if len(value) != 2:
            raise ValueError("a whole number or a pair of whole numbers")
        return tuple(whole(v, name) for v in value)
    return whole(value, name)


def _grey_card(value: Any, name: str) -> Any:
    """None or false: no grey card (not even the scene's); {"mask": PNG, "reflectance": R}: this one."""
    if value is None or value is False:
        return None
    what = 'false, null or {"mask": PNG, "reflectance": R} with 0 < R <= 1'
    if not isinstance(value, dict) or set(value) != {"mask", "reflectance"}:
        raise ValueError(what)
    mask, refl = value["mask"], value["reflectance"]
    if not isinstance(mask, str) or not mask or isinstance(refl, bool) or not isinstance(refl, (int, float)):
        raise ValueError(what)
    if not 0 < refl <= 1:
        raise ValueError(what)
    return {"mask": mask, "reflectance": float(refl)}


def _vignetting(value: Any, name: str) -> Any:
    """"auto", "on", "off" or [k1, k2] (two finite numbers: the lens's falloff given)."""
    what = '"auto", "on", "off" or [k1, k2] (two finite numbers)'
    if isinstance(value, str) and value in ("auto", "on", "off"):
        return value
    if isinstance(value, (list, tuple)) and len(value) == 2 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        return (float(value[0]), float(value[1]))
    raise ValueError(what)


def _lights(value: Any, name: str) -> Any:
    """"auto" or a whole number (1 to 8 is rtloop.fit's to check: a job error)."""
    if value == "auto" and isinstance(value, str) or isinstance(value, int) and not isinstance(value, bool):
        return value
    raise ValueError('"auto" or a whole number of lights (1 to 8)')


_NUMBER = _kind(int, float, what="a number")
_WHOLE = _kind(int, what="a whole number")
_TEXT = _kind(str, what="text")
_BOOL = _kind(bool, what="true or false")
_CHECKS: dict[str, Callable[[Any, str], Any]] = {
    "protocol": _TEXT, "population": _WHOLE, "generations": _generations, "f": _NUMBER, "cr": _NUMBER,
    "norm": _TEXT, "space": _choice("auto", "linear", "srgb"), "optimizer": _TEXT, "polish": _WHOLE,
    "clip": _BOOL, "uncertainty": _choice(True, False, "bootstrap"), "pixels_per_object": _WHOLE,
    "environment": _choice("auto", "on", "off"), "interreflection": _choice("auto", "on", "off"),
    "highlights": _choice("auto", "off"), "footprint": _choice("auto", "silhouette", "on", "off", True, False),
    "framing": _choice("check", "correct", "off"), "vignetting": _vignetting, "tone": _choice("auto", "on", "off"),
    "lights": _lights, "response": _TEXT, "crop": _BOOL, "grey_card": _grey_card,
}


def check_options(options: dict[str, Any], where: str) -> dict[str, Any]:
    """``options`` (names of :data:`OPTIONS`) with each value's kind checked; unknown names refused."""
    unknown = sorted(set(options) - set(OPTIONS), key=str)
    if unknown:
        known = ", ".join(("id", "scene", "photo", "seed", "mask", *OPTIONS))
        raise RtloopError(f"{where}: unknown field{'s' if len(unknown) > 1 else ''} "
                          f"{', '.join(_short(u) for u in unknown)} (known: {known})")
    checked = {}
    for name, value in options.items():
        try:
            checked[name] = _CHECKS[name](value, name)
        except ValueError as e:
            raise RtloopError(f"{where}: '{name}' must be {e}, got {_short(value)}") from None
    return checked
