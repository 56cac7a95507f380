"""The protocols (named budgets and settings) and how a fit's budget follows from one: the method
(closed form or two stages), population, generations and polish, scaled to the searched dimensions."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _native
from ..errors import RtloopError
from ..scene import Scene

__all__ = ["LOSS_SPACES", "PIXELS_PER_OBJECT", "PROTOCOLS", "Budget", "budget", "searched_paths"]

#: Where a loss compares pixel values: ``linear`` radiance (default) or ``srgb`` code values.
LOSS_SPACES = ("linear", "srgb")

#: Named settings. ``paper``: the paper's numbers. ``rtloop``: the default (see README, speed against error).
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
    pop = int(population if population is not None else proto["population"])
    gens = generations if generations is not None else proto["generations"]
    gens = (int(gens), int(gens)) if isinstance(gens, (int, np.integer)) else (int(gens[0]), int(gens[1]))
    f_ = float(f if f is not None else proto["f"])
    cr_ = float(cr if cr is not None else proto["cr"])
    if pop < 4:
        raise RtloopError(f"population: must be at least 4 (got {pop})")
    if min(gens) < 0:
        raise RtloopError(f"generations: must be >= 0 (got {gens})")
    return Budget(proto, pop, gens, f_, cr_)


def searched_paths(paths: list[str]) -> list[str]:
    """What the closed-form method searches: the light's position or direction and any free shininess."""
    where = ["light.direction"] if "light.direction" in paths else ["light.position"]
    return where + [p for p in paths if p.endswith(".shininess")]


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
