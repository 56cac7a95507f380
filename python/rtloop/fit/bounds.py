"""Edits of a scene's fit bounds (widened, narrowed, restored), made by the native scene itself: no round
trip through JSON text."""

from __future__ import annotations

from typing import Any

from ..scene import Scene

__all__ = ["AT_BOUND", "at_bounds", "narrowed", "restore_bounds", "with_bounds"]

#: A fitted value this close to a bound (as a fraction of its range) is reported as at the bound.
AT_BOUND = 1e-6


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


def at_bounds(scene: Scene, paths: list[str]) -> list[str]:
    """A doubt naming the fitted values at one of their bounds (a range too narrow, or a wrong input)."""
    at = []
    for p in paths:
        for n, v, (lo, hi) in zip(scene.param_names([p]), scene.get_params([p]), scene.bounds([p])):
            near = AT_BOUND * (hi - lo)
            if hi <= lo:
                continue
            # a physical limit is no doubt: 0 for what cannot be negative, 1 for an albedo (a yellow ball's red)
            if (v - lo <= near and (lo != 0 or p == "light.position")) or (hi - v <= near and not (p.endswith(".albedo") and hi == 1)):
                at.append(f"{n} = {v:.6g}")
    if not at:
        return []
    return [(f"fitted values at their fit bounds: {', '.join(at)} (widen the bounds if the truth may lie "
             "beyond)")]
