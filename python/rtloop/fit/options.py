"""``fit()``'s arguments checked once, in one place: :class:`FitOptions` for the one-light fit, or
:class:`LightsOptions` for several lights (:mod:`.lights`). The photo's own arguments (the image, its
mask and a grey card) are checked against the scene where it is observed (:mod:`.observation`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..errors import RtloopError
from ..scene import Scene
from .camera import Camera, check_camera
from .framing import check_framing
from .inputs import check_footprint, check_norm
from .lights import check_lights
from .protocol import LOSS_SPACES, PIXELS_PER_OBJECT, Budget, budget, check_arguments, whole
from .result import GenerationInfo
from .selection import check_environment, check_highlights, check_interreflection

__all__ = ["FitOptions", "LightsOptions", "check_options", "not_with_lights"]

#: The values ``uncertainty`` takes besides True and False.
UNCERTAINTY_MODES = ("default", "bootstrap", "off")

#: fit()'s arguments the lights fit has no use for: each must keep its default there (the lights fit takes
#: the objects as matte, under its own loss, with no camera terms), so that none is silently dropped.
NOT_WITH_LIGHTS = ("protocol", "f", "cr", "clip", "pixels_per_object", "optimizer", "polish", "norm", "space",
                   "environment", "interreflection", "highlights", "reference", "footprint", "vignetting", "tone",
                   "flat_field")

#: The arguments a fit with the framing corrected passes on to each of its fits (:func:`.framing.fit_reframed`).
REFRAMED = ("protocol", "seed", "population", "generations", "f", "cr", "threads", "clip", "pixels_per_object",
            "callback", "optimizer", "polish", "uncertainty", "norm", "space", "environment", "interreflection",
            "highlights", "footprint")


@dataclass(frozen=True)
class LightsOptions:
    """``fit()``'s arguments for several lights or a sphere light, checked: the others keep their defaults."""

    lights: int | str | None
    seed: int
    threads: int | None
    population: int | None
    generations: Any


@dataclass(frozen=True)
class FitOptions:
    """``fit()``'s arguments for one light, checked (their meaning: :func:`rtloop.fit`). ``norm``, ``space``
    and ``footprint`` are the modes given ("auto" or one), ``first_norm`` and ``first_space`` what the first
    fit takes; ``budget`` is the protocol's numbers with the caller's overrides, before the method is chosen
    for the scene (:func:`.protocol.choose_method`); ``camera`` the camera terms asked for."""

    protocol: str
    seed: int
    population: int | None
    generations: int | tuple[int, int] | None
    f: float | None
    cr: float | None
    threads: int | None
    clip: bool
    pixels_per_object: int
    callback: Callable[[GenerationInfo], Any] | None
    optimizer: str | None
    polish: int | None
    uncertainty: bool | str
    norm: str
    first_norm: str
    space: str
    first_space: str
    environment: str
    interreflection: str
    highlights: str
    footprint: str
    framing: str
    budget: Budget
    camera: Camera

    @property
    def with_sigma(self) -> bool:
        """Whether the result has the uncertainty's error bars."""
        return self.uncertainty not in (False, "off")

    def reframed(self, args: dict[str, Any]) -> dict[str, Any]:
        """The arguments (``args``: fit()'s as given) each fit of ``framing="correct"`` takes."""
        return {**{name: args[name] for name in REFRAMED}, "footprint": self.footprint}

    def budget_copy(self) -> Budget:
        """A copy of :attr:`budget` to choose the method in (:func:`.protocol.choose_method` sets it)."""
        return dataclasses.replace(self.budget)


