"""Image terms judged on held-out pixels (docs/methods.md, "Image terms"): the pixels a test takes split
into square blocks, the blocks dealt to folds in a fixed pattern, and per fold the closed form's products
solved on the other folds and the loss measured on the fold's own pixels (``_native.held_out``), in the
fit's norm and space. Summed over the folds every pixel is predicted once by products it did not inform:
a term that only soaks up a local mismatch (a few pixels the light's model misses) predicts less there
than it explains in-sample."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _native
from ..scene import Scene
from .spec import closed_form_spec

__all__ = ["HELD_OUT_BLOCK", "HELD_OUT_FOLDS", "HELD_OUT_GAIN", "HeldOut", "block_folds", "held_out_evidence",
           "held_out_loss"]

#: The side of a block, in image pixels (the test's every-other-pixel grid holds 4 x 4 of a block's pixels).
HELD_OUT_BLOCK = 8
#: The folds the blocks are dealt to: block (bx, by) goes to fold (bx + 2 by) mod HELD_OUT_FOLDS, so no
#: two blocks that share an edge or a corner share a fold.
HELD_OUT_FOLDS = 5
#: The least relative reduction of the held-out loss for "auto" to add a term, beside the in-sample rule:
#: the in-sample rule's own (``selection.MIN_GAIN``), measured on pixels the products were not fitted to.
HELD_OUT_GAIN = 0.05


def block_folds(pixels: np.ndarray, width: int, block: int = HELD_OUT_BLOCK,
                folds: int = HELD_OUT_FOLDS) -> np.ndarray:
    """Each of ``pixels`` (row-major indices into an image ``width`` wide)'s fold: its ``block`` x ``block``
    block (bx, by) dealt to fold (bx + 2 by) mod ``folds`` (uint8). Depends on the pixels' positions only."""
    p = np.asarray(pixels, dtype=np.int64)
    bx, by = (p % width) // block, (p // width) // block
    return ((bx + 2 * by) % folds).astype(np.uint8)


class HeldOut:
    """A held-out comparison's pixels' folds (one per pixel of the test, :func:`block_folds`) and the held-out
    loss of the model without the term tested: ``without`` computes it (once, when first asked: a photo
    whose terms the in-sample rule all rejects never pays for it)."""

    def __init__(self, folds: np.ndarray, without: Callable[[], float]):
        self.folds = folds
        self._without = without
        self._value: float | None = None

    def without(self) -> float:
        if self._value is None:
            self._value = float(self._without())
        return self._value


def held_out_loss(scene: Scene, paths: list[str], x: list[float], target: np.ndarray, pixels: np.ndarray | None,
                  folds: np.ndarray, *, environment: bool, clip: bool, norm: str, space: str, threads: int | None,
                  saturated: float | None = None) -> float:
    """The closed form's held-out loss of ``scene`` at the values ``x`` of ``paths``, with or without the
    environment column: over the ``folds`` (one per pixel of ``pixels``), the loss of each fold's pixels at the
    products (those minimising the fit's own loss, ``norm`` in ``space``: in linear L2 the least-squares
    products, whose refine by bisection would cost more than the fit's test) solved on the other folds."""
    if pixels is None:
        pixels = np.arange(scene.width * scene.height, dtype=np.uint32)
    spec = closed_form_spec(scene, paths, pixels, environment=environment, clip=clip, norm=norm, space=space,
                            saturated=saturated)
    v = _native.held_out(scene, target, np.asarray(x, dtype=np.float64),
                         np.ascontiguousarray(folds, dtype=np.uint8), spec, threads=threads,
                         refine=not (norm == "l2" and space == "linear"))
    return float(np.sum(v[:, 0]))


def held_out_evidence(without: float, with_term: float) -> dict[str, Any]:
    """The held-out record of a term that takes the held-out loss from ``without`` to ``with_term``: both
    losses, the relative gain, the folds and the block, and whether it passes (``gain`` >= HELD_OUT_GAIN)."""
    gain = (without - with_term) / without if without > 0 else 0.0
    return {"loss_without": without, "loss_with": with_term, "gain": gain, "passes": bool(gain >= HELD_OUT_GAIN),
            "folds": HELD_OUT_FOLDS, "block": HELD_OUT_BLOCK,
            "rule": f"the held-out loss must fall by at least {HELD_OUT_GAIN:.0%} too"}
