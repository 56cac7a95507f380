"""The protocols (named budgets and settings) and how a fit's budget follows from one: the method
(closed form or two stages), population, generations and polish, scaled to the searched dimensions."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _native
from ..errors import RtloopError
from ..scene import Scene

__all__ = ["LIMITS", "LOSS_SPACES", "PIXELS_PER_OBJECT", "PROTOCOLS", "Budget", "budget", "check_arguments",
           "searched_paths", "whole"]

#: Where a loss compares pixel values: ``linear`` radiance (default) or ``srgb`` code values.
LOSS_SPACES = ("linear", "srgb")

#: Named settings. ``paper``: the paper's numbers. ``rtloop``: the default (see docs/accuracy.md).
PROTOCOLS: dict[str, dict[str, Any]] = {
    "paper": {"population": 60, "generations": (200, 200), "f": 0.6, "cr": 0.8, "refine": False},
    # Default: the closed-form method searched by L-SHADE, 16 x 17 = 272 evaluations to find the basin, then
    # a Nelder-Mead polish of up to 200 evaluations that stops once its simplex spans less than 1e-6 of
    # every range (a short search hands the polish a wide simplex; 200 is where it stops improving). Chosen
    # on synthetic scenes (random lights and colours, clean, noisy and JPEG; not the reference scenes):
    # the smallest split with no wrong basin and every clean fit within 1 mm. Scenes it does not apply to
    # fall back to DE in two stages plus a refine pass, 30 x 100 per stage.
    # These are for a light position, 3 searched parameters ("per_dimensions"); D > 3 (a free shininess)
    # scales the population and generations by D / 3 and the polish by (D / 3)^2, as Nelder-Mead's cost
    # grows (a glossy ball: 21 x 22 + 356).
    "rtloop": {"population": 16, "generations": (16, 16), "f": 0.6, "cr": 0.8, "refine": True,
               "projected": True, "optimizer": "lshade", "polish": 200, "polish_tol": 1e-6, "per_dimensions": 3,
               "fallback_population": 30, "fallback_generations": (100, 100)},
}

#: Pixels sampled per object for stage 2.
PIXELS_PER_OBJECT = 64

#: The range of each whole-number argument of fit() (docs/scene-format.md: "Input limits"); threads also
#: <= 64 x cores.
LIMITS: dict[str, tuple[int, int]] = {
    "seed": (0, 2**64 - 1),
    "population": (4, 100_000),
    "generations": (0, 1_000_000),
    "polish": (0, 1_000_000),
    "threads": (1, 1024),
    "pixels_per_object": (1, 1_000_000),
}

#: Most pixel evaluations one generation may ask for (population x the scene's pixels): 4 x 10^9.
MAX_POPULATION_PIXELS = 4_000_000_000


def whole(name: str, value: Any, lo: int, hi: int) -> int:
    """``value`` as an int in [lo, hi], else an RtloopError naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise RtloopError(f"{name}: must be a whole number (got {value!r})")
    if not lo <= int(value) <= hi:
        raise RtloopError(f"{name}: must be between {lo} and {hi} (got {value})")
    return int(value)


def _real(name: str, value: Any, lo: float, hi: float, *, open_low: bool = False) -> float:
    """``value`` as a float in [lo, hi] (or (lo, hi]), else an RtloopError naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise RtloopError(f"{name}: must be a number (got {value!r})")
    v = float(value)
    if not (lo < v <= hi if open_low else lo <= v <= hi):
        raise RtloopError(f"{name}: must be in {'(' if open_low else '['}{lo}, {hi}] (got {value})")
    return v


def max_threads() -> int:
    """The most worker threads a fit may ask for: 1024, and at most 64 per core."""
    return min(LIMITS["threads"][1], 64 * (os.cpu_count() or 1))


def check_arguments(scene: Scene, *, seed: Any, threads: Any, polish: Any, pixels_per_object: Any,
                    population: int) -> None:
    """The whole-number arguments of fit() not checked by :func:`budget`, and the population's work."""
    whole("seed", seed, *LIMITS["seed"])
    if threads is not None:
        whole("threads", threads, 1, max_threads())
    if polish is not None:
        whole("polish", polish, *LIMITS["polish"])
    whole("pixels_per_object", pixels_per_object, *LIMITS["pixels_per_object"])
    pixels = scene.width * scene.height
    if population * pixels > MAX_POPULATION_PIXELS:
        raise RtloopError(f"population: {population} individuals x {pixels} pixels is more than "
                          f"{MAX_POPULATION_PIXELS:.0e} pixel evaluations a generation; use a smaller population "
                          "or scene")


