"""Edits of a scene's fit bounds (widened, narrowed, restored), made by the native scene itself: no round
trip through JSON text."""

from __future__ import annotations

from typing import Any

from ..scene import Scene

__all__ = ["narrowed", "restore_bounds", "with_bounds"]


def with_bounds(scene: Scene, changes: dict[str, tuple[Any, Any]]) -> Scene:
    """The scene with the fit bounds of some paths replaced: ``{path: (min, max)}``."""
    return scene.with_bounds(changes)


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
    return scene.with_fit(original)
