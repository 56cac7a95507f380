"""The decomposition behind the covariance: singular values and vectors of the column-scaled Jacobian,
from its Gram matrix while that is accurate, else by a tall-skinny QR and an SVD."""

from __future__ import annotations

import numpy as np

#: The decomposition comes from the Gram matrix while every singular value is above this fraction of the
#: largest (its error is then below 1e-9 relative), else from QR and SVD of the Jacobian itself.
GRAM_RCOND = 1e-3
#: Rows per block of the tall-skinny QR (see _svd_scaled).
_QR_BLOCK = 512


def _svd_scaled(
    jt: np.ndarray, idx: np.ndarray, gram: np.ndarray, col: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Singular values (descending) and right singular vectors (rows) of Js = J / col, J = ``jt[idx]``ᵀ
    (``gram`` = JᵀJ, ``col`` its columns' norms).

    From the eigen-decomposition of JsᵀJs (``gram`` scaled) when every singular value is above GRAM_RCOND
    of the largest: its eigenvalues are then accurate to about 1e-16 / GRAM_RCOND² relative, at P x P
    cost. Otherwise, where squaring would lose the small singular values to rounding, from the SVD of R in
    Js = QR (the same singular values and vectors as Js's), R by a tall-skinny QR: the QR of each block
    of rows, then of their stacked R factors (cache-sized LAPACK calls; one QR of all of Js is several
    times slower, and much slower still when a threaded BLAS competes with the renderer's threads).
    """
    w, vec = np.linalg.eigh(gram / np.outer(col, col))
    if w[-1] > 0 and w[0] > GRAM_RCOND**2 * w[-1]:
        return np.sqrt(w[::-1]), vec[:, ::-1].T
    js = jt[idx].T / col
    m, p = js.shape
    blocks = -(-m // _QR_BLOCK)
    padded = np.zeros((blocks * _QR_BLOCK, p))  # zero rows leave R unchanged
    padded[:m] = js
    r = np.linalg.qr(padded.reshape(blocks, _QR_BLOCK, p), mode="r").reshape(-1, p)
    _, s, vt = np.linalg.svd(np.linalg.qr(r, mode="r"))
    return s, vt
