"""What the photo determines: which scalings are degenerate (intensity x albedo), and which objects no
lit pixel shows (their albedo keeps the scene's value)."""

from __future__ import annotations

from typing import Any

from .. import _native
from ..scene import Scene, scene_to_dict
from .products import unit_light

__all__ = ["identifiability", "keep_undetermined", "lit_pixel_counts"]


def identifiability(scene: Scene, paths: list[str]) -> dict[str, Any]:
    """Whether the image fixes only products of the free parameters (``degenerate``), which ones, and why."""
    d = scene_to_dict(scene)
    albedo_paths = [p for p in paths if p.endswith(".albedo")]
    light_scale = [p for p in paths if p in ("light.intensity", "light.color", "exposure")]
    specular_paths = [p for p in paths if p.endswith(".specular")]
    # Known ambient light measures the intensity (albedo x ambient against albedo x intensity); a free one
    # scales with the light like the intensity does.
    ambient_free = "ambient" in paths
    no_ambient = all(v == 0 for v in d["ambient"]) or ambient_free
    # A highlight of known strength (a fixed, non-zero specular) measures the light's intensity; a free
    # specular scales with the intensity like an albedo does.
    known_specular = any(
        o["material"]["specular"] != 0 and f"objects.{o['name']}.specular" not in paths for o in d["objects"]
    )
    degenerate = bool((albedo_paths or specular_paths) and light_scale and no_ambient and not known_specular)
    info: dict[str, Any] = {"degenerate": degenerate}
    if degenerate:
        info["determined"] = [f"{'*'.join(light_scale)}*{p}" for p in albedo_paths + specular_paths]
        if ambient_free:
            info["determined"] += [f"ambient*{p}" for p in albedo_paths]
        info["note"] = (
            ("a free ambient light (which scales with the light)" if ambient_free else "no ambient light")
            + " and no highlight of known strength: the image fixes only light intensity x "
            "albedo per object and channel (see 'products'), and intensity x specular; the intensity is "
            "kept at the scene's value (the paper protocol: stage 1's value) unless an albedo or a specular "
            "would exceed its bounds, in which case the light is made just bright enough"
        )
    elif len(light_scale) > 1:
        info["degenerate"] = True
        info["determined"] = ["*".join(light_scale)]
        info["note"] = f"{' and '.join(light_scale)} scale the image together; only their product is determined"
    return info


def lit_pixel_counts(scene: Scene) -> list[int]:
    """Per object: how many of its visible pixels receive direct light from the scene's light."""
    d = scene_to_dict(scene)
    lit = unit_light(d) > 0
    ids = _native.object_ids(scene)
    return [int(((ids == k) & lit).sum()) for k in range(len(d["objects"]))]


def keep_undetermined(fitted: Scene, original: Scene, paths: list[str], ident: dict[str, Any],
                      counts: list[int] | None = None) -> Scene:
    """An object the fitted light leaves unlit in every visible pixel says nothing about its albedo (a
    sphere lit only from behind, one hidden by another): report it and keep the scene's own value.
    ``counts``: lit pixels per object when the search already knows them (else rendered here)."""
    fd = scene_to_dict(fitted)
    if ("ambient" in paths or any(v != 0 for v in fd["ambient"]) or any(fd.get("environment", [0.0] * 3))
            or fd.get("interreflection", False)):
        return fitted  # ambient or environment light, or the bounce, still shows the albedo
    if counts is None:
        counts = lit_pixel_counts(fitted)
    undetermined = []
    for name, n in zip(fitted.object_names, counts):
        p = f"objects.{name}.albedo"
        if p in paths and n == 0:
            undetermined.append(p)
            fitted = fitted.with_params(original.get_params([p]), [p])
    if undetermined:
        ident["undetermined"] = undetermined
        ident["undetermined_note"] = (
            "no visible pixel of these objects receives direct light from the fitted light, so the photo "
            "does not determine their albedo; the scene's own values are kept"
        )
    return fitted
