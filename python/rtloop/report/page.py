"""The report page: one self-contained HTML file (every image embedded, also written beside it) and
:func:`report`, which lays out the sections."""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import math
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import _native
from .._files import write_bytes
from ..scene import Scene
from .plots import (
    GenerationRow,
    _enlarge,
    _image_panel,
    _png_of_array,
    _png_of_figure,
    _rows_from_history,
    _rows_given,
    _srgb,
    _srgb8,
    plot_search,
)
from .answer import answer, colour_rows, light_sentence, scene_views, verdict_sentence
from .truth import image_metrics, truth_errors

__all__ = ["Report", "report"]

#: About this many frames in the strip when ``strip_every`` is not given (plus the last of every stage).
STRIP_FRAMES = 10
#: Strip frames are enlarged (nearest neighbour, whole factors) to at least this many pixels wide.
STRIP_MIN_WIDTH = 192


@dataclass
class Report:
    """What :func:`report` wrote and showed."""

    #: The HTML page.
    path: Path
    #: The PNGs written beside it (in the folder named after the page), in page order.
    files: list[Path]
    #: Error numbers of the fitted render against the objective (empty without an objective).
    metrics: dict[str, float]
    #: The data of every plot as drawn, read back from matplotlib: ``plots[panel][series] = (x, y)``;
    #: series ids are parameter names (``light.position.x``), ``truth:<name>``, ``product:<object>.<c>``,
    #: ``fitness:<stage>``. ``plots["_generation"]`` maps the x axis back to (stage, generation).
    plots: dict[str, Any]
    #: (stage, generation, fitness) of every frame of the strip.
    strip: list[tuple[str, int, float]]
    #: :func:`truth_errors` when a truth scene was given, else None.
    truth: dict[str, Any] | None = None
    #: Where the parameter rows came from: ``"generations"`` (given) or ``"history"`` (rebuilt).
    source: str = "generations"
    notes: list[str] = field(default_factory=list)
    #: The numbers the page opens with (:func:`rtloop.report.answer.answer`).
    answer: dict[str, Any] = field(default_factory=dict)
    #: What the scene picture drew per view (:func:`rtloop.report.answer.scene_views`).
    views: dict[str, Any] = field(default_factory=dict)


def _strip_frames(rows: Sequence[GenerationRow], every: int | None) -> list[int]:
    """Indices of the rows to render: every k-th generation of every stage, and each stage's last."""
    if not rows:
        return []
    k = every if every and every > 0 else max(1, math.ceil(len(rows) / STRIP_FRAMES))
    keep = []
    for i, r in enumerate(rows):
        last_of_stage = i == len(rows) - 1 or rows[i + 1].stage != r.stage
        if r.generation % k == 0 or last_of_stage:
            keep.append(i)
    return keep


_SAFE = re.compile(r"[^A-Za-z0-9_.+-]+")
_OURS = re.compile(r"^(strip_\d+_.*|param_.*|insert_.*)\.png$")


#: The two angles of a directional light in rtloop.uncertainty's sigma (radians).
_ANGLE_NAMES = ("light.direction.u", "light.direction.v")


def _fmt(v: Any, digits: int = 6) -> str:
    if v is None:
        return "–"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.{digits}g}" if math.isfinite(float(v)) else str(float(v))
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_fmt(x, digits) for x in v) + "]"
    return str(v)


