"""Loading and saving scenes. Parsing and validation live in the Rust core (one owner of the format);
this module only turns files and dicts into the JSON text it reads, with errors that name the file."""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path
from typing import Any

from ._files import write_text
from ._native import Scene
from .errors import RtloopError, SceneError, SceneTypeError

__all__ = ["MAX_INTENSITY", "MAX_MAGNITUDE", "Scene", "load_scene", "save_scene", "scene_to_dict"]

#: The largest magnitude of a scene number or fit bound but a direction's components: the core's
#: ``scene::MAX_MAGNITUDE`` (docs/scene-format.md: "Input limits"; tests/test_input_limits.py checks they
#: agree).
MAX_MAGNITUDE = 1e8
#: The largest light intensity (value or bound): it grows with distance squared (``scene::MAX_INTENSITY``).
MAX_INTENSITY = 1e20


def _first_non_finite(value: Any, path: str = "") -> str | None:
    """The dotted path of the first NaN or infinite float in a nested dict/list, else None."""
    if isinstance(value, float) and not math.isfinite(value):
        return path or "scene"
    if isinstance(value, dict):
        for k, v in value.items():
            found = _first_non_finite(v, f"{path}.{k}" if path else str(k))
            if found:
                return found
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            found = _first_non_finite(v, f"{path}[{i}]")
            if found:
                return found
    return None


def load_scene(source: str | os.PathLike[str] | dict[str, Any] | Scene) -> Scene:
    """Load and validate a scene from a JSON file path, a dict in the scene format, or a Scene (returned as is).

    Raises SceneError naming the field (``objects[0].radius: must be > 0 (got -1)``); for a file, the
    message starts with the file name. A mesh object's relative ``file`` is read from the scene file's
    folder, or for a dict from the current directory.
    """
    if isinstance(source, Scene):
        return source
    if isinstance(source, dict):
        try:
            text = json.dumps(source, allow_nan=False)
        except (TypeError, ValueError, RecursionError) as e:
            # Only now walk the dict (slow) to name the field holding a NaN or infinity; a dict that
            # contains itself (or nests past Python's recursion limit) is no JSON.
            try:
                bad = _first_non_finite(source)
            except RecursionError:
                bad = None
            if bad:
                raise SceneError(f"{bad}: must be a finite number (got NaN or infinity)") from None
            raise SceneError(f"scene: cannot be written as JSON ({e})") from None
        try:
            return Scene(text)
        except SceneError as e:
            # Positions in the JSON text we made from the dict mean nothing to the caller.
            raise SceneError(re.sub(r" at line \d+ column \d+$", "", str(e))) from None
    if isinstance(source, (str, os.PathLike)):
        from ._files import MAX_TEXT_BYTES, read_regular

        path = Path(source)
        if not os.path.lexists(path):
            raise RtloopError(f"{path}: scene file not found")
        try:
            text = read_regular(path, limit=MAX_TEXT_BYTES, what="scene file").decode("utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise RtloopError(f"{path}: cannot read scene file ({e})") from None
        try:
            return Scene(text, path.parent)
        except SceneError as e:
            raise SceneError(f"{path}: {e}") from None
    raise SceneTypeError(f"scene: expected a path, a dict or a Scene, not {type(source).__name__}")


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    """The scene in the public format as a plain dict (defaults written out)."""
    return scene.to_dict()


def save_scene(scene: Scene | dict[str, Any], path: str | os.PathLike[str]) -> None:
    """Write a scene (or any JSON-able dict) to ``path`` atomically: a temporary file renamed into place."""
    data = scene_to_dict(scene) if isinstance(scene, Scene) else scene
    try:
        text = json.dumps(data, indent=2, allow_nan=False) + "\n"
    except (TypeError, ValueError, RecursionError) as e:  # NaN, infinity, a value JSON has no form for, a loop
        raise SceneError(f"{os.fspath(path)}: the scene cannot be written as JSON ({e}); nothing written") from None
    write_text(path, text)
