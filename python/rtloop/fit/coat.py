"""The coated lobe against Blinn-Phong: where the photo shows a highlight, which of the two lobes explains
it (docs/methods.md, "Image terms").

A coated (plastic) ball is a Lambertian base under a clear coat with a rough GGX interface
(``material.coat``, ``rust/render/coat.rs``): its diffuse light passes the coat twice, dimmed by the coat's
Fresnel transmission at grazing angles, and its highlight is GGX's. Once the Blinn-Phong lobe has been
selected, the coat is tried at the same light: its loss at each of ROUGHNESS_TRIALS (the specular weight
and the colours solved in closed form, as the lobe's are), refined by a parabola in log roughness through
the best trial and its neighbours, and a second one about that vertex. Both models add k = 2 parameters per sphere (strength and shininess,
or strength and roughness), so the same evidence (:func:`.selection._verdict`) compares them: the coat is
used where it is selected and explains the photo better than Blinn-Phong. Its roughness then stays at the
value found while the refit searches the light (each roughness costs its coat's tables).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from ..scene import Scene, scene_to_dict
from .selection import _verdict, closed_form_loss, interreflection_given

__all__ = ["COAT_IOR", "COAT_SPECULAR_RANGE", "ROUGHNESS_TRIALS", "choose_lobe", "coat_evidence", "with_coat"]

#: GGX roughnesses tried at the found light: a factor 2 apart from a near-mirror coat to a matte one (the
#: parabola through the best and its neighbours in log roughness refines it).
ROUGHNESS_TRIALS = (0.03, 0.06, 0.12, 0.24, 0.48, 0.9)
#: The coat's relative index of refraction the fit assumes (polypropylene in air, Mitsuba's default).
COAT_IOR = 1.49
#: The coat's specular weight's bounds (a physical coat's is 1; the photo's exposure and the light's
#: intensity share a gauge with the albedos, so the fitted weight may exceed it).
COAT_SPECULAR_RANGE = (0.0, 4.0)
#: The second parabola's points: a factor this far either side of the first's vertex.
REFINE = 1.2
#: The roughness a refinement may reach: ROUGHNESS_TRIALS' ends.
_LOG_RANGE = (math.log(ROUGHNESS_TRIALS[0]), math.log(ROUGHNESS_TRIALS[-1]))


def with_coat(scene: Scene, names: list[str], roughness: float, *, free_roughness: bool = False) -> Scene:
    """``scene`` with the spheres ``names`` coated (``roughness``, COAT_IOR), their specular weight free in
    COAT_SPECULAR_RANGE (at 1) and, with ``free_roughness``, their roughness free in the trials' range."""
    d = scene_to_dict(scene)
    fit = dict(d.get("fit", {}))
    for o in d["objects"]:
        if o["name"] in names:
            o["material"] = {**o["material"], "specular": 1.0,
                             "coat": {"roughness": float(roughness), "ior": COAT_IOR}}
            fit[f"objects.{o['name']}.specular"] = {"min": COAT_SPECULAR_RANGE[0], "max": COAT_SPECULAR_RANGE[1]}
            fit.pop(f"objects.{o['name']}.shininess", None)
            if free_roughness:
                fit[f"objects.{o['name']}.roughness"] = {"min": ROUGHNESS_TRIALS[0], "max": ROUGHNESS_TRIALS[-1]}
    d["fit"] = fit
    return Scene(json.dumps(d, allow_nan=False))


def _vertex(r: list[float], y: list[float]) -> float | None:
    """The vertex of the parabola through (log r_i, y_i), within the points' span (None: not convex)."""
    u = [math.log(v) for v in r]
    den = (u[0] - u[1]) * (u[0] - u[2]) * (u[1] - u[2])
    a = (u[2] * (y[1] - y[0]) + u[1] * (y[0] - y[2]) + u[0] * (y[2] - y[1])) / den
    b = (u[2] ** 2 * (y[0] - y[1]) + u[1] ** 2 * (y[2] - y[0]) + u[0] ** 2 * (y[1] - y[2])) / den
    if not a > 0:
        return None
    v = min(max(-b / (2 * a), min(u)), max(u), _LOG_RANGE[1])
    return float(math.exp(max(v, _LOG_RANGE[0])))