_CSS = """
:root{color-scheme:light}
*{box-sizing:border-box}
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;color:#1d1d1f;
 background:#fafafa;margin:0 auto;max-width:1280px;padding:0 14px 40px}
h1{font-size:1.45em;margin:18px 0 4px}
h2{font-size:1.15em;margin:28px 0 8px;padding-bottom:4px;border-bottom:1px solid #ddd}
h3{font-size:1em;margin:16px 0 6px}
p.sub{color:#555;margin:0 0 10px}
img{max-width:100%;height:auto;display:block}
.row{display:flex;flex-wrap:wrap;gap:12px;align-items:flex-start}
figure{margin:0;background:#fff;border:1px solid #e4e4e4;border-radius:6px;padding:6px}
.row.three>figure{flex:1 1 260px;max-width:440px}
.row.plots>figure{flex:1 1 340px;max-width:600px}
.row.wide>figure{flex:1 1 100%;max-width:1000px}
.row.strip{display:grid;grid-template-columns:repeat(auto-fill,minmax(140px,1fr));gap:10px}
.strip img{width:100%;image-rendering:pixelated}
figcaption{font-size:.8em;color:#444;margin-top:4px;text-align:center}
.scroll{overflow-x:auto;max-width:100%}
table{border-collapse:collapse;font-size:.9em;background:#fff;margin:4px 0 8px}
th,td{border:1px solid #ddd;padding:3px 8px;text-align:left;vertical-align:top}
td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
th{background:#f1f1f1}
.note{background:#fff8e1;border-left:4px solid #f0b400;padding:6px 10px;margin:8px 0;font-size:.92em}
.muted{color:#666;font-size:.88em}
code{font-size:.92em}
"""

# After load, record on <body> how many images there are, how many decoded, and any script or load errors
# (a headless browser's --dump-dom then shows them; tests use this).
_CHECK = """
(function(){
  var errors = [];
  window.addEventListener('error', function(e){
    errors.push(e.message || (e.target && e.target.tagName) || 'error');
  }, true);
  window.addEventListener('load', function(){
    var imgs = Array.prototype.slice.call(document.images);
    var ok = imgs.filter(function(i){ return i.complete && i.naturalWidth > 0; }).length;
    var b = document.body;
    b.setAttribute('data-images', String(imgs.length));
    b.setAttribute('data-images-ok', String(ok));
    b.setAttribute('data-errors', String(errors.length));
    b.setAttribute('data-loaded', '1');
  });
})();
"""


class _Page:
    def __init__(self, folder: Path, folder_ref: str):
        self.parts: list[str] = []
        self.folder = folder
        self.folder_ref = folder_ref
        self.files: list[Path] = []

    def add(self, text: str) -> None:
        self.parts.append(text)

    def png(self, name: str, data: bytes, alt: str, caption: str | None = None) -> str:
        path = self.folder / name
        write_bytes(path, data)
        self.files.append(path)
        uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
        cap = f"<figcaption>{caption}</figcaption>" if caption else ""
        return (
            f'<figure><img src="{uri}" alt="{html.escape(alt)}" '
            f'title="{html.escape(self.folder_ref + "/" + name)}">{cap}</figure>'
        )


def _table(header: Sequence[str], body: Iterable[Sequence[Any]], numeric_from: int = 1) -> str:
    out = ['<div class="scroll"><table><thead><tr>']
    out += [f"<th>{html.escape(h)}</th>" for h in header]
    out.append("</tr></thead><tbody>")
    for row in body:
        out.append("<tr>")
        for i, cell in enumerate(row):
            cls = ' class="n"' if i >= numeric_from and not isinstance(cell, str) else ""
            text = cell if isinstance(cell, str) else _fmt(cell)
            out.append(f"<td{cls}>{html.escape(text)}</td>")
        out.append("</tr>")
    out.append("</tbody></table></div>")
    return "".join(out)