def check_options(scene: Scene, args: dict[str, Any], defaults: dict[str, Any]) -> FitOptions | LightsOptions:
    """``fit()``'s arguments ``args`` (its locals, ``defaults`` its keyword defaults) checked against the
    loaded ``scene``, each refused in one line naming it; the photo's are checked where it is observed."""
    meshes = [o["name"] for o in scene.to_dict()["objects"] if o["shape"] == "mesh"]
    if meshes:
        raise RtloopError(f"fit: object {meshes[0]!r} is a mesh: meshes can be rendered and inserted, not fitted")
    lights, framing = check_lights(args["lights"]), check_framing(args["framing"])
    if lights not in (None, 1) or "lights" in scene.to_dict():
        if framing == "correct":
            raise RtloopError("framing: 'correct' fits a camera correction with one light, not with several")
        return _lights_options(scene, args, defaults, lights)
    footprint = check_footprint(args["footprint"])
    uncertainty = args["uncertainty"]
    if not (isinstance(uncertainty, bool) or isinstance(uncertainty, str) and uncertainty in UNCERTAINTY_MODES):
        raise RtloopError(f"uncertainty: must be True, False, 'default', 'bootstrap' or 'off' (got {uncertainty!r})")
    space = args["space"]
    if space not in ("auto", *LOSS_SPACES):
        raise RtloopError(f"space: unknown loss space {space!r} (known: auto, {', '.join(LOSS_SPACES)})")
    first_space = "linear" if space == "auto" else space
    norm, first_norm = check_norm(args["norm"])
    b = budget(args["protocol"], first_space, args["population"], args["generations"], args["f"], args["cr"])
    environment = check_environment(args["environment"])
    highlights = check_highlights(args["highlights"])
    interreflection = check_interreflection(args["interreflection"])
    check_arguments(scene, seed=args["seed"], threads=args["threads"], polish=args["polish"],
                    pixels_per_object=args["pixels_per_object"], population=b.population)
    camera = check_camera(scene, args["vignetting"], args["tone"], args["flat_field"])
    given = {name: args[name] for name in ("protocol", "seed", "population", "generations", "f", "cr", "threads",
                                           "clip", "pixels_per_object", "callback", "optimizer", "polish")}
    return FitOptions(**given, uncertainty=uncertainty, norm=norm, first_norm=first_norm, space=space,
                      first_space=first_space, environment=environment, interreflection=interreflection,
                      highlights=highlights, footprint=footprint, framing=framing, budget=b, camera=camera)


#: Values of NOT_WITH_LIGHTS that ask for what the lights fit does anyway: it fits no camera term and takes
#: the image as it is (linear).
AS_LIGHTS_DO = {"vignetting": ("off",), "tone": ("off", "linear")}


def not_with_lights(args: dict[str, Any], defaults: dict[str, Any]) -> str | None:
    """The first of NOT_WITH_LIGHTS that ``args`` (fit()'s) give other than its default and other than what
    the lights fit does anyway (AS_LIGHTS_DO), or None."""
    for name in NOT_WITH_LIGHTS:
        value, default = args[name], defaults[name]
        given = value is not None if default is None else not (type(value) is type(default) and value == default)
        if given and not (isinstance(value, str) and value in AS_LIGHTS_DO.get(name, ())):
            return name
    return None


def _lights_options(scene: Scene, args: dict[str, Any], defaults: dict[str, Any],
                    lights: int | str | None) -> LightsOptions:
    """The arguments of the lights fit checked: an argument it would ignore refused, in one line naming it
    (one given other than its default, and a bootstrap: its error bars are a jackknife's), then its own."""
    name = not_with_lights(args, defaults)
    if name is not None:
        raise RtloopError(f"{name}: not taken by the lights fit (several lights, or a scene with a 'lights' "
                          f"list: matte objects, its own loss, no camera terms); leave it at its default "
                          f"({defaults[name]!r})")
    if args["uncertainty"] == "bootstrap":
        raise RtloopError("uncertainty: 'bootstrap' is not taken by the lights fit (its error bars are a "
                          "delete-a-tile jackknife's)")
    population, generations = args["population"], args["generations"]
    if population is not None:
        whole("population", population, 4, 10_000)
    if generations is not None:
        whole("generations", generations, 1, 100_000)
    check_arguments(scene, seed=args["seed"], threads=args["threads"], polish=0, pixels_per_object=PIXELS_PER_OBJECT,
                    population=population or 40)
    return LightsOptions(lights, args["seed"], args["threads"], population, generations)
