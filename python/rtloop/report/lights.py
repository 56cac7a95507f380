"""The report of a lights fit (:class:`rtloop.fit.lights.LightsFit`): one self-contained page that opens
with every light (position or direction with its error bar, intensity with its error bar, its share of
the light), then the evidence for the number of lights (the held-out error per count), the photo beside
the fitted render and their difference, and the products per object. :func:`rtloop.report` hands a
LightsFit here."""

from __future__ import annotations

import html
import os
from pathlib import Path
from typing import Any

import numpy as np

from .. import _native
from .._files import write_bytes
from ..fit.lights import size_text
from .page import _CHECK, _CSS, Report, _objective_section, _Page, _table

__all__ = ["lights_report"]


def _cm(v: Any) -> str:
    return "–" if v is None else f"{float(np.linalg.norm(v)) * 100:.2f} cm"


def light_rows(fit: Any) -> list[list[str]]:
    """One table row per light: name, kind, where, its error bar, intensity, its error bar, share."""
    rows = []
    for light in fit.lights:
        if "direction" in light:
            where, bar = light["direction"], light.get("direction_error")
            bar_text = "–" if bar is None else "[" + ", ".join(f"{b:.3g}" for b in bar) + "]"
        else:
            where, bar_text = light["position"], _cm(light.get("position_error"))
        shape = f" r {light['radius']:.3g} m" if "radius" in light else ""
        if "size" in light:
            shape = " " + size_text(light).replace(" x ", " × ").replace("+-", "±")
        err = light.get("intensity_error")
        rows.append([light["name"], light["kind"] + shape, "(" + ", ".join(f"{v:.3f}" for v in where) + ")",
                     bar_text, f"{light['intensity']:.4g}",
                     "held (sets the albedos' scale)" if err is None else f"{err:.2g}", f"{light['share']:.1%}"])
    return rows


def lights_report(fit: Any, path: str | os.PathLike[str], *, objective: Any = None, final: Any = None,
                  title: str | None = None) -> Report:
    """Write the report of the lights fit ``fit`` to the HTML page ``path`` (images also in the folder
    named after it); ``objective`` and ``final`` as :func:`rtloop.report` takes them."""
    from matplotlib.figure import Figure  # noqa: F401  (fail early, before writing anything)

    page_path = Path(path)
    folder = page_path.with_name(page_path.stem if page_path.suffix else page_path.name + "_files")
    folder.mkdir(parents=True, exist_ok=True)
    page = _Page(folder, folder.name)
    heading = title or "rtloop lights fit report"
    n = len(fit.lights)
    page.add(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{html.escape(heading)}</title><style>{_CSS}</style><script>{_CHECK}</script></head><body>"
        f"<h1>{html.escape(heading)}</h1>"
        f'<p class="sub">the lights fit: {n} light{"s" if n != 1 else ""}, L-SHADE over their geometry, products '
        f"in closed form · {fit.evaluations} evaluations in {fit.seconds:.2f} s · "
        f"{fit.scene.width}×{fit.scene.height}</p>"
    )
    page.add("<h2>The lights</h2>")
    page.add(_table(["light", "kind", "position (m) or direction", "error bar (1σ)", "intensity",
                     "its error bar", "share of the light"], light_rows(fit), numeric_from=9))
    page.add('<p class="muted">Error bars (1σ): the loss\'s curvature at the optimum plus a delete-a-tile '
             "jackknife over 4 × 3 tiles of the image (docs/methods.md).</p>")
    for light in fit.lights:
        if "size_note" in light:
            page.add(f'<p class="muted">{html.escape(light["name"])}: {html.escape(light["size_note"])}.</p>')
    page.add("<h2>How many lights</h2>")
    if fit.evidence:
        page.add(_table(["lights", "held-out error", "held-out pixels", "kept"],
                        [[e["lights"], e["held_out"], e["pixels"], e["kept"]] for e in fit.evidence]))
        page.add('<p class="muted">Each count fitted on half the pixels and scored on the other half; a further '
                 "light is kept when it lowers the held-out error by 25 % or more.</p>")
    else:
        page.add(f'<p class="muted">{n} light{"s" if n != 1 else ""}, as asked (no choice made).</p>')
    metrics = _objective_section(page, fit.scene, objective, final)
    page.add("<h2>Products per object</h2>")
    body = []
    for name, rows in fit.products.items():
        for k, row in enumerate(rows):
            who = fit.lights[k]["name"] if k < n else "constant (ambient)" if k == n else \
                f"{fit.lights[k - n - 1]['name']} (its lobe)"
            body.append([name, who, *[float(v) for v in row]])
    page.add(_table(["object", "light", "R", "G", "B"], body, numeric_from=2))
    page.add(f'<p class="muted">rtloop {html.escape(_native.__version__)} · images also in '
             f"<code>{html.escape(folder.name)}/</code></p></body></html>\n")
    write_bytes(page_path, "".join(page.parts).encode("utf-8"))
    return Report(path=page_path, files=page.files, metrics=metrics, plots={}, strip=[], source="lights",
                  answer={"lights": fit.lights, "evidence": fit.evidence})