def report(
    result: Any,
    path: str | os.PathLike[str],
    *,
    objective: np.ndarray | str | os.PathLike[str] | None = None,
    truth: Any = None,
    generations: Iterable[Any] | None = None,
    speed_plot: str | os.PathLike[str] | None = None,
    strip_every: int | None = None,
    title: str | None = None,
    speed_vs_error_png: str | os.PathLike[str] | None = None,
    insertion: Any = None,
    final: np.ndarray | str | os.PathLike[str] | None = None,
) -> Report:
    """Write the fit report of ``result`` (a :class:`FitResult`) to the HTML page ``path`` (a lights fit's
    :class:`~rtloop.fit.lights.LightsFit` gets its own page: :func:`rtloop.report.lights.lights_report`).

    ``objective``: the photo the fit saw (linear float (H, W, 3) at the scene's size, or an image path,
    loaded with :func:`rtloop.load_image`) for the objective / fitted / difference panels and the error
    numbers; without it only the fitted render is shown. ``truth``: the true scene (path, dict or Scene)
    drawn dashed in the plots and compared in the tables. ``generations``: the best individual of every
    generation with all fit parameters, e.g. the ``GenerationInfo`` objects that ``rtloop.fit(...,
    callback=rows.append)`` collects, or (stage, generation[, fitness], params) tuples; without it they
    are rebuilt from ``result.stages[i].history`` (exact for the searched parameters only, see the page).
    ``speed_plot``: a PNG to include as the speed-against-error plot (e.g. the benchmark's
    benches/results/speed_vs_error.png; skipped if the file does not exist; ``speed_vs_error_png`` is its
    older name). ``insertion``: an :class:`rtloop.Insertion` (from :func:`rtloop.insert`), shown as the
    photo beside the composite. Nothing else is read from outside ``result``, ``objective`` and ``truth``.
    ``strip_every``: render every k-th generation in the strip (default: about ten frames). ``final``:
    the fitted scene's finished render (``rtloop-fit``'s final.png: linear float (H, W, 3) or a PNG path),
    shown beside the photo; without it, the one-sample render at the working resolution.

    The page opens with the answer: the light's position in mm with its error bar, what the photo fixes
    of the colours (in %), the verdict, and the scene from above and from the side with the fitted light
    and its error ellipse.

    The PNGs go into a folder named after the page (``report.html`` -> ``report/``) beside it; they are
    also embedded in the page, which needs nothing else to display. Returns a :class:`Report`.
    """
    from matplotlib.figure import Figure  # noqa: F401  (fail early, before writing anything)

    if hasattr(result, "evidence"):  # a lights fit (rtloop.fit.lights.LightsFit): its own page
        from .lights import lights_report

        return lights_report(result, path, objective=objective, final=final, title=title)
    page_path = Path(path)
    folder = page_path.with_name(page_path.stem if page_path.suffix else page_path.name + "_files")
    folder.mkdir(parents=True, exist_ok=True)
    page = _Page(folder, folder.name)
    scene: Scene = result.scene
    names = scene.param_names()
    ident = result.identifiability or {}

    terr, true_vals = _truth(result, truth, names)
    rows, source, notes = _generation_rows(result, generations, names)
    _page_head(page, result, scene, title)
    info = answer(result, terr)
    truth_light = ([terr["values"][f"light.position.{c}"] for c in "xyz"]
                   if terr is not None and all(f"light.position.{c}" in terr["values"] for c in "xyz") else None)
    views = _answer_section(page, result, info, truth_light)
    metrics = _objective_section(page, scene, objective, final)
    strip = _strip_section(page, scene, rows, strip_every, notes)
    plots = _plots_section(page, scene, rows, true_vals, terr, ident, set(info["split"]))
    _values_section(page, scene, terr, info)
    _fit_report_section(page, result, terr, ident)
    _speed_section(page, speed_plot if speed_plot is not None else speed_vs_error_png)
    if insertion is not None:
        _insertion_section(page, insertion)

    page.add(f'<p class="muted">rtloop {html.escape(_native.__version__)} · images also in '
             f"<code>{html.escape(folder.name)}/</code></p></body></html>\n")

    _write_page(page, page_path, folder)
    return Report(path=page_path, files=page.files, metrics=metrics, plots=plots, strip=strip, truth=terr,
                  source=source, notes=notes, answer=info, views=views)


def _truth(result: Any, truth: Any, names: list[str]) -> tuple[dict[str, Any] | None, np.ndarray | None]:
    """The fit's errors against the true scene (:func:`truth_errors`) and the true values of the fit
    parameters ``names``; both None without a truth."""
    true_vals = None
    terr = None
    if truth is not None:
        terr = truth_errors(result, truth)
        true_vals = np.array([terr["values"][n] for n in names], float)
    return terr, true_vals


def _generation_rows(result: Any, generations: Iterable[Any] | None, names: list[str]
                     ) -> tuple[list[GenerationRow], str, list[str]]:
    """The best individual of every generation: the ``generations`` given, else rebuilt from the stages'
    histories. Returns the rows, where they came from and notes on them."""
    if generations is not None:
        rows = _rows_given(result, generations, names)
        source, notes = "generations", []
        freed = [n for n in names if n not in result.generation_names()]
        if freed:
            notes.append(f"{', '.join(freed)}: freed by the fit for its refit (the photo showed a highlight), so "
                         "not among the generations' values; shown at the fitted value.")
    else:
        rows, notes = _rows_from_history(result)
        source = "history"
    return rows, source, notes


