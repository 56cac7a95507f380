"""The thorough error bars: a spatial block bootstrap of the closed-form fit.

The image is cut into the square blocks of the block sandwich (:func:`.sandwich.block_side`); each
replicate draws as many blocks as hold used pixels, with replacement, and refits the light (and any searched
shininess) with the products solved in closed form on the drawn pixels (a pixel of a block drawn twice counts
twice), in a box around the fitted light, with the terms the fit selected (environment, interreflection,
lobes). The spread of the refitted light and products over the replicates is the error bar: it holds when
residuals are correlated in space (a shadow edge, a highlight, a bounce the model misses) because whole blocks
move together, and it sees the fit's own nonlinearity, which the sandwich's linearisation does not.
Deterministic for a seed (the blocks drawn and every refit's search are seeded from it).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from ..errors import RtloopError
from ..fit.bounds import narrowed
from ..fit.gauge import hold_gauges
from ..fit.identifiability import identifiability
from ..fit.products import products_of
from ..fit.protocol import PROTOCOLS, budget, choose_method, searched_paths
from ..fit.result import GenerationInfo
from ..fit.stages import Stages
from ..scene import Scene, scene_to_dict
from .sandwich import block_side

__all__ = ["REPLICATES", "STAGE", "block_bootstrap", "replicate_of"]

#: Replicates of the block bootstrap (the sigma of a standard deviation from n draws is about 1 / sqrt(2 n):
#: 13 % at 30).
REPLICATES = 30
#: The callback's stage name for the refits: ``"bootstrap R/N"``.
STAGE = "bootstrap"
#: Each refit searches the light within +-this fraction of its bound range around the fitted light.
BOX_FRACTION = 0.05
#: The refit's search (population, generations, Nelder-Mead polish evaluations) for 3 searched parameters;
#: the polish ends at the protocol's tolerance.
REFIT_BUDGET = (8, 6, 200)


def block_bootstrap(result: Any, target: np.ndarray, use: np.ndarray | None, *, seed: int = 0,
                    replicates: int = REPLICATES, threads: int | None = None,
                    shift: dict[str, float | None] | None = None,
                    callback: Callable[[GenerationInfo], Any] | None = None) -> dict[str, Any]:
    """The block bootstrap's sigma of a closed-form fit ``result`` (a :class:`rtloop.FitResult` from
    :func:`rtloop.fit`) of ``target`` (linear float (H, W, 3)) on the pixels ``use`` (indices; None: all).

    Returns a JSON-able dict: ``method`` ("block-bootstrap"), ``replicates``, ``block_px``, ``blocks``,
    ``seed``, ``sigma`` ({``light.position.x`` ..., ``products.<object>.<r|g|b>``: the standard deviation
    over the replicates}), ``light_position_m`` (the replicates' position covariance's largest axis),
    ``values`` (the same names: per replicate), ``seconds`` and ``ms`` (its cost), ``warnings``.

    ``shift``: a systematic shift of the fit by name (the pixel footprint's, ``robust["footprint_shift"]`` of
    :func:`rtloop.uncertainty.estimate_uncertainty`), which every replicate shares and their spread cannot
    show: ``sigma`` and ``light_position_m`` then hold it as a mean squared error (the spread's variance plus
    the shift squared; the light's covariance plus its outer product), ``shift_included`` the names it
    entered.

    ``callback(GenerationInfo)`` runs after every generation of every refit (as a fit's: the GIL is taken
    only then), its ``stage`` ``"bootstrap R/N"`` (:func:`replicate_of` reads R and N back) and its ``params``
    the refit's values of the fit parameters of its scene (the fit's, the gauges held): the searched ones
    (the light, any shininess) of the generation's best, the others the fit's. An exception it
    raises ends the bootstrap within that generation's refit; returning False ends it after that
    generation, with no sigma and a warning that says so."""
    t0 = time.perf_counter()
    if not isinstance(replicates, int) or isinstance(replicates, bool) or replicates < 2:
        raise RtloopError(f"replicates: must be an integer >= 2 (got {replicates!r})")
    settings = result.settings
    if settings.get("method") != "projected":
        raise RtloopError("uncertainty: the bootstrap refits the closed-form method; this fit used "
                          f"{settings.get('method')!r} (protocol {result.protocol!r})")
    scene: Scene = result.scene
    d = scene_to_dict(scene)
    if d["light"].get("type", "point") != "point" or "light.position" not in scene.fit_paths:
        raise RtloopError("uncertainty: the bootstrap needs a point light whose position is fitted")
    side, members, nb = _blocks(scene.width, scene.height, use)
    env, box, b = _refit_setup(result, scene, d, target, use)
    ident = identifiability(box, box.fit_paths)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xB007]))
    names = [f"light.position.{c}" for c in "xyz"]
    names += [f"products.{o['name']}.{c}" for o in d["objects"] for c in "rgb"]
    rows = []
    stopped: list[int] = []
    for k in range(replicates):
        name = f"{STAGE} {k + 1}/{replicates}"
        watch = None
        if callback is not None:
            def watch(info: GenerationInfo, name: str = name, k: int = k) -> bool:
                if callback(replace(info, stage=name)) is False:
                    stopped.append(k)
                    return False
                return True
        drawn = rng.integers(0, nb, nb)
        pixels = np.sort(np.concatenate([members[i] for i in drawn])).astype(np.uint32)
        st = Stages(box, target, pixels, None, b, ident, clip=settings.get("clip", True),
                    norm=settings.get("norm", "l1"), space=settings.get("space", "linear"), threads=threads,
                    pixels_per_object=settings.get("pixels_per_object", 0), rng=np.random.default_rng(0),
                    callback=watch, footprint=_footprint_mode(settings.get("footprint", "off")))
        st.silhouettes = "on" if settings.get("silhouettes") else "off"  # the outlines as the fit took them
        st.products_per_generation = False  # the callback watches; a solve per generation would only slow it
        refit = scene_to_dict(st.projected(int(rng.integers(0, 2**63 - 1)), environment=env, name=name))
        if stopped:
            return {"method": "block-bootstrap", "replicates": k, "sigma": {}, "seed": int(seed),
                    "seconds": time.perf_counter() - t0, "ms": 1e3 * (time.perf_counter() - t0),
                    "warnings": [f"the callback stopped the bootstrap in refit {k + 1} of {replicates}: no sigma"]}
        prods = products_of(refit)
        rows.append([*refit["light"]["position"], *(v for o in d["objects"] for v in prods[o["name"]])])
    return _summary(np.array(rows, dtype=np.float64), names, shift, box, replicates, side, nb, seed, t0)


def replicate_of(stage: str) -> tuple[int, int] | None:
    """(R, N) of a bootstrap refit's stage name ``"bootstrap R/N"``; None for any other stage."""
    head, _, count = stage.partition(" ")
    done, _, total = count.partition("/")
    if head != STAGE or not (done.isdigit() and total.isdigit()):
        return None
    return int(done), int(total)