@dataclass
class Budget:
    """A fit's search settings: the protocol's numbers, the caller's overrides, the method chosen."""

    protocol: dict[str, Any]
    population: int
    generations: tuple[int, int]
    f: float
    cr: float
    method: str = "two-stage"
    optimizer: str = "de"
    polish: int = 0
    #: Why the protocol's closed-form method does not apply (None when it does or is not asked for).
    projection_unavailable: str | None = None

    def settings(self) -> dict[str, Any]:
        """The budget's entries of FitResult.settings, in their order there."""
        return {"population": self.population, "generations": list(self.generations), "f": self.f,
                "cr": self.cr}


def budget(protocol: str, space: str, population: int | None, generations: int | tuple[int, int] | None,
           f: float | None, cr: float | None) -> Budget:
    """The protocol's numbers with the caller's overrides, checked (before the method is chosen)."""
    if protocol not in PROTOCOLS:
        raise RtloopError(f"protocol: unknown protocol {protocol!r} (known: {', '.join(PROTOCOLS)})")
    if space not in LOSS_SPACES:
        raise RtloopError(f"space: unknown loss space {space!r} (known: {', '.join(LOSS_SPACES)})")
    proto = PROTOCOLS[protocol]
    pop = whole("population", population if population is not None else proto["population"],
                *LIMITS["population"])
    gens = generations if generations is not None else proto["generations"]
    if isinstance(gens, (list, tuple)):
        if len(gens) != 2:
            raise RtloopError(f"generations: must be one number or a pair (stage 1, stage 2), got {gens!r}")
        gens = (whole("generations[0]", gens[0], *LIMITS["generations"]),
                whole("generations[1]", gens[1], *LIMITS["generations"]))
    else:
        g = whole("generations", gens, *LIMITS["generations"])
        gens = (g, g)
    f_ = _real("f", f if f is not None else proto["f"], 0.0, 2.0, open_low=True)
    cr_ = _real("cr", cr if cr is not None else proto["cr"], 0.0, 1.0)
    return Budget(proto, pop, gens, f_, cr_)


def searched_paths(paths: list[str]) -> list[str]:
    """What the closed-form method searches: the light's position or direction and any free shininess or
    coat roughness."""
    where = ["light.direction"] if "light.direction" in paths else ["light.position"]
    return where + [p for p in paths if p.endswith((".shininess", ".roughness"))]


def choose_method(b: Budget, scene: Scene, paths: list[str], *, population: int | None,
                  generations: int | tuple[int, int] | None, optimizer: str | None,
                  polish: int | None) -> Budget:
    """``b`` with its method chosen for ``scene`` and its numbers scaled to it (the caller's own kept)."""
    proto = b.protocol
    why_not = _native.projection_blocker(scene, paths)  # the core decides, as Fitness::new does
    b.method = "projected" if proto.get("projected") and why_not is None else "two-stage"
    if b.method == "two-stage":
        if proto.get("projected"):
            b.projection_unavailable = why_not
        if generations is None and "fallback_generations" in proto:
            b.generations = proto["fallback_generations"]
        if population is None and "fallback_population" in proto:
            b.population = int(proto["fallback_population"])
    b.optimizer = optimizer if optimizer is not None else proto.get("optimizer", "de")
    b.polish = int(polish if polish is not None else proto.get("polish", 0))
    if b.method == "projected" and proto.get("per_dimensions"):
        # The protocol's numbers are for its `per_dimensions` searched parameters (a light position); more
        # (a free shininess) get more of each (see PROTOCOLS), unless the caller set them.
        k = max(1.0, len(scene.param_names(searched_paths(paths))) / proto["per_dimensions"])
        if population is None:
            b.population = round(b.population * k)
        if generations is None:
            b.generations = (round(b.generations[0] * k), round(b.generations[1] * k))
        if polish is None:
            b.polish = round(b.polish * k * k)
    return b