def _page_head(page: _Page, result: Any, scene: Scene, title: str | None) -> None:
    """The page's head (style, the check script), its title and the line on the fit: protocol, optimizer,
    seed, evaluations, time, size and when the page was made."""
    heading = title or "rtloop fit report"
    stamp = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    page.add(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{html.escape(heading)}</title><style>{_CSS}</style><script>{_CHECK}</script></head><body>"
        f"<h1>{html.escape(heading)}</h1>"
        f'<p class="sub">{html.escape(result.protocol)} protocol, '
        f"{'L-SHADE' if result.settings.get('optimizer') == 'lshade' else 'differential evolution'}, "
        f"seed {result.seed}, "
        f"{result.evaluations} evaluations in {result.seconds:.2f} s · {scene.width}×{scene.height} · "
        f"{html.escape(stamp)}</p>"
    )


def _write_page(page: _Page, page_path: Path, folder: Path) -> None:
    """Remove the images of an earlier page that this one does not have from ``folder``, then write the
    page."""
    written = {p.name for p in page.files}
    for old in folder.iterdir():
        if old.name not in written and _OURS.match(old.name) and old.is_file():
            old.unlink(missing_ok=True)
    write_bytes(page_path, "".join(page.parts).encode("utf-8"))


def _answer_section(page: _Page, result: Any, info: dict[str, Any], truth_light: list[float] | None) -> dict[str, Any]:
    """The answer first: the light, the colours, the verdict and the picture of the scene; what the
    picture drew (returned)."""
    page.add("<h2>The answer</h2>")
    page.add(f'<p class="answer"><b>{html.escape(light_sentence(info))}</b></p>')
    header, body = colour_rows(info)
    if body:
        page.add(_table(header, body, numeric_from=2))
    if info["split"]:
        page.add('<p class="muted">Without ambient light or a highlight of known strength the photo fixes only '
                 "these products: the light's intensity and the albedos in the scene are one way of splitting "
                 "them (a convention).</p>")
    verdict = verdict_sentence(info)
    if verdict:
        page.add(f"<p><b>{html.escape(verdict)}</b> The difference image below shows where.</p>")
    views: dict[str, Any] = {}
    if "position" in result.scene.to_dict()["light"]:
        fig, views = scene_views(result, info, truth_light)
        page.add('<div class="row wide">' + page.png(
            "scene_views.png", _png_of_figure(fig), "the scene from above and from the side with the fitted light",
            "camera, objects and the fitted light with its 1σ error ellipse, from above and from the side")
            + "</div>")
    return views


def _objective_section(page: _Page, scene: Scene, objective: Any, final: Any = None) -> dict[str, float]:
    """The objective, the fitted render (``final`` when given) and their difference, with the error numbers
    (returned; always of the working-resolution render the fit compared)."""
    metrics: dict[str, float] = {}
    fitted_img = np.asarray(_native.render(scene), np.float64)
    panels = []
    if objective is not None:
        if isinstance(objective, (str, os.PathLike)):
            from ..acquisition.objective import load_image

            objective = load_image(objective, scene)
        obj = np.asarray(objective, np.float64)
        if obj.shape != fitted_img.shape:
            raise ValueError(f"objective: shape {obj.shape} does not match the scene's {fitted_img.shape}")
        metrics = image_metrics(fitted_img, obj)
        diff = (np.minimum(fitted_img, 1.0) - obj).mean(axis=2)
        vmax = max(float(np.max(np.abs(diff))), 1e-6)
        panels.append(page.png("objective.png", _png_of_figure(_image_panel("the photo (as the fit saw it)",
                                                                            _srgb(obj))), "the objective"))
        panels.append(_fitted_panel(page, fitted_img, final))
        panels.append(page.png(
            "difference.png",
            _png_of_figure(_image_panel("render − photo (linear, mean of RGB)", diff, diverging=True,
                                        vmax=vmax)),
            "signed difference, fitted render minus objective",
            "red: render brighter, blue: render darker; symmetric scale",
        ))
    else:
        panels.append(_fitted_panel(page, fitted_img, final))
    page.add("<h2>Photo, fit and difference</h2>")
    page.add('<div class="row three">' + "".join(panels) + "</div>")
    if metrics:
        page.add(_table(
            ["error (the fit's render against the photo, at the working resolution)", "value"],
            [["L1, mean |difference| (linear)", metrics["l1_linear"]],
             ["RMSE (linear)", metrics["rmse_linear"]],
             ["PSNR (sRGB, dB)", metrics["psnr_srgb_db"]],
             ["sum |difference| over the image (linear, the fit's L1 loss)", metrics["sum_abs_linear"]]],
        ))
    else:
        page.add('<p class="muted">No objective given: no difference image or error numbers.</p>')
    return metrics


