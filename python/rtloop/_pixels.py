"""Which pixels say what: the saturation threshold of an objective channel (``SATURATED`` in the Rust
core too) and the 4-neighbour edge test (silhouettes, shadow edges)."""

from __future__ import annotations

import numpy as np

__all__ = ["SATURATED", "edges"]

#: Objective channels at or above this are saturated: they say only "at least 1".
SATURATED = 0.999


def edges(labels: np.ndarray) -> np.ndarray:
    """Pixels with a 4-neighbour of a different label."""
    e = np.zeros(labels.shape, dtype=bool)
    diff_v = labels[1:, :] != labels[:-1, :]
    diff_h = labels[:, 1:] != labels[:, :-1]
    e[1:, :] |= diff_v
    e[:-1, :] |= diff_v
    e[:, 1:] |= diff_h
    e[:, :-1] |= diff_h
    return e
