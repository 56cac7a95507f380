"""Type stubs for rtloop's compiled core (rust/python/)."""

from collections.abc import Callable, Sequence
from os import PathLike
from typing import Any, Self

import numpy as np
import numpy.typing as npt

__version__: str

class RtloopError(Exception): ...
class SceneError(RtloopError): ...

class Scene:
    """A validated, immutable scene. Prefer ``rtloop.load_scene``."""

    def __new__(cls, json_text: str, base_dir: str | PathLike[str] | None = None) -> Self: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def object_names(self) -> list[str]: ...
    @property
    def fit_paths(self) -> list[str]: ...
    def param_names(self, paths: list[str] | None = None) -> list[str]: ...
    def bounds(self, paths: list[str] | None = None) -> list[tuple[float, float]]: ...
    def get_params(self, paths: list[str] | None = None) -> list[float]: ...
    def with_params(self, values: list[float], paths: list[str] | None = None) -> Scene: ...
    def with_bounds(
        self, changes: dict[str, tuple[float | list[float], float | list[float]]]
    ) -> Scene:
        """A copy with these fit bounds, path -> (min, max) (a path not in the fit section is added)."""
    def with_fit(self, other: Scene) -> Scene:
        """A copy with ``other``'s fit section, checked against this scene."""
    def without_fit(self) -> Scene: ...
    def to_json(self) -> str: ...
    def to_dict(self) -> dict[str, Any]: ...

def render(
    scene: Scene, width: int | None = None, height: int | None = None, spp: int = 1, footprint: bool = False,
    outlines: bool = False,
) -> npt.NDArray[np.float32]: ...
def object_ids(scene: Scene, width: int | None = None, height: int | None = None) -> npt.NDArray[np.int32]: ...
def render_many(scenes: list[Scene]) -> tuple[list[npt.NDArray[np.float32]], npt.NDArray[np.int32]]:
    """One-sample renders of scenes of one size in one pass, and the first scene's object index per pixel."""
def render_pixels(scene: Scene, idx: npt.NDArray[np.uint32], footprint: bool = False) -> npt.NDArray[np.float32]:
    """The pixels ``idx`` (flat, row-major) of ``render(scene, footprint=footprint)``, (len(idx), 3), bit for bit."""
def save_image(path: str | PathLike[str], image: npt.NDArray[np.float32]) -> None: ...
def render_layers(
    scenes: list[Scene], width: int, height: int, spp: int = 16, adaptive: bool = True, cover_from: int = 0,
    progress: Callable[[int, int], object] | None = None, refine: str = "steps",
) -> tuple[list[npt.NDArray[np.float32]], npt.NDArray[np.float32], int]:
    """The scenes rendered together, supersampled where any has an edge (and, ``refine``, where the
    colour steps between neighbours, "steps", or bends, "curvature"): (images, coverage of the last
    scene's objects from ``cover_from`` on, pixels supersampled)."""
def composite(
    photo: npt.NDArray[np.float32], with_objects: npt.NDArray[np.float32], without: npt.NDArray[np.float32],
    matte: npt.NDArray[np.float32],
) -> npt.NDArray[np.float32]:
    """matte * with + (1 - matte) * max(photo + (with - without), 0), blended only where matte > 0."""
def projection_blocker(scene: Scene, paths: list[str]) -> str | None: ...
def constant_term(scene: Scene) -> str:
    """"environment" or "ambient": the constant radiance the closed form's second column models."""
def fd_columns(
    ups: list[Scene | None],
    downs: list[Scene | None],
    denoms: list[float],
    rows: list[int],
    f0: npt.NDArray[np.float32],
    idx: npt.NDArray[np.uint32],
    clipped0: npt.NDArray[np.bool_],
    free: npt.NDArray[np.bool_],
    clip: bool,
    kink: npt.NDArray[np.bool_],
    jump: npt.NDArray[np.bool_],
    jt: npt.NDArray[np.float64],
) -> None:
    """Finite-difference Jacobian columns into the rows ``rows`` of ``jt``, their scenes rendered in one pass."""