def _fitted_panel(page: _Page, fitted: np.ndarray, final: Any) -> str:
    """The fitted scene: ``final`` (an array or a PNG's path) at its own pixels where given, else the
    working-resolution render in a panel like the photo's."""
    if final is None:
        return page.png("fitted.png", _png_of_figure(_image_panel("fitted render (one sample per pixel)",
                                                                  _srgb(fitted))), "the fitted render")
    if isinstance(final, (str, os.PathLike)):
        from PIL import Image

        data = Path(final).read_bytes()
        with Image.open(io.BytesIO(data)) as im:
            width = im.size[0]
    else:
        data = _png_of_array(_srgb8(np.asarray(final, np.float64)))
        width = np.asarray(final).shape[1]
    return page.png("fitted.png", data, "the fitted scene, final.png",
                    f"the fitted scene (final.png, {width / fitted.shape[1]:.3g}× the photo's size)")


def _strip_section(page: _Page, scene: Scene, rows: Sequence[GenerationRow], strip_every: int | None,
                   notes: list[str]) -> list[tuple[str, int, float]]:
    """The best render through the stages; (stage, generation, fitness) of each frame."""
    strip: list[tuple[str, int, float]] = []
    frames = []
    for n, i in enumerate(_strip_frames(rows, strip_every)):
        r = rows[i]
        shot = _native.render(scene.with_params([float(v) for v in r.params]))
        name = f"strip_{n:02d}_{_SAFE.sub('_', r.stage)}_g{r.generation:04d}.png"
        cap = f"{html.escape(r.stage)} · gen {r.generation}<br>fitness {_fmt(r.fitness, 4)}"
        frames.append(page.png(name, _png_of_array(_enlarge(_srgb8(shot), STRIP_MIN_WIDTH)),
                               f"best render, {r.stage} generation {r.generation}", cap))
        strip.append((r.stage, r.generation, r.fitness))
    page.add("<h2>The search: best render through the stages</h2>")
    if frames:
        page.add('<div class="row strip">' + "".join(frames) + "</div>")
    else:
        page.add('<p class="muted">No generations recorded.</p>')
    for note in notes:
        page.add(f'<p class="muted">{html.escape(note)}</p>')
    return strip


def _plots_section(page: _Page, scene: Scene, rows: Sequence[GenerationRow], true_vals: np.ndarray | None,
                   terr: dict[str, Any] | None, ident: dict[str, Any], split: set[str]) -> dict[str, Any]:
    """The parameters and the fitness against generation; the plotted data read back."""
    plots: dict[str, Any] = {}
    if rows:
        figs, plots = plot_search(
            scene, rows, true_vals, terr["products_true"] if terr else None,
            products=bool(ident.get("degenerate")), split=split,
        )
        imgs = [page.png(f"param_{_SAFE.sub('_', pid)}.png" if pid != "fitness" else "fitness.png",
                         _png_of_figure(fig), f"plot: {pid}") for pid, fig in figs]
        page.add("<h2>Parameters and fitness against generation</h2>")
        if true_vals is not None:
            page.add('<p class="muted">Dashed: the true values.</p>')
        page.add('<div class="row plots">' + "".join(imgs) + "</div>")
    return plots


