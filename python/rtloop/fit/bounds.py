"""Edits of a scene's fit bounds (widened, narrowed, restored). One function each, through the scene
dict for now, until the native scene edits its bounds itself."""

from __future__ import annotations

from typing import Any

from ..scene import Scene, load_scene, scene_to_dict

__all__ = ["narrowed", "restore_bounds", "with_bounds"]


def with_bounds(scene: Scene, changes: dict[str, tuple[Any, Any]]) -> Scene:
    """The scene with the fit bounds of some paths replaced: ``{path: (min, max)}``."""
    d = scene_to_dict(scene)
    for path, (lo, hi) in changes.items():
        d["fit"][path] = {"min": lo, "max": hi}
    return load_scene(d)


def narrowed(scene: Scene, paths: list[str], fraction: float = 0.15) -> Scene:
    """The scene with the bounds of ``paths`` shrunk to +-fraction of their range around the current values."""
    changes = {}
    for p in paths:
        vals = scene.get_params([p])
        b = scene.bounds([p])
        lo = [max(l0, v - fraction * (h0 - l0)) for v, (l0, h0) in zip(vals, b)]
        hi = [min(h0, v + fraction * (h0 - l0)) for v, (l0, h0) in zip(vals, b)]
        changes[p] = (lo, hi)
    return with_bounds(scene, changes)


def restore_bounds(scene: Scene, original: Scene) -> Scene:
    """The scene with the fit section (bounds) of ``original``."""
    d = scene_to_dict(scene)
    d["fit"] = scene_to_dict(original)["fit"]
    return load_scene(d)
