"""The outline pixels of a fit with the pixel footprint (docs/methods.md, "Pixel footprint"): at pixel
centres, unless the photo shows it needs them integrated over the pixel's area. The closed-form search's
outline gate (``_native.optimize(..., silhouettes="auto")``) evaluates its light's loss once more with the
outlines integrated and, where that explains the photo better by ``OUTLINE_GAIN`` of the loss, polishes the
light again with them and keeps the result where its loss is lower. This module reads its evidence into the
fit's record."""

from __future__ import annotations

from typing import Any

from .stages import Stages

__all__ = ["OUTLINE_GAIN", "OUTLINE_SHARE", "OUTLINE_SHARE_GAIN", "outlines_taken", "record_outlines"]

#: The outline gate's least relative fall of the loss (the core's ``fit::outlines::OUTLINE_GAIN``).
OUTLINE_GAIN = 0.45
#: Or this share of some object's lit pixels on its outline (``fit::outlines::OUTLINE_SHARE``) and a fall
#: of ``OUTLINE_SHARE_GAIN`` at least.
OUTLINE_SHARE = 0.5
OUTLINE_SHARE_GAIN = 0.15


def _last_gate(stages: Stages) -> tuple[float, float, int, float, bool, float | None, bool] | None:
    """The evidence of the last stage of ``stages`` that ran the outline gate (None: none did)."""
    return next((s.outlines for s in reversed(stages.stages) if s.outlines is not None), None)


def outlines_taken(stages: Stages, silhouettes: str) -> bool:
    """Whether the fit of ``stages`` compared the photo with its outline pixels integrated: always with
    ``silhouettes`` "on", with "auto" where the last gate kept the polish with them."""
    if silhouettes == "on":
        return True
    gate = _last_gate(stages) if silhouettes == "auto" else None
    return gate is not None and gate[6]


def record_outlines(stages: Stages, silhouettes: str, model: dict[str, Any], settings: dict[str, Any]) -> None:
    """``model["outlines"]``: how the fit took the outline pixels ("integrated" or "centres"), why, and the
    gate's evidence where it ran; ``settings["silhouettes"]``: whether the model compared integrates them
    (the render of :func:`rtloop.fit.framing.compared_render` and the uncertainty follow it)."""
    taken = outlines_taken(stages, silhouettes)
    settings["silhouettes"] = taken
    record: dict[str, Any] = {"mode": silhouettes, "used": "integrated" if taken else "centres"}
    gate = _last_gate(stages) if silhouettes == "auto" else None
    if gate is not None:
        centre, integrated, pixels, share, fired, polished, kept = gate
        gain = (centre - integrated) / centre if centre > 0 else 0.0
        record["evidence"] = {"loss_centres": centre, "loss_integrated": integrated, "outline_pixels": pixels,
                              "outline_share": share, "min_share": OUTLINE_SHARE,
                              "min_gain_with_share": OUTLINE_SHARE_GAIN,
                              "gain": gain, "min_gain": OUTLINE_GAIN, "fired": fired, "loss_polished": polished,
                              "kept": kept}
        record["why"] = (f"at the fitted light, integrating the {pixels} outline pixels lowers the loss by "
                         f"{100 * gain:.1f} % (the gate takes {100 * OUTLINE_GAIN:g} %, or {100 * OUTLINE_SHARE_GAIN:g} % "
                         f"where half an object's lit pixels are on its outline: here up to {100 * share:.0f} %)"
                         + ("" if not fired else "; polished again with them: " + ("kept" if kept else "not lower")))
    elif silhouettes == "on":
        record["why"] = "forced (footprint='silhouette')"
    else:
        record["why"] = "no footprint polish (footprint 'on' or 'off', or a fit without the closed form's search)"
    model["outlines"] = record