def _blocks(w: int, h: int, use: np.ndarray | None) -> tuple[int, list[np.ndarray], int]:
    """The side of the square blocks the pixels ``use`` (indices; None: all of the w x h image) are drawn
    in, each non-empty block's pixels (blocks in row order) and the number of blocks."""
    pix = np.arange(w * h, dtype=np.int64) if use is None else np.asarray(use, dtype=np.int64)
    side = block_side(w, h)
    y, x = np.divmod(pix, w)
    bid = (y // side) * (-(-w // side)) + x // side
    order = np.argsort(bid, kind="stable")
    blocks, starts = np.unique(bid[order], return_index=True)
    members = np.split(pix[order], starts[1:])
    return side, members, len(blocks)


def _refit_setup(result: Any, scene: Scene, d: dict[str, Any], target: np.ndarray,
                 use: np.ndarray | None) -> tuple[bool, Scene, Any]:
    """What every refit shares: whether it fits the environment (or ambient) term, its scene (the fit's
    with the gauges held and the light's bounds narrowed around the fit) and its budget (closed form)."""
    settings = result.settings
    env = "environment" in result.model.get("terms", []) or "ambient" in result.model.get("terms", [])
    work, _ = hold_gauges(scene, scene.fit_paths, target, None if use is None else np.asarray(use, np.uint32),
                          bounce=bool(d.get("interreflection")))
    where = searched_paths(work.fit_paths)
    box = narrowed(work, where, BOX_FRACTION)
    k = max(1.0, len(box.param_names(where)) / PROTOCOLS["rtloop"]["per_dimensions"])
    b = budget("rtloop", settings.get("space", "linear"), round(REFIT_BUDGET[0] * k), round(REFIT_BUDGET[1] * k),
               None, None)
    choose_method(b, box, box.fit_paths, population=b.population, generations=b.generations, optimizer=None,
                  polish=round(REFIT_BUDGET[2] * k * k))
    if b.method != "projected":
        raise RtloopError("uncertainty: the bootstrap refits the closed-form method, which this scene's fit "
                          "section does not allow")
    return env, box, b


def _summary(vals: np.ndarray, names: list[str], shift: dict[str, float | None] | None, box: Scene,
             replicates: int, side: int, nb: int, seed: int, t0: float) -> dict[str, Any]:
    """:func:`block_bootstrap`'s answer from the replicates' values ``vals`` (replicate x name), with the
    shared ``shift`` in sigma and the light's covariance, and a warning where replicates reach the edge of
    the light's search box."""
    sd = vals.std(axis=0, ddof=1)
    cov = np.cov(vals[:, :3], rowvar=False)
    delta = np.array([(shift or {}).get(n) if (shift or {}).get(n) is not None else np.nan for n in names])
    known = np.isfinite(delta)
    sd = np.where(known, np.sqrt(sd ** 2 + np.where(known, delta, 0.0) ** 2), sd)
    if known[:3].all():
        cov = cov + np.outer(delta[:3], delta[:3])
    warnings: list[str] = []
    lo, hi = np.array(box.bounds(["light.position"]), float).T
    at = (np.abs(vals[:, :3] - lo) < 1e-9 * (hi - lo)) | (np.abs(vals[:, :3] - hi) < 1e-9 * (hi - lo))
    if at.any():
        warnings.append(f"{int(at.any(axis=1).sum())} of {replicates} replicates put the light at the edge of "
                        f"their search box (+-{BOX_FRACTION:.0%} of the bounds around the fit): sigma is a lower "
                        "bound")
    seconds = time.perf_counter() - t0
    return {"method": "block-bootstrap", "replicates": int(replicates), "block_px": int(side), "blocks": int(nb),
            "seed": int(seed), "sigma": {n: float(s) for n, s in zip(names, sd)},
            "light_position_m": float(np.sqrt(max(np.linalg.eigvalsh(cov)[-1], 0.0))),
            "values": {n: vals[:, i].tolist() for i, n in enumerate(names)},
            "shift_included": [n for n, k in zip(names, known) if k],
            "seconds": seconds, "ms": 1e3 * seconds, "warnings": warnings}


def _footprint_mode(recorded: object) -> str:
    """The fit's footprint mode as its settings record it ("off", "polish", "on"; True/False from older fits)."""
    if recorded is True:
        return "on"
    if recorded in ("polish", "on"):
        return str(recorded)
    return "off"
