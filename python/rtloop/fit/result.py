"""What a fit returns: FitResult (the fitted scene and its report), StageResult per stage, and the
GenerationInfo a callback receives."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..scene import Scene

__all__ = ["FitResult", "GenerationInfo", "StageResult"]


@dataclass
class GenerationInfo:
    """What a fit's callback receives after every generation of every stage."""

    stage: str
    generation: int
    fitness: float
    objectives: list[float]
    #: Values of all of the scene's fit parameters (the stage's best individual, the rest held fixed), in
    #: the order of ``scene.param_names()``; in the refit with the terms a photo selected, the parameters a
    #: term frees (a lobe's specular and shininess) are not among them.
    params: np.ndarray
    evaluations: int


@dataclass
class StageResult:
    name: str
    paths: list[str]
    param_names: list[str]
    x: np.ndarray
    objectives: list[float]
    evaluations: int
    generations: int
    seconds: float
    loss: str
    pixels: int
    #: (generation, fitness, objectives, x) of the best individual of every generation (not in the repr).
    history: list[tuple[int, float, list[float], np.ndarray]] = field(default_factory=list, repr=False)
    #: For the projected loss: the closed-form products of the best individual, per object
    #: [P_r, P_g, P_b, Q] (Q = intensity x specular, 0 for a matte object), then [E_r, E_g, E_b]
    #: (exposure x environment x albedo) when the fit has the environment term.
    products: list[list[float]] | None = None
    #: For the projected loss: per object, its (unmasked) pixels that the fitted light reaches.
    lit_pixels: list[int] | None = None
    #: For the projected loss with interreflection: 1 / the light intensity the bounce was solved with.
    gauge: float | None = None
    #: The outline gate's evidence where it ran (``_native.OptimizeResult.outlines``): (loss with outlines at
    #: pixel centres, with them integrated, outline pixels, the largest share of an object's lit pixels on its
    #: outline, fired, loss after the polish with them, kept).
    outlines: tuple[float, float, int, float, bool, float | None, bool] | None = None


@dataclass
class FitResult:
    """The outcome of :func:`fit`, in the spirit of scipy's OptimizeResult."""

    scene: Scene
    #: The fitted values of all fit parameters by scalar name (e.g. ``light.position.x``).
    x: dict[str, float]
    stages: list[StageResult]
    evaluations: int
    seconds: float
    protocol: str
    seed: int
    #: Per object: light intensity x light colour x albedo, the combination the image determines.
    products: dict[str, list[float]]
    identifiability: dict[str, Any]
    settings: dict[str, Any]
    success: bool = True
    message: str = ""
    #: Per-parameter 1-sigma uncertainty (see rtloop.uncertainty), or None when not estimated.
    uncertainty: dict[str, Any] | None = None
    #: Doubts about the inputs or the result (each also issued as an RtloopWarning), in the order found.
    warnings: list[str] = field(default_factory=list)
    #: The image terms the fit used and why: ``{"terms": [...], "evidence": {term: {...}}}`` (see
    #: :mod:`rtloop.fit.selection`).
    model: dict[str, Any] = field(default_factory=dict)
    #: The residual against the photo's noise floor and a verdict (:mod:`rtloop.fit.goodness`).
    goodness: dict[str, Any] = field(default_factory=dict)
    #: With a reference of known reflectance (a grey card): the gauge it fixed, the absolute albedos and
    #: the light's intensity in W/sr (:mod:`rtloop.fit.reference`); None without one.
    reference: dict[str, Any] | None = None
    #: With ``framing="correct"`` where the photo was resampled into the scene's framing: the photo and the
    #: mask (bool (H, W)) that were fitted (:mod:`rtloop.fit.framing`); None otherwise.
    reframed: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    def __repr__(self) -> str:
        """A few lines' worth: the outcome, the budget and the fitted values (``report()`` has the rest)."""
        x = ", ".join(f"{k!r}: {v:.6g}" for k, v in self.x.items())
        more = f", warnings={len(self.warnings)}" if self.warnings else ""
        return (f"FitResult(success={self.success}, protocol={self.protocol!r}, seed={self.seed}, "
                f"fitness={self.fitness:.6g}, evaluations={self.evaluations}, seconds={self.seconds:.3g}, "
                f"stages={[s.name for s in self.stages]}, x={{{x}}}{more})")

    def generation_names(self) -> list[str]:
        """The names of a callback's ``GenerationInfo.params`` (and of best_per_generation.csv's columns):
        every fit parameter of the fitted ``scene`` but those the fit freed itself (the lobe of a sphere
        whose highlight the photo showed, ``model["specular_objects"]``), which its first stage did not
        have."""
        freed = {f"objects.{n}.{p}" for n in self.model.get("specular_objects", []) for p in ("specular", "shininess")}
        return [n for n in self.scene.param_names() if n not in freed]

    @property
    def fitness(self) -> float:
        return float(sum(self.stages[-1].objectives)) if self.stages else float("nan")

    def report(self) -> dict[str, Any]:
        """A JSON-able summary (the ``fit_report`` of result.json)."""
        return {
            "protocol": self.protocol,
            "seed": self.seed,
            "settings": self.settings,
            "evaluations": self.evaluations,
            "seconds": round(self.seconds, 4),
            "stages": [
                {
                    "name": s.name,
                    "parameters": s.param_names,
                    "loss": s.loss,
                    "pixels": s.pixels,
                    "fitness": float(sum(s.objectives)),
                    "objectives": [float(v) for v in s.objectives],
                    "evaluations": s.evaluations,
                    "generations": s.generations,
                    "seconds": round(s.seconds, 4),
                }
                for s in self.stages
            ],
            "fitted": self.x,
            "products": self.products,
            "identifiability": self.identifiability,
            "model": self.model,
            "goodness": self.goodness,
            "uncertainty": self.uncertainty,
            "message": self.message,
            "warnings": list(self.warnings),
            **({"reference": self.reference} if self.reference is not None else {}),
        }