def _unit(name: str) -> tuple[float, str, str]:
    """How a parameter is shown: (factor, unit, format) - positions in mm, albedos in %."""
    if name.startswith("light.position."):
        return 1000.0, " mm", ".1f"
    if ".albedo." in name:
        return 100.0, " %", ".1f"
    if name == "light.intensity":
        return 1.0, " W/sr", ".4g"
    return 1.0, "", ".4g"


def _shown(name: str, v: float | None, fmt: str | None = None, signed: bool = False) -> str:
    if v is None:
        return "–"
    k, unit, f = _unit(name)
    return f"{k * v:{'+' if signed else ''}{fmt or f}}{unit}"


def _values_section(page: _Page, scene: Scene, terr: dict[str, Any] | None, info: dict[str, Any]) -> None:
    """The fitted values with their 1σ and bounds (and the truth and the errors when known): positions in
    mm, albedos in %."""
    names = scene.param_names()
    fitted = np.asarray(scene.get_params(scene.fit_paths), float)
    bounds = scene.bounds()
    split = set(info["split"])
    sigma = {}
    for n in names:
        s = (info.get("sigmas") or {}).get(n)
        sigma[n] = "" if s is None or n in split else "± " + _shown(n, s, ".2g")
    page.add("<h2>Fitted values</h2>")
    if terr is not None:
        zs = terr.get("sigmas", {})
        body = [[n, _shown(n, fitted[j]) + (" (convention)" if n in split else ""), sigma[n],
                 _shown(n, terr["values"][n]),
                 "split convention" if n in split else _shown(n, terr["errors"][n], ".3g", signed=True),
                 "" if n in split or zs.get(n) is None else f"{zs[n]:+.2g}",
                 f"{_shown(n, lo)} … {_shown(n, hi)}"]
                for j, (n, (lo, hi)) in enumerate(zip(names, bounds))]
        page.add(_table(["parameter", "fitted", "1σ", "truth", "error", "error / σ", "bounds"], body))
        if split:
            page.add("<p>Split convention: the photo fixes only the products of these parameters (light intensity "
                     "x colour x albedo x exposure), not each one; their truth and fitted values differ by how the "
                     "fit split the products. The product errors below are what the photo determines.</p>")
        errs = []
        if "light_position_m" in terr:
            errs.append(["light position error", f"{1000 * terr['light_position_m']:.3g} mm"])
        for obj, rel in terr["product_relative"].items():
            errs.append([f"{obj}: product relative error", f"{100 * rel:.3g} %"])
        if errs:
            page.add(_table(["compared with the truth", "value"], errs))
    else:
        body = [[n, _shown(n, fitted[j]) + (" (convention)" if n in split else ""), sigma[n],
                 f"{_shown(n, lo)} … {_shown(n, hi)}"]
                for j, (n, (lo, hi)) in enumerate(zip(names, bounds))]
        page.add(_table(["parameter", "fitted", "1σ", "bounds"], body))


def _search_rows(st: dict[str, Any], stages: list[dict[str, Any]]) -> list[list[str]]:
    """The settings that ran, in words: the method, the search (L-SHADE's budget, or DE's population, F and
    CR) and the generations each stage ran, the polish."""
    pop, gens = st.get("population"), st.get("generations") or []
    rows = [["method", "closed form: the colours solved for every candidate light"
             if st.get("method") == "projected" else f"{len(stages)} stage search: the light, then the colours"
             if len(stages) > 1 else str(st.get("method", "?"))]]
    if st.get("optimizer") == "lshade":
        budget = f", a budget of {pop * (int(gens[0]) + 1)} evaluations" if pop and gens else ""
        rows.append(["search", f"L-SHADE (adapts its own F and CR), population {pop} shrinking{budget}"])
    else:
        rows.append(["search", f"differential evolution, population {pop}, F {_fmt(st.get('f'))}, "
                               f"CR {_fmt(st.get('cr'))}"])
    rows.append(["generations run", ", ".join(f"{s['name']} {s['generations']}" for s in stages) or "–"])
    if st.get("method") == "projected" and st.get("polish"):
        rows.append(["polish", f"Nelder-Mead, up to {st['polish']} evaluations"])
    return rows


