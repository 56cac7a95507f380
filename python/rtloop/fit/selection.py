"""Which image terms a fit uses, decided from the photo (README: "Image terms").

The default fit starts from the model every photo needs (direct light) and adds a term only where the photo
shows it: nested models compared at the fitted light, by the Bayesian information criterion of the fit's
own loss and by the size of the improvement. Today's term is the occluded environment (a room's light
from every direction, darkened under and between the objects; :mod:`rtloop` renders it with the sky view
factor of ``render::environment``). A term costs nothing on a photo that does not select it: one extra
evaluation decides.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import _native
from ..errors import RtloopError
from ..scene import Scene, scene_to_dict
from .products import product_bounds

__all__ = ["ENVIRONMENT_MODES", "MIN_GAIN", "check_environment", "environment_evidence", "environment_given"]

#: ``fit(environment=...)``: "auto" (default) adds the term when the photo shows it, "on" always fits
#: it, "off" never (today's model).
ENVIRONMENT_MODES = ("auto", "on", "off")

#: The least relative reduction of the loss at the fitted light for "auto" to add a term. The information
#: criterion alone accepts any term that explains a few pixels better (a photo has ~10^4 of them, so
#: ln n per parameter is cheap), including a column that only soaks up some other mismatch; a term must also
#: explain a visible part of the residual.
MIN_GAIN = 0.05


def check_environment(mode: Any) -> str:
    """``mode`` if it is one of ENVIRONMENT_MODES, else an RtloopError naming the argument."""
    if mode not in ENVIRONMENT_MODES:
        raise RtloopError(f"environment: must be one of {', '.join(ENVIRONMENT_MODES)} (got {mode!r})")
    return str(mode)


def environment_given(scene: Scene) -> bool:
    """Whether the scene itself has the term: ``environment`` free in its fit section, or a value given."""
    return "environment" in scene.fit_paths or any(v != 0 for v in scene_to_dict(scene).get("environment", [0, 0, 0]))


def environment_evidence(scene: Scene, paths: list[str], x: list[float], target: np.ndarray,
                         pixels: np.ndarray | None, *, clip: bool, norm: str, space: str,
                         threads: int | None, active_pixels: int) -> dict[str, Any]:
    """Whether the occluded environment explains the photo better at the light ``x`` (of ``paths``) found
    without it: the closed-form loss without and with each object's environment column, the relative gain,
    the change in BIC (for the L1 and Huber norms, a Laplace likelihood: 2 n ln(L0/L1); for L2, Gaussian:
    n ln(L0/L1); minus k ln n for the k = 3 x objects added products), and the verdict."""
    pop = np.asarray([x], dtype=np.float64)
    loss = []
    for env in (False, True):
        v = _native.evaluate(scene, paths, target, pop, pixels=pixels, loss="l1_projected", clip=clip,
                             threads=threads, product_bounds=product_bounds(scene, env), norm=norm, space=space)
        loss.append(float(v[0, 0]))
    l0, l1 = loss
    n = 3 * max(int(active_pixels), 1)
    k = 3 * len(scene.object_names)
    gain = (l0 - l1) / l0 if l0 > 0 else 0.0
    per = n if norm == "l2" else 2 * n
    dbic = per * math.log(l0 / l1) - k * math.log(n) if l0 > 0 and l1 > 0 else (math.inf if l0 > l1 else -k * math.log(n))
    selected = bool(gain >= MIN_GAIN and dbic > 0)
    return {
        "loss_without": l0,
        "loss_with": l1,
        "gain": gain,
        "delta_bic": dbic if math.isfinite(dbic) else None,
        "selected": selected,
        "rule": f"added when the loss falls by at least {MIN_GAIN:.0%} and the BIC falls",
    }
