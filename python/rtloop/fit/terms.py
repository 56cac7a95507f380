"""The image terms a photo selects for the closed-form fit (:func:`select_terms`): the terms given or forced
on fitted first; then each auto term (environment, interreflection, a sphere's lobe) tested at the light
found (:mod:`.selection`'s evidence), forward, and one refit near that light with every term selected
(:mod:`.refit`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .._srgb import decode
from ..scene import Scene
from .bounds import narrowed, restore_bounds
from .coat import choose_lobe, with_coat
from .constant import as_environment, compare_constant, declares_ambient
from .heldout import HeldOut, block_folds, held_out_loss
from .jpeg import jpeg_codes
from .observation import Observation
from .options import FitOptions
from .plan import Plan
from .products import constant_term
from .refit import REFIT_FRACTION, jpeg_refit, refit_stages, stays_linear
from .selection import (
    BOUNCE_PASSES,
    EXPLAINED,
    closed_form_loss,
    environment_evidence,
    environment_given,
    explained_ratio,
    highlight_candidates,
    highlight_evidence,
    interreflection_evidence,
    interreflection_given,
    with_highlights,
    with_interreflection,
)
from .stages import Stages

__all__ = ["ENCODED_GAIN", "select_terms"]

#: The auto terms in the order they are tested and named.
TERM_ORDER = ("environment", "interreflection", "specular")

#: An image whose sRGB decoding the base model explains at least this many times better (each loss against
#: its own quantisation floor) is doubted as sRGB-encoded. On the Mitsuba test photos the decoded encodings
#: fit 1.8-15x better, and decoding a linear photo makes the fit 1.1-5.8x worse, never better.
ENCODED_GAIN = 1.5


def select_terms(options: FitOptions, photo: Observation, plan: Plan, stages: Stages, model: dict[str, Any],
                 encoding: dict[str, Any] | None = None) -> Scene:
    """The closed-form fit of ``photo`` (``stages``: its stages, on the photo's used pixels) with the image
    terms the photo needs (:mod:`.selection`): fitted with the terms given or forced on; then, unless that
    fit explains the photo to its quantisation floor, each auto term in turn (environment, interreflection,
    a sphere's lobe) is tested at the light found, on top of those already selected (a term not selected is
    tested again after another is: forward selection), and one refit near that light has every selected
    term; it replaces the first fit only when its loss is lower. ``model`` receives the terms and the
    evidence (each term's last test: ``tested_with`` the terms it was tested on top of, ``earlier_gain`` its
    first test's gain where it was tested again). ``encoding``: the encoding check of an earlier fit of the
    same photo (``{}``: it had none), taken instead of checking again."""
    s = _Selection(options, photo, plan, stages, model)
    if s.explained():
        return s.current
    s.check_encoding(encoding)
    if s.ambient and declares_ambient(s.work):  # the declared ambient, or the same light occluded (.constant)
        s.constant()
    added = s.forward()
    if not added:
        return jpeg_refit(s.current, s.work, stages, s.first, model, int(plan.seeds[1]),
                          codes=jpeg_codes(photo.blocking, options.space), env=s.env, refit=s.refit,
                          photo=photo)
    return s.refit_with(added)


class _Selection:
    """One selection's state: the scene as fitted (``work``, with the environment where ambient light gave
    way to it), its first fit (``first``, ``current``) and what the forward selection has added."""

    def __init__(self, options: FitOptions, photo: Observation, plan: Plan, stages: Stages, model: dict[str, Any]):
        self.options, self.photo, self.plan, self.stages, self.model = options, photo, plan, stages, model
        # Ambient light (given or free, no environment) takes the closed form's constant column instead.
        self.ambient = constant_term(plan.scene) == "ambient"
        self.env = environment_given(plan.scene) or options.environment == "on" or self.ambient
        self.work = plan.work
        self.current = stages.projected(int(plan.seeds[0]), environment=self.env)
        self.first = stages.stages[-1]
        if self.env:
            model["terms"].append("ambient" if self.ambient else "environment")
        if interreflection_given(self.work):
            model["terms"].append("interreflection")
        self.kw = {"clip": options.clip, "norm": stages.norm, "space": options.first_space,
                   "threads": options.threads, "saturated": stages.saturated}

    def refit(self, box: Scene, space: str) -> Stages | None:
        """The stages of one refit of ``box`` in ``space`` (:func:`.refit.refit_stages`)."""
        return refit_stages(self.options, self.photo, self.stages, box, space)

    def explained(self) -> bool:
        """Whether the first fit is at the photo's noise level: it needs no more terms, and the tests are
        skipped (one sum, no evaluation). Records the residual against the floor in the fit's own norm and
        space (alike in every norm), and the pixels the tests take (``sub``)."""
        photo, model, first = self.photo, self.model, self.first
        floor, self.ratio = explained_ratio(sum(first.objectives), photo.target, photo.use, photo.codes,
                                            norm=self.stages.norm, space=self.options.first_space)
        model["residual"] = {"loss": float(sum(first.objectives)), "quantisation_floor": floor, "ratio": self.ratio,
                             "explained_below": EXPLAINED}
        if self.ratio < EXPLAINED:
            model["skipped"] = (f"the fit's residual is {self.ratio:.2g}x the size of the photo's 8-bit rounding "
                                f"error (below {EXPLAINED:g}x): the photo needs no more terms")
            return True
        # The tests compare models on every other pixel in each direction: a term that explains 5 % of the
        # loss shows there as well, and the bounce's gathers cost a quarter.
        w, h = self.plan.scene.width, self.plan.scene.height
        grid = np.arange(w * h, dtype=np.uint32).reshape(h, w)[::2, ::2]
        self.sub = grid.ravel() if photo.use is None else np.intersect1d(grid.ravel(), photo.use).astype(np.uint32)
        return False

    def check_encoding(self, encoding: dict[str, Any] | None) -> None:
        """``model["encoding"]``: whether the image looks sRGB-encoded rather than linear. An encoding is
        within [0, 1]: an image beyond it is radiance, not sRGB codes. An image whose every value is an 8-bit
        code's linear value (a PNG or JPEG as load_image decodes it) was decoded: linear; an image declared
        linear (``tone="linear"``) is not checked. ``encoding``: the
        first fit's check (the L1 one the check's gain was measured with), where this is a refit."""
        target = self.photo.target
        if encoding is not None:
            if encoding:
                self.model["encoding"] = encoding
        elif self.options.camera.tone == "linear":
            self.model["encoding"] = {"suspect": False, "why": "declared linear (tone='linear', as a file read "
                                                               "with response='linear'): not checked"}
        elif self.photo.codes is not None:
            self.model["encoding"] = {"suspect": False, "why": "its values are 8-bit sRGB codes decoded to linear "
                                                               "(as rtloop.load_image reads a PNG or JPEG): not checked"}
        elif self.options.first_space == "linear" and float(target.min()) >= 0.0 and float(target.max()) <= 1.0:
            self.model["encoding"] = _encoding_check(self.work, self.stages, int(self.plan.seeds[0]), target,
                                                     self.sub, self.ratio, environment=self.env)

    def constant(self) -> None:
        """Ambient light declared (or free): compared with the same light occluded, the environment
        (:func:`.constant.compare_constant`), which replaces it where its refit's loss is lower."""
        where, x, first = self.first.paths, list(self.first.x), self.first
        self.model["constant"] = ev = compare_constant(self.work, where, x, self.photo.target, self.sub, **self.kw)
        more = self.refit(narrowed(as_environment(self.work).with_params(x, where), where, REFIT_FRACTION),
                          self.options.first_space) if ev["use_environment"] and "refit_blocked" not in ev else None
        if more is not None:
            candidate = more.projected(int(self.plan.seeds[2]), environment=True, name="light+colour+environment",
                                       from_scene=True)
            self.stages.add(more)
            ev["loss_refit"] = float(sum(more.stages[-1].objectives))
            if ev["loss_refit"] < sum(first.objectives):
                self.work, self.first, self.ambient = as_environment(self.work), more.stages[-1], False
                self.current = restore_bounds(candidate, self.work)
                terms = self.model["terms"]
                terms[terms.index("ambient")] = "environment"
        ev["used"] = "ambient" if self.ambient else "environment"

    def forward(self) -> list[str]:
        """Forward selection: each auto term is tested on top of those selected so far, and a term not
        selected is tested again once another has been added (a missing term's share of the residual shows
        only when the others' is explained: judged by its share of the whole loss, lamp-front's dim room
        light takes 3.5 % beside the unexplained bounce and lobe, 5.1 % on top of them), until a round adds
        nothing (a term is tested at most once per term selected, and once more only if another was selected
        after it). Returns the terms selected, in TERM_ORDER."""
        options, model, work = self.options, self.model, self.work
        where, x = self.first.paths, list(self.first.x)
        self.model_work, self.model_env, added = work, self.env, []
        self.base = float(closed_form_loss(work.with_params(x, where), where, [x], self.photo.target, self.sub,
                                           environment=self.env, **self.kw)[0])
        self.held = self.held_out(work, where, x, self.env)
        held_colour = "light.color" in model.get("held", {})
        self.names = highlight_candidates(work) if options.highlights == "auto" and not held_colour else []
        candidates = [t for t, wanted in (
            ("environment", options.environment == "auto" and not self.env),
            ("interreflection", options.interreflection == "auto" and not interreflection_given(work)
             and len(self.plan.scene.object_names) > 1 and not self.ambient and not held_colour),
            # (a lobe's highlight has the light's own colour, which a held colour would get wrong)
            ("specular", bool(self.names)),
        ) if wanted]
        tested_with: dict[str, int] = {}  # a term: how many terms were selected when it was last tested
        while todo := [t for t in candidates if t not in added and tested_with.get(t, -1) < len(added)]:
            for term in todo:
                tested_with[term] = len(added)
                ev, shininess = self.evidence(term, self.model_work.with_params(x, where), where, x)
                earlier = model["evidence"].get(term)
                ev["tested_with"] = [t for t in TERM_ORDER if t in added]
                if earlier is not None:
                    ev["earlier_gain"] = earlier.get("earlier_gain", earlier["gain"])
                model["evidence"][term] = ev
                if ev["selected"]:
                    self.base = ev["loss_with"]
                    added.append(term)
                    self.add_term(term, ev, shininess)
                    known = ev["held_out"].get("loss_with")
                    self.held = (self.held_out(self.model_work, where, x, self.model_env) if known is None
                                 else HeldOut(self.held.folds, lambda known=known: known))
        added.sort(key=TERM_ORDER.index)
        return added

    def held_out(self, work: Scene, where: list[str], x: list[float], env: bool) -> HeldOut:
        """The held-out comparison's folds of the test's pixels and, when first asked, the held-out loss of
        the model ``work`` (``env``: with the environment's column) at the light ``x`` (of ``where``)."""
        folds = block_folds(self.sub, self.plan.scene.width)
        return HeldOut(folds, lambda: held_out_loss(work.with_params(x, where), where, x, self.photo.target,
                                                    self.sub, folds, environment=env, **self.kw))

    def evidence(self, term: str, at: Scene, where: list[str], x: list[float]) -> tuple[dict[str, Any], float | None]:
        """``term``'s test at ``at`` (the model so far at the light found), and a lobe's best trial shininess."""
        target, sub, base, kw = self.photo.target, self.sub, self.base, self.kw
        n_sub, env, names = self.first.pixels // 4, self.model_env, self.names
        if term == "environment":
            return environment_evidence(at, where, x, target, sub, base=base, active_pixels=n_sub, held=self.held,
                                        **kw), None
        if term == "interreflection":
            return interreflection_evidence(at, where, x, target, sub, base=base, environment=env,
                                            active_pixels=n_sub, held=self.held, **kw), None
        ev, shininess = highlight_evidence(at, names, where, x, target, sub, base=base, environment=env,
                                           active_pixels=n_sub, **kw)
        if ev["selected"]:  # the coat against Blinn-Phong, by the same evidence (fit/coat.py)
            choose_lobe(ev, at, names, where, x, target, sub, base=base, environment=env, active_pixels=n_sub, **kw)
        return ev, shininess

    def add_term(self, term: str, ev: dict[str, Any], shininess: float | None) -> None:
        """The model with ``term`` (selected by its evidence ``ev``) added."""
        if term == "environment":
            self.model_env = True
        elif term == "interreflection":
            self.model_work = with_interreflection(self.model_work)
        elif ev.get("lobe") == "coat":
            self.model_work = with_coat(self.model_work, self.names, ev["coat"]["roughness"])
        else:
            self.model_work = with_highlights(self.model_work, self.names, shininess)

    def lobe_off_its_top(self, candidate: Scene, more: Stages, where: list[str], seed: int,
                         lobe: dict[str, Any]) -> tuple[Scene, Stages]:
        """The Blinn-Phong refit ``candidate`` (its stages ``more``) refitted while a sphere's shininess ends
        at the top of its box. The box is set about the best trial shininess at the light found without a
        lobe, which the highlight pulls towards itself, where a broader lobe fits; at the refit's light the
        photo's highlight may want a tighter one, and a lobe held too broad is narrowed by a nearer light
        (which tilts the diffuse shading's direction). So the box is moved up (SHININESS_SPAN either side of
        the value reached) and the fit made again from there, kept where its loss is lower, at most
        LOBE_RAISES times; ``lobe["raised_shininess"]`` records each."""
        raises: list[dict[str, Any]] = []
        for _ in range(LOBE_RAISES):
            top = _at_top(candidate, self.model_work, self.names)
            if not top:
                break
            shin = [f"objects.{n}.shininess" for n in self.names]
            work = self.model_work.with_params(candidate.get_params(shin), shin)
            for n, v in top.items():
                work = with_highlights(work, [n], v)
            x = list(candidate.get_params(where))
            again = self.refit(narrowed(work.with_params(x, where), where, REFIT_FRACTION), self.options.first_space)
            if again is None:
                break
            found = again.projected(seed, environment=self.model_env, name="light+colour+lobe (its box moved up)",
                                    from_scene=True)
            record = {"at_top": top, "loss_before": float(sum(more.stages[-1].objectives)),
                      "loss_after": float(sum(again.stages[-1].objectives))}
            record["kept"] = record["loss_after"] < record["loss_before"]
            raises.append(record)
            if not record["kept"]:
                break
            candidate, more, self.model_work = found, again, work
            self.stages.add(again)
        if raises:
            lobe["raised_shininess"] = raises
        return candidate, more

    def refit_with(self, added: list[str]) -> Scene:
        """One refit with every selected term (``added``), in a box around the light found, with a smaller
        search; it replaces the first fit where its loss is lower."""
        model, seed, first = self.model, int(self.plan.seeds[1]), self.first
        where, x = first.paths, list(first.x)
        box = narrowed(self.model_work.with_params(x, where), where, REFIT_FRACTION)
        more = self.refit(box, self.options.first_space)
        if more is None:
            return self.current
        if (codes := jpeg_codes(self.photo.blocking, self.options.space)) is not None:
            stays_linear(model, codes)
        bounce = "interreflection" in added or interreflection_given(self.work)
        if bounce:
            more.frozen_bounce = BOUNCE_PASSES  # the bounce held, from the light found without it
        # The refit's search starts from the light found (and a lobe's best trial shininess), so that its small
        # population cannot end worse than that; but not with the bounce: there the light found without it is
        # centimetres off, and a start there stops the held passes early (they end once a pass barely moves
        # the light): on rtloop's own bounce renders 0.15-0.41 mm -> 1.0-1.5 mm off (docs/methods.md,
        # "How a photo selects them").
        candidate = more.projected(seed, environment=self.model_env,
                                   name="+".join(["light", "colour", *model["terms"][1:], *added]),
                                   from_scene=not bounce)
        self.stages.add(more)
        if sum(more.stages[-1].objectives) >= sum(first.objectives):
            model["rejected"] = f"the refit with {', '.join(added)} did not lower the loss"
            return self.current
        model["terms"] += added
        if "specular" in added:
            model["specular_objects"] = self.names
            lobe = model["evidence"]["specular"]
            if lobe.get("lobe", "blinn-phong") == "blinn-phong" and not bounce:
                candidate, more = self.lobe_off_its_top(candidate, more, where, seed, lobe)
            if lobe.get("lobe") == "blinn-phong" and "coat" in lobe and not bounce:
                coated = _coat_after_refit(self.work, self.names, candidate, where,
                                           float(sum(more.stages[-1].objectives)), self.model_env, self.refit,
                                           self.options.first_space, seed, lobe)
                if coated is not None:
                    candidate, self.model_work, extra = coated
                    self.stages.add(extra)
        # The user's bounds back (the search box was narrowed), with the freed lobes' bounds kept.
        return restore_bounds(candidate, self.model_work)