def order_statistics(values: npt.NDArray[np.float64], ks: list[int]) -> list[float]:
    """The ``ks``-th smallest of ``values`` (0-based), as ``np.partition(values, ks)[ks]``."""
def render_centre_and_footprint(
    scene: Scene, outlines: bool = False
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """The pixel-centre render and the footprint render of ``scene`` (its own size) in one pass: ``render(scene)``
    and ``render(scene, footprint=True)`` bit for bit."""
def footprint_delta(
    centre: npt.NDArray[np.float32], idx: npt.NDArray[np.uint32], f0: npt.NDArray[np.float32]
) -> npt.NDArray[np.float64]:
    """The pixel footprint's area average less the centre value, (f_xx + f_yy) / 24 from the 4-neighbour
    Laplacian of the (H, W, 3) pixel-centre render, per used residual (0 at the border, at clipped values and
    where ``f0`` is not the centre's)."""
def block_scores(
    jt: npt.NDArray[np.float64], rows: list[int], r: npt.NDArray[np.float64], block_of: npt.NDArray[np.int64],
    blocks: int,
) -> npt.NDArray[np.float64]: ...
def noise_medians(image: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """Per channel, the median absolute response of Immerkaer's kernel over the interior of the C-contiguous
    (H, W, 3) image (H, W >= 3), as numpy computes it: (3,)."""
def jpeg_phases(codes: npt.NDArray[np.float32], block: int, edge_sq: float) -> npt.NDArray[np.float64]:
    """The JPEG blocking's mean clipped squared jump per phase of the grid, along the rows then the columns,
    each halved (goodness.jpeg_blocking's), of the C-contiguous (H, W, 3) sRGB codes (H, W >= 4): (block, 3)."""
def codes8(values: npt.NDArray[np.float32], table: npt.NDArray[np.float32], buckets: npt.NDArray[np.int16],
           shift: int) -> npt.NDArray[np.uint8] | None:
    """The 8-bit codes of the 1-D ``values`` if each is bit for bit a code's value in ``table``, else None
    (``buckets`` and ``shift`` as ``rtloop._srgb`` builds them)."""
class FitnessSpec:
    """What ``evaluate``, ``optimize`` and ``held_out`` compare and how, checked once (each bad value a
    one-line RtloopError naming its field). paths: the searched parameters (in the scene's fit section).
    pixels: the pixel indices the loss counts (uint32; None: all). loss: "l1", "l1_rgb" or "l1_projected"
    (the closed form). product_bounds: the closed form's bounds, (objects, 3, 2), or (objects, 4, 2) whose
    row 4 bounds Q = intensity x specular, or (objects, 7, 2) whose rows 5-7 bound exposure x environment
    x albedo. norm: "l1", "l2", "huber" or "huber:H"; space: "linear" or "srgb" (the loss compares the
    sRGB encodings of the clipped render and of target; the least-squares products stay linear).
    footprint: pixels integrated over their area. saturated: objective values at or above it (capped at
    0.999) may be clipped: the least-squares solve leaves them out and the refine counts them one-sidedly
    (default 0.999; rtloop.fit passes goodness.clip_level). solve_margin: only pixels whose neighbours
    within this Chebyshev distance all show their object inform the closed-form products (0, the default:
    the 4-neighbours; rtloop.fit passes 2 for a JPEG); the loss counts every pixel. frozen_bounce: with
    interreflection, 0 the full bounce; N >= 1 holds it at the scene's light (``evaluate``, ``held_out``)
    or, for ``optimize``, ranks lights with the bounce held at the scene's light, then up to N - 1 times at
    the light found so far, each later pass a Nelder-Mead polish from it (half the polish budget) in a
    tenth of the box; the first pass's own polish takes half the budget too where N > 1."""

    def __init__(
        self,
        paths: list[str],
        *,
        pixels: npt.NDArray[np.uint32] | None = None,
        loss: str = "l1",
        clip: bool = True,
        product_bounds: npt.NDArray[np.float64] | None = None,
        norm: str = "l1",
        space: str = "linear",
        footprint: bool = False,
        frozen_bounce: int = 0,
        saturated: float | None = None,
        solve_margin: int = 0,
    ) -> None: ...

def evaluate(
    scene: Scene,
    target: npt.NDArray[np.float32],
    population: npt.NDArray[np.float64],
    spec: FitnessSpec,
    threads: int | None = None,
) -> npt.NDArray[np.float64]: ...
def held_out(
    scene: Scene,
    target: npt.NDArray[np.float32],
    x: npt.NDArray[np.float64],
    folds: npt.NDArray[np.uint8],
    spec: FitnessSpec,
    threads: int | None = None,
    refine: bool = True,
) -> npt.NDArray[np.float64]:
    """spec's loss must be "l1_projected"."""
def optimize(
    scene: Scene,
    target: npt.NDArray[np.float32],
    spec: FitnessSpec,
    *,
    population: int = 60,
    generations: int = 200,
    f: float = 0.6,
    cr: float = 0.8,
    seed: int = 0,
    method: str = "de",
    max_evaluations: int | None = None,
    polish: int = 0,
    polish_tol: float | None = None,
    polish_footprint: bool = False,
    with_products: bool = True,
    x0: Sequence[float] | None = None,
    callback: Callable[[int, npt.NDArray[np.float64], list[float], int, list[list[float]] | None], Any]
    | None = None,
    threads: int | None = None,
    silhouettes: str = "off",
) -> OptimizeResult:
    """polish_tol: the polish stops once every simplex vertex is within this fraction of each range of
    the best (default 1e-13). polish_footprint: the pixel footprint in the polish (and the products and
    loss reported) only. x0: one value per searched parameter (clamped to its bounds), the first member
    of L-SHADE's initial population, so that a search refining a point never ends worse than it (method
    "lshade" only). silhouettes (with the footprint): "on"
    integrates the outline pixels in every footprint evaluation, "auto" (with polish_footprint) only where
    the outline gate finds the photo needs them (OptimizeResult.outlines), "off" at pixel centres."""

class OptimizeResult:
    """What ``optimize`` found (immutable). For the projected loss ``products`` (per object
    [P_r, P_g, P_b, Q]: the products minimising the loss at x), ``lit_pixels`` (per object) and
    ``search_objectives`` (the loss at the least-squares products the search ranked candidates by) are
    set, else None."""

    @property
    def x(self) -> npt.NDArray[np.float64]: ...
    @property
    def objectives(self) -> list[float]: ...
    @property
    def search_objectives(self) -> list[float] | None: ...
    @property
    def evaluations(self) -> int: ...
    @property
    def generations(self) -> int: ...
    @property
    def stopped(self) -> bool: ...
    @property
    def stop_reason(self) -> str: ...
    @property
    def polish(self) -> tuple[int, float, float] | None:
        """(evaluations, value before, value after) of the Nelder-Mead polish; None when none ran."""
    @property
    def active_pixels(self) -> int: ...
    @property
    def products(self) -> list[list[float]] | None: ...
    @property
    def lit_pixels(self) -> list[int] | None: ...
    @property
    def outlines(self) -> tuple[float, float, int, float, bool, float | None, bool] | None:
        """The outline gate's (loss at centres, loss with the outlines averaged, outline pixels, the largest
        share of an object's lit pixels on its outline, fired, loss polished, kept)."""
    @property
    def history(self) -> list[tuple[int, npt.NDArray[np.float64], list[float], int]]:
        """(generation, best, best's objectives, evaluations) after the initial population and every
        generation: recorded in the core, so no callback (and no GIL) is needed for it."""

# The optimisers' test hooks (minimize_test_function, test_function_value) are not in this module: they
# live in the test-only extension _rtloop_test_hooks (cargo feature test-hooks, rust/python/test_hooks.rs).
