"""What a one-light fit searches and how (:class:`Plan`): the gauges held, the method and budget chosen for
the scene, the footprint, the scene as fitted and the settings recorded; and the stages of a fit of the
observed photo (:func:`new_stages`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import RtloopError
from ..scene import Scene
from .gauge import hold_gauges
from .identifiability import identifiability
from .observation import Observation
from .options import FitOptions
from .protocol import Budget, check_arguments, choose_method
from .selection import with_interreflection
from .stages import Stages

__all__ = ["Plan", "new_stages", "plan_fit"]


@dataclass(frozen=True)
class Plan:
    """A fit's plan. ``given``: the scene as given; ``scene``: with the light's colour and the exposure held
    where they only rescale the albedos (``held``: :func:`.gauge.hold_gauges`); ``work``: the scene as
    fitted (with the interreflection term where asked for, "on"); ``ident``: what the photo determines
    (:func:`.identifiability.identifiability`); ``budget``: the method and its numbers; ``footprint``: where
    the fit takes the pixel footprint ("off", "polish": the closed-form polish, "on": everywhere);
    ``seeds``: the stages' seeds; ``settings``: the result's record of them."""

    given: Scene
    scene: Scene
    work: Scene
    held: dict[str, str]
    ident: dict[str, Any]
    budget: Budget
    footprint: str
    seeds: np.ndarray
    settings: dict[str, Any]
    #: The outline pixels with the footprint ("auto": where the outline gate finds the photo needs them,
    #: "on": always, "off": at pixel centres; :attr:`.stages.Stages.silhouettes`).
    silhouettes: str = "off"

    def new_model(self) -> dict[str, Any]:
        """The record of the image terms before any is selected (``result.model``)."""
        return {"terms": ["direct"], "evidence": {}, **({"held": self.held} if self.held else {})}


def plan_fit(scene: Scene, options: FitOptions, photo: Observation) -> Plan:
    """The plan of fitting ``scene``'s free parameters to ``photo``, its scaled budget checked."""
    all_paths = scene.fit_paths
    if not all_paths:
        raise RtloopError("fit: the scene's fit section names no free parameters")
    ident = identifiability(scene, all_paths)
    given = scene
    if options.protocol != "paper":
        scene, held = hold_gauges(scene, all_paths, photo.target, photo.use, bounce=options.interreflection == "on")
    else:
        held = {}
    b = choose_method(options.budget_copy(), scene, scene.fit_paths, population=options.population,
                      generations=options.generations, optimizer=options.optimizer, polish=options.polish)
    check_arguments(scene, seed=options.seed, threads=options.threads, polish=b.polish,
                    pixels_per_object=options.pixels_per_object, population=b.population)  # the scaled budget too
    footprint = ("polish" if b.method == "projected" else "off") if options.footprint in ("auto", "silhouette") \
        else options.footprint
    # the outline pixels integrated where the photo shows it needs them (the gate after the closed-form
    # search), or always ("silhouette")
    silhouettes = {"auto": "auto" if footprint == "polish" else "off", "silhouette": "on"}.get(options.footprint, "off")
    settings = {**b.settings(), "clip": options.clip,
                "masked_pixels": None if photo.use is None else int(scene.width * scene.height - photo.use.size),
                "norm": options.first_norm, "space": options.first_space,
                "pixels_per_object": options.pixels_per_object, "threads": options.threads, "method": b.method,
                "optimizer": b.optimizer, "polish": b.polish, "environment": options.environment,
                "interreflection": options.interreflection, "highlights": options.highlights}
    if b.projection_unavailable is not None:
        settings["projection_unavailable"] = b.projection_unavailable
    settings["footprint"] = footprint
    settings["saturated"] = photo.saturated
    if photo.jpeg:
        settings["solve_margin"] = photo.solve_margin
    work = with_interreflection(scene) if options.interreflection == "on" else scene
    seeds = np.random.SeedSequence(options.seed).generate_state(4, dtype=np.uint64)
    return Plan(given, scene, work, held, ident, b, footprint, seeds, settings, silhouettes)


def new_stages(options: FitOptions, photo: Observation, scene: Scene, budget: Budget, ident: dict[str, Any], *,
               norm: str, space: str, footprint: str, report_names: list[str] | None = None,
               silhouettes: str = "off") -> Stages:
    """The stages of a fit of ``scene`` to ``photo`` (its used pixels, clip level and solve margin) with
    ``budget``, in ``norm`` and ``space``."""
    stages = Stages(scene, photo.target, photo.use, photo.mask, budget, ident, clip=options.clip, norm=norm,
                    space=space, threads=options.threads, pixels_per_object=options.pixels_per_object,
                    rng=np.random.default_rng(options.seed), callback=options.callback, footprint=footprint,
                    report_names=report_names)
    stages.saturated, stages.solve_margin = photo.saturated, photo.solve_margin
    stages.silhouettes = silhouettes
    return stages