#: A Blinn-Phong refit whose shininess ends within this fraction of its box's span (in log shininess) of the
#: box's top is refitted with the box moved up (:meth:`_Selection.lobe_off_its_top`), at most LOBE_RAISES
#: times. The refit's small search does not always reach the top exactly (a DiLiGenT ball photo's ended at
#: 1973 of 2000, 0.7 % of the span); a raise is kept only where it lowers the loss, and its search starts
#: from the light and shininess found, so a looser test costs a refit, never accuracy.
LOBE_TOP = 0.02
LOBE_RAISES = 2


def _at_top(scene: Scene, box: Scene, names: list[str]) -> dict[str, float]:
    """The spheres of ``names`` whose fitted shininess in ``scene`` lies within LOBE_TOP of its bounds'
    span in ``box`` (in log shininess) of their top: name -> that shininess."""
    paths = [f"objects.{n}.shininess" for n in names]
    values, bounds = scene.get_params(paths), box.bounds(paths)
    return {n: float(v) for n, v, (lo, hi) in zip(names, values, bounds)
            if lo > 0 and v > 0 and math.log(hi / v) <= LOBE_TOP * math.log(hi / lo)}


def _coat_after_refit(work: Scene, names: list[str], fitted: Scene, where: list[str], fitted_loss: float,
                      env: bool, refit: Callable[[Scene, str], Stages | None], space: str, seed: int,
                      lobe: dict[str, Any]) -> tuple[Scene, Scene, Stages] | None:
    """The coat tried again after Blinn-Phong's refit. The lobes were compared at the light found without
    any (:func:`.coat.choose_lobe`), which a highlight pulls towards itself: there Blinn-Phong's broader
    lobe can absorb the misplaced light and win, and its refit then ends degrees off on a coated ball
    (Mitsuba's roughplastic balls of studies/results/linear_photos.md: 0.8-3.3 deg with Blinn-Phong,
    0.02-0.07 deg with the coat given). So the fit is made once more with the coat (the roughness its
    evidence found), in the refit's box around the light Blinn-Phong's refit found, and the coat is kept
    when its loss is lower. ``fitted`` is the Blinn-Phong refit's scene, ``fitted_loss`` its loss, ``where``
    the paths of the light and colours. Returns (scene, its model, the refit's stages), or None where
    Blinn-Phong stays; the record goes in ``lobe["after_refit"]``. Not with the bounce (the coat's closed
    form does not model it)."""
    x = list(fitted.get_params(where))
    roughness = lobe["coat"]["roughness"]
    record: dict[str, Any] = {"roughness": roughness}
    lobe["after_refit"] = record
    model_work = with_coat(work, names, roughness)
    more = refit(narrowed(model_work.with_params(x, where), where, REFIT_FRACTION), space)
    if more is None:
        return None
    candidate = more.projected(seed, environment=env, name="light+colour+coat (after the lobe's refit)",
                               from_scene=True)
    record["loss_refit_coat"] = float(sum(more.stages[-1].objectives))
    record["loss_refit_blinn_phong"] = fitted_loss
    if record["loss_refit_coat"] >= record["loss_refit_blinn_phong"]:
        record["kept"] = "blinn-phong"
        return None
    record["kept"] = "coat"
    lobe.update(lobe="coat", roughness=roughness)
    return candidate, model_work, more