def _fit_report_section(page: _Page, result: Any, terr: dict[str, Any] | None, ident: dict[str, Any]) -> None:
    """The fit report: settings, stages, identifiability, products, uncertainty."""
    rep = result.report()
    st = rep.get("settings", {})
    page.add("<h2>Fit report</h2>")
    info = [
        ["protocol", str(rep.get("protocol"))],
        *_search_rows(st, rep.get("stages", [])),
        ["seed", str(rep.get("seed"))],
        ["render clipped to 1", _fmt(st.get("clip"))],
        ["threads", "all cores" if st.get("threads") is None else _fmt(st.get("threads"))],
        ["evaluations", _fmt(rep.get("evaluations"))],
        ["time (s)", _fmt(rep.get("seconds"), 4)],
    ]
    if st.get("projection_unavailable"):
        info.append(["closed-form method not used because", str(st["projection_unavailable"])])
    if rep.get("message"):
        info.append(["message", str(rep["message"])])
    page.add(_table(["setting", "value"], info))
    page.add("<h3>Stages</h3>")
    page.add(_table(
        ["stage", "parameters", "loss", "pixels", "generations", "evaluations", "seconds", "fitness"],
        [[s["name"], ", ".join(s["parameters"]), s["loss"], s["pixels"] or "all", s["generations"],
          s["evaluations"], s["seconds"], s["fitness"]] for s in rep.get("stages", [])],
        numeric_from=3,
    ))
    _identifiability_part(page, ident)
    _reference_part(page, rep.get("reference"))
    _products_part(page, rep.get("products") or {}, terr)
    _uncertainty_part(page, getattr(result, "uncertainty", None) or rep.get("uncertainty"))


def _identifiability_part(page: _Page, ident: dict[str, Any]) -> None:
    """The fit report's identifiability: the note and the determined combinations of a degenerate fit."""
    page.add("<h3>Identifiability</h3>")
    if ident.get("degenerate"):
        if ident.get("note"):
            page.add(f'<div class="note">{html.escape(str(ident["note"]))}</div>')
        if ident.get("determined"):
            page.add('<p class="muted">Determined: ' + ", ".join(
                f"<code>{html.escape(str(d))}</code>" for d in ident["determined"]) + "</p>")
    else:
        page.add('<p class="muted">Every fitted parameter is determined by the image separately.</p>')


def _reference_part(page: _Page, ref: dict[str, Any] | None) -> None:
    """The fit report's absolute light intensity and albedos, from a reference of known reflectance."""
    if not ref:
        return
    page.add(f"<h3>Absolute, from the {html.escape(str(ref['source']))} of reflectance "
             f"{_fmt(ref['reflectance'])} ({ref['pixels']} px)</h3>")
    body = [["light intensity (W/sr)", _fmt(ref["light_intensity_w_sr"])],
            *[[f"albedo {name} (R, G, B)", _fmt(a)] for name, a in ref["albedos"].items()],
            ["gauge applied (R, G, B)", _fmt(ref["gauge"])]]
    page.add(_table(["quantity", "value"], body))
    if ref.get("warning"):
        page.add(f'<p class="note">{html.escape(str(ref["warning"]))}</p>')


def _products_part(page: _Page, prods: dict[str, Any], terr: dict[str, Any] | None) -> None:
    """The fit report's products, with the truth and the relative error where known (``terr``)."""
    if not prods:
        return
    page.add("<h3>Products (exposure × intensity × light colour × albedo), R, G, B</h3>")
    if terr is not None:
        body = [[obj, _fmt(p), _fmt(terr["products_true"].get(obj)), terr["product_relative"].get(obj)]
                for obj, p in prods.items()]
        page.add(_table(["object", "fitted", "truth", "relative error"], body, numeric_from=3))
    else:
        body = [[obj, _fmt(p)] for obj, p in prods.items()]
        page.add(_table(["object", "fitted"], body, numeric_from=2))