def coat_evidence(scene: Scene, names: list[str], paths: list[str], x: list[float], target: np.ndarray,
                  pixels: np.ndarray | None, *, base: float, lobe: dict[str, Any], environment: bool, clip: bool,
                  norm: str, space: str, threads: int | None, active_pixels: int,
                  saturated: float | None = None) -> tuple[dict[str, Any], float] | None:
    """Whether a coat on the spheres ``names`` explains the photo better than the Blinn-Phong ``lobe``
    evidence (:func:`.selection.highlight_evidence`'s, at the same light ``x``): the closed-form loss at
    each of ROUGHNESS_TRIALS and at the vertices of two parabolas in log roughness (:func:`_vertex`), the
    verdict against ``base`` (k = 2 per sphere), and ``better_than_blinn_phong``. Returns (evidence, roughness), or None where the
    coat is not tried (the scene models a bounce, which the coat does not shape)."""
    if interreflection_given(scene):
        return None
    coated = with_coat(scene, names, ROUGHNESS_TRIALS[0], free_roughness=True)
    cpaths = paths + [f"objects.{n}.roughness" for n in names]
    kw = {"environment": environment, "clip": clip, "norm": norm, "space": space, "threads": threads,
          "saturated": saturated}

    def losses(roughnesses: list[float]) -> list[float]:
        rows = [list(x) + [r] * len(names) for r in roughnesses]
        return [float(v) for v in closed_form_loss(coated, cpaths, rows, target, pixels, **kw)]

    tried = list(ROUGHNESS_TRIALS)
    loss = losses(tried)
    k = int(np.argmin(loss))
    if 0 < k < len(tried) - 1:
        # the parabola's vertex through the best trial and its neighbours (in log roughness), then again
        # through that vertex and a factor REFINE either side of it
        r = _vertex([tried[i] for i in (k - 1, k, k + 1)], [loss[i] for i in (k - 1, k, k + 1)])
        if r is not None:
            near = [r / REFINE, r, r * REFINE]
            tried += near
            loss += losses(near)
            r2 = _vertex(near, loss[-3:])
            if r2 is not None:
                tried.append(r2)
                loss += losses([r2])
    best = int(np.argmin(loss))
    # not nested: a coat of weight 0 still dims the base by its Fresnel transmission
    ev = _verdict(base, loss[best], active_pixels, 2 * len(names), norm, nested=False)
    ev["roughness_tried"] = tried
    ev["loss_per_roughness"] = loss
    ev["roughness"] = tried[best]
    ev["ior"] = COAT_IOR
    ev["better_than_blinn_phong"] = bool(loss[best] < lobe["loss_with"])
    return ev, tried[best]


def choose_lobe(lobe: dict[str, Any], scene: Scene, names: list[str], paths: list[str], x: list[float],
                target: np.ndarray, pixels: np.ndarray | None, **kw: Any) -> None:
    """Add to the selected Blinn-Phong ``lobe`` evidence the coat's (:func:`coat_evidence`, ``kw`` its
    keywords) as ``lobe["coat"]``, and ``lobe["lobe"]``: "coat" where the coat is selected and explains the
    photo better, else "blinn-phong". With the coat, the term's loss, gain and BIC change are the coat's
    (Blinn-Phong's kept in ``lobe["blinn_phong"]``)."""
    coat = coat_evidence(scene, names, paths, x, target, pixels, lobe=lobe, **kw)
    if coat is None:
        return
    lobe["coat"] = coat[0]
    lobe["lobe"] = "coat" if coat[0]["selected"] and coat[0]["better_than_blinn_phong"] else "blinn-phong"
    if lobe["lobe"] == "coat":  # the term's loss is the coat's: later terms are tested on top of it
        keys = [k for k in ("loss_with", "gain", "delta_bic", "nested", "loss_with_nested", "raised") if k in coat[0]]
        lobe["blinn_phong"] = {k: lobe[k] for k in keys if k in lobe}
        lobe.update({k: coat[0][k] for k in keys})
        lobe.pop("why_raised", None)