def _encoding_check(work: Scene, stages: Stages, seed: int, target: np.ndarray, sub: np.ndarray,
                    ratio: float, environment: bool = False) -> dict[str, Any]:
    """Whether ``target`` looks sRGB-encoded rather than linear: the base model fitted once more, on every
    other pixel in each direction, to the target decoded from sRGB; the two residuals against the rounding
    error (:func:`.selection.explained_ratio`; ``ratio``: the fit as given). Run only for photos in [0, 1]
    that the first fit does not explain and whose values are not decoded 8-bit codes; ``environment``: the
    base model has the environment's (or ambient light's) column."""
    decoded = np.ascontiguousarray(decode(target), dtype=np.float32)
    check = Stages(work, decoded, sub, None, stages.budget, stages.ident, clip=stages.clip, norm=stages.norm,
                   space="linear", threads=stages.threads, pixels_per_object=stages.pixels_per_object,
                   rng=np.random.default_rng(seed), callback=None, footprint=stages.footprint)
    check.saturated = None if stages.saturated is None else float(decode(np.float64(stages.saturated)))
    check.projected(seed, environment=environment)
    _, decoded_ratio = explained_ratio(sum(check.stages[-1].objectives), decoded, sub, norm=stages.norm)
    out: dict[str, Any] = {"ratio_as_given": ratio, "ratio_decoded": decoded_ratio,
                           "suspect": bool(decoded_ratio * ENCODED_GAIN <= ratio),
                           "rule": f"doubted when the sRGB-decoded image fits at least {ENCODED_GAIN:g}x better"}
    if out["suspect"]:
        out["doubt"] = (f"image: it looks sRGB-encoded, not linear (decoded from sRGB, the fit's residual is "
                        f"{decoded_ratio:.2g}x the rounding error against {ratio:.2g}x as given): pass linear "
                        "radiance, e.g. rtloop.load_image(path, scene) for a file, or rtloop.srgb_to_linear(array)")
    return out