def _uncertainty_part(page: _Page, uncertainty: Any) -> None:
    """The fit report's uncertainty: sigma per parameter (Gauss-Newton, block sandwich, and block bootstrap
    where it ran), a directional light's cone, the light's position as a whole, notes and warnings."""
    if not uncertainty:
        return
    page.add("<h3>Uncertainty (1 sigma, Gauss-Newton at the optimum, from the residual)</h3>")
    sigma = uncertainty.get("sigma", uncertainty) if isinstance(uncertainty, dict) else {}
    robust = uncertainty.get("robust") if isinstance(uncertainty, dict) else None
    rsig = robust.get("sigma", {}) if isinstance(robust, dict) else {}
    body = [[f"{k} (rad)" if str(k) in _ANGLE_NAMES else str(k), "not determined" if v is None else _fmt(v),
             "not determined" if rsig.get(k) is None else _fmt(rsig[k])]
            for k, v in sigma.items()]
    cone = uncertainty.get("light_direction") if isinstance(uncertainty, dict) else None
    if isinstance(cone, dict):  # a directional light: its two angles (radians) as one cone, in degrees
        line = ["light direction (angle, degrees)", "not determined", "not determined"]
        if isinstance(robust, dict) and robust.get("light_direction_deg") is not None:
            line[2] = f"{_fmt(robust['light_direction_deg'], 3)}° along the worse axis"
        if cone.get("angle_deg") is not None and cone.get("rms_angle_deg") is not None:
            line[1] = (f"{_fmt(cone['angle_deg'], 3)}° along the worse axis, "
                       f"{_fmt(cone['rms_angle_deg'], 3)}° rms")
        after = [i for i, row in enumerate(body) if row[0].startswith("light.direction.")]
        body.insert(after[-1] + 1 if after else len(body), line)
    if isinstance(robust, dict) and robust.get("light_position_m") is not None:
        body.append(["light position (whole, m)", "", f"{_fmt(robust['light_position_m'], 3)} along the worse axis"])
    heads = ["parameter", "sigma (Gauss-Newton)", "sigma (block sandwich: correlated residuals and the pixel footprint's shift)"]
    boot = uncertainty.get("bootstrap") if isinstance(uncertainty, dict) else None
    if isinstance(boot, dict) and boot.get("sigma"):  # the thorough mode: one more column
        bsig = boot["sigma"]
        for row in body:
            name = row[0]
            row.append(_fmt(bsig[name]) if bsig.get(name) is not None else
                       (f"{_fmt(boot['light_position_m'], 3)} along the worse axis"
                        if name.startswith("light position (whole") and boot.get("light_position_m") is not None
                        else ""))
        heads.append(f"sigma (block bootstrap: {boot.get('replicates')} refits, {_fmt(boot.get('ms'), 3)} ms)")
    page.add(_table(heads, body))
    for key, lead in (("why_none", "No block-sandwich error bars: "), ("smaller_blocks", "Block sandwich: ")):
        if isinstance(robust, dict) and robust.get(key):
            page.add(f"<p class='note'>{html.escape(lead + str(robust[key]))}</p>")
    for w in (uncertainty.get("warnings", []) if isinstance(uncertainty, dict) else []):
        page.add(f"<p class='note'>{html.escape(str(w))}</p>")


def _insertion_section(page: _Page, insertion: Any) -> None:
    """The photo beside the composite with the inserted objects (rtloop.insert)."""
    panels = [page.png(name, _png_of_array(_srgb8(np.asarray(image, np.float64))), alt)
              for name, image, alt in (("insert_photo.png", insertion.photo, "the photo"),
                                       ("insert_composite.png", insertion.composite,
                                        "the photo with the inserted objects"))]
    page.add("<h2>Inserted objects</h2>")
    page.add('<div class="row three">' + "".join(panels) + "</div>")
    page.add('<p class="muted">Differential rendering (Debevec 1998): the render of the objects where they '
             "are seen, elsewhere the photo plus the difference they make.</p>")


def _speed_section(page: _Page, speed_plot: str | os.PathLike[str] | None) -> None:
    """The speed-against-error plot, only when the caller gave one."""
    if speed_plot is not None and Path(speed_plot).is_file():
        data = Path(speed_plot).read_bytes()
        page.add("<h2>Speed against error (benchmark)</h2>")
        fig_html = page.png("speed_vs_error.png", data, "speed against error")
        page.add('<div class="row wide">' + fig_html + "</div>")
