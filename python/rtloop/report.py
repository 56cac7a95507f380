"""The fit report: one self-contained HTML page that shows the search, not just its numbers.

    rows = []
    result = rtloop.fit(scene, photo, callback=rows.append)
    rtloop.report(result, "out/report.html", objective=photo, truth="scene.json", generations=rows)

The page shows the objective, the fitted render and their signed difference with the error numbers; a
strip of the best render through all stages (the paper's Fig. 5); the parameters and the fitness against
generation (the truth dashed when given); the fit report (method, budgets, time, identifiability, the
determined products); and a speed-against-error plot when one is given. Every image is embedded as a
base64 data URI (the page needs no network and no other file) and also written as a PNG into a folder
named after the page (``report.html`` -> ``report/``). Every file is written atomically.

matplotlib (Agg, through ``Figure`` directly: no pyplot, no global backend change) is imported only when a
report is made, so ``import rtloop`` stays fast.
"""

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

from . import _native
from . import _srgb as _srgb_codec
from ._files import write_bytes
from .fit.products import products_of
from .scene import Scene, load_scene, scene_to_dict

__all__ = ["GenerationRow", "Report", "report", "truth_errors", "truth_values"]

#: About this many frames in the strip when ``strip_every`` is not given (plus the last of every stage).
STRIP_FRAMES = 10
#: Strip frames are enlarged (nearest neighbour, whole factors) to at least this many pixels wide.
STRIP_MIN_WIDTH = 192
_DPI = 110
_RGB = ("#d62728", "#2ca02c", "#1f77b4")
_XYZ = ("#1f77b4", "#ff7f0e", "#2ca02c")


@dataclass(frozen=True)
class GenerationRow:
    """The best individual of one generation: all of the scene's fit parameters (``params``, in the order
    of ``scene.param_names()``), as ``rtloop.fit``'s callback reports them in a ``GenerationInfo``."""

    stage: str
    generation: int
    fitness: float
    params: np.ndarray


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


# --- truth -------------------------------------------------------------------------------------------------


def truth_values(scene: Scene, truth: Any) -> tuple[Scene, np.ndarray]:
    """The truth scene (path, dict or Scene) read with ``scene``'s fit section, and the true values of
    ``scene.param_names()``. Raises RtloopError/SceneError if the truth lacks one of the fitted things."""
    truth_scene = load_scene(truth)
    d = scene_to_dict(truth_scene)
    d["fit"] = scene_to_dict(scene)["fit"]
    aligned = load_scene(d)
    return aligned, np.asarray(aligned.get_params(scene.fit_paths), float)


def truth_errors(result: Any, truth: Any) -> dict[str, Any]:
    """Compare a fit with the true scene: per-parameter values and errors, the light position error in
    metres (when the position was fitted) and each object's product relative error,
    |P_fit - P_true| / |P_true| over R, G, B (products: exposure x intensity x colour x albedo)."""
    scene = result.scene
    aligned, true = truth_values(scene, truth)
    names = scene.param_names()
    fitted = np.asarray(scene.get_params(scene.fit_paths), float)
    out: dict[str, Any] = {
        "values": {n: float(v) for n, v in zip(names, true)},
        "errors": {n: float(f - t) for n, f, t in zip(names, fitted, true)},
    }
    pos = [names.index(f"light.position.{c}") for c in "xyz" if f"light.position.{c}" in names]
    if len(pos) == 3:
        out["light_position_m"] = float(np.linalg.norm(fitted[pos] - true[pos]))
    fit_p, true_p = products_of(scene_to_dict(scene)), products_of(scene_to_dict(aligned))
    rel = {}
    for name, p in fit_p.items():
        t = true_p.get(name)
        if t is not None:
            denom = float(np.linalg.norm(t))
            rel[name] = float(np.linalg.norm(p - t) / denom) if denom > 0 else float("nan")
    out["products_true"] = {k: [float(v) for v in p] for k, p in true_p.items()}
    out["product_relative"] = rel
    return out


# --- the rows of the search --------------------------------------------------------------------------------


def _rows_given(result: Any, generations: Iterable[Any], n: int) -> list[GenerationRow]:
    fitness_of = {(s.name, int(h[0])): float(h[1]) for s in result.stages for h in s.history}
    rows = []
    for r in generations:
        if hasattr(r, "params"):
            stage, gen, fit_, params = r.stage, r.generation, getattr(r, "fitness", None), r.params
        elif isinstance(r, dict):
            stage, gen, fit_, params = r["stage"], r["generation"], r.get("fitness"), r["params"]
        elif len(r) == 3:
            stage, gen, params = r
            fit_ = None
        elif len(r) == 4:
            stage, gen, fit_, params = r
        else:
            raise ValueError(
                "generations: rows must be GenerationInfo-like (stage, generation, fitness, params), "
                f"dicts with those keys, or (stage, generation[, fitness], params) tuples; got {r!r}"
            )
        params = np.asarray(params, float).reshape(-1)
        if params.size != n:
            raise ValueError(
                f"generations: row ({stage!r}, {gen}) has {params.size} parameter values; the scene has {n}"
            )
        gen = int(gen)
        fit_ = float(fit_) if fit_ is not None else fitness_of.get((str(stage), gen), float("nan"))
        rows.append(GenerationRow(str(stage), gen, fit_, params))
    return rows


def _rows_from_history(result: Any) -> tuple[list[GenerationRow], list[str]]:
    """Full parameter vectors rebuilt from ``result.stages[i].history``: a stage's own parameters from its
    history, the others at the value the previous stages left them (the fitted value if none set them)."""
    scene = result.scene
    names = scene.param_names()
    current = np.asarray(scene.get_params(scene.fit_paths), float)
    rows, notes = [], []
    held: list[str] = []
    for s in result.stages:
        idx = [names.index(n) for n in s.param_names]
        for gen, fitness, _objectives, x in s.history:
            full = current.copy()
            full[idx] = np.asarray(x, float)
            rows.append(GenerationRow(s.name, int(gen), float(fitness), full))
        if s.history:
            current = current.copy()
            current[idx] = np.asarray(s.history[-1][3], float)
        if s.products is not None:
            held.append(s.name)
    notes.append(
        "Rebuilt from the fit history: each stage's own parameters per generation; the others at the value "
        "the earlier stages left them, or at the fitted value where no earlier stage set them. Pass the fit "
        "callback's rows (generations=) for the exact values."
    )
    if held:
        notes.append(
            f"Stage {', '.join(held)} solves the colours in closed form; the history keeps only the light "
            "position, so the colours (and intensity) are shown at their fitted values."
        )
    return rows, notes


def _stage_axis(rows: Sequence[GenerationRow]) -> tuple[np.ndarray, list[tuple[str, float, float]]]:
    """A global x (generations counted on across stages) per row, and each stage's (name, first x, last x)."""
    xs = np.zeros(len(rows))
    spans: list[list[Any]] = []
    offset, base = 0.0, 0
    for i, r in enumerate(rows):
        if i == 0 or r.stage != rows[i - 1].stage:
            offset = xs[i - 1] + 1 if i else 0.0
            base = r.generation
            spans.append([r.stage, offset, offset])
        xs[i] = offset + (r.generation - base)
        spans[-1][2] = float(xs[i])
    return xs, [(str(a), float(b), float(c)) for a, b, c in spans]


# --- images ------------------------------------------------------------------------------------------------


def _srgb(linear: np.ndarray) -> np.ndarray:
    return _srgb_codec.encode(linear, np.float64)


def _srgb8(linear: np.ndarray) -> np.ndarray:
    return _srgb_codec.encode8(linear, np.float64)


def _png_of_array(rgb8: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb8), "RGB").save(buf, "PNG", optimize=True)
    return buf.getvalue()


def _png_of_figure(fig: Any) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI, metadata={"Software": None})
    return buf.getvalue()


def _enlarge(rgb8: np.ndarray, min_width: int) -> np.ndarray:
    k = max(1, math.ceil(min_width / rgb8.shape[1]))
    return np.repeat(np.repeat(rgb8, k, axis=0), k, axis=1) if k > 1 else rgb8


def image_metrics(render_linear: np.ndarray, objective_linear: np.ndarray) -> dict[str, float]:
    """L1 (mean |difference|) and RMSE in linear RGB, PSNR (dB, peak 1) of the sRGB-encoded images, and the
    fit's own whole-image loss (sum of |difference|). The render is clipped to 1 as the fit compares it."""
    r = np.minimum(np.asarray(render_linear, np.float64), 1.0)
    o = np.asarray(objective_linear, np.float64)
    d = r - o
    mse_srgb = float(np.mean((_srgb(r) - _srgb(o)) ** 2))
    return {
        "l1_linear": float(np.mean(np.abs(d))),
        "rmse_linear": float(np.sqrt(np.mean(d * d))),
        "psnr_srgb_db": float(10 * np.log10(1.0 / mse_srgb)) if mse_srgb > 0 else float("inf"),
        "sum_abs_linear": float(np.sum(np.abs(d))),
    }


def _image_panel(title: str, image: np.ndarray, *, diverging: bool = False, vmax: float = 1.0) -> Any:
    """One image with a title and a colour-bar slot (used by the difference, left empty by the others), so
    that the panels side by side are the same size. Fixed margins: no layout engine (fast)."""
    from matplotlib.figure import Figure

    h, w = image.shape[:2]
    fig_w, img_w, pad, title_h, cbar_w = 4.4, 3.55, 0.1, 0.34, 0.14
    img_h = img_w * h / w
    fig_h = img_h + title_h + 2 * pad
    fig = Figure(figsize=(fig_w, fig_h))
    ax = fig.add_axes((pad / fig_w, pad / fig_h, img_w / fig_w, img_h / fig_h))
    ax.set_title(title, fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    if diverging:
        im = ax.imshow(image, cmap="RdBu_r", vmin=-vmax, vmax=vmax, interpolation="nearest", aspect="auto")
        cax = fig.add_axes(((pad + img_w + 0.1) / fig_w, pad / fig_h, cbar_w / fig_w, img_h / fig_h))
        cb = fig.colorbar(im, cax=cax)
        cb.ax.tick_params(labelsize=8)
    else:
        ax.imshow(image, interpolation="nearest", aspect="auto")
    return fig


# --- plots -------------------------------------------------------------------------------------------------


def _panels_spec(scene: Scene, names: list[str]) -> list[tuple[str, str, list[str], Sequence[str]]]:
    """(panel id, title, parameter names, colours) for every fit path, in the fit section's order."""
    out = []
    for path in scene.fit_paths:
        members = scene.param_names([path])
        if path == "light.position":
            title, colours = "light position (m)", _XYZ
        elif path == "light.intensity":
            title, colours = "light intensity (W/sr)", ("#9467bd",)
        elif path.startswith("objects.") and path.endswith(".albedo"):
            title, colours = f"{path.split('.')[1]}: albedo R, G, B", _RGB
        elif len(members) == 3 and path in ("light.color", "ambient"):
            title, colours = f"{path} R, G, B", _RGB
        else:
            title, colours = path, ("C0", "C1", "C2", "C3")
        out.append((path, title, members, colours))
    return out


def _stage_marks(ax: Any, spans: list[tuple[str, float, float]]) -> None:
    from matplotlib.transforms import blended_transform_factory

    tr = blended_transform_factory(ax.transData, ax.transAxes)
    for i, (stage, start, _end) in enumerate(spans):
        if i:
            ax.axvline(start - 0.5, color="0.55", lw=0.8, ls=":")
        if len(spans) > 1:
            ax.text(start, 1.005, stage, transform=tr, fontsize=7, color="0.35", va="bottom", ha="left")


def _read_back(ax: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The (x, y) of every line drawn with a gid: exactly what the figure shows."""
    return {
        line.get_gid(): (np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float))
        for line in ax.get_lines()
        if line.get_gid()
    }


def plot_search(
    scene: Scene, rows: Sequence[GenerationRow], truth: np.ndarray | None = None,
    truth_products: dict[str, Sequence[float]] | None = None, products: bool = False,
) -> tuple[list[tuple[str, Any]], dict[str, Any]]:
    """Parameter evolution (one panel per fit path, optionally the products per object) and the fitness
    (log y) against generation across stages. Returns [(panel id, Figure)] and the plotted data read back
    from the figures (see :attr:`Report.plots`)."""
    from matplotlib.figure import Figure

    names = scene.param_names()
    xs, spans = _stage_axis(rows)
    P = np.array([r.params for r in rows], float).reshape(len(rows), len(names))
    figs: list[tuple[str, Any]] = []
    data: dict[str, Any] = {"_generation": {"x": xs, "rows": [(r.stage, r.generation) for r in rows]}}

    def new(title: str, ylabel: str = "") -> tuple[Any, Any]:
        fig = Figure(figsize=(5.2, 3.1))
        ax = fig.subplots()
        fig.subplots_adjust(left=0.12, right=0.98, bottom=0.15, top=0.88 if len(spans) > 1 else 0.9)
        ax.set_title(title, fontsize=10, pad=13 if len(spans) > 1 else 6)
        ax.set_xlabel("generation (across stages)", fontsize=8)
        if ylabel:
            ax.set_ylabel(ylabel, fontsize=8)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.25)
        _stage_marks(ax, spans)
        return fig, ax

    for pid, title, members, colours in _panels_spec(scene, names):
        fig, ax = new(title)
        for k, name in enumerate(members):
            j = names.index(name)
            colour = colours[k % len(colours)]
            ax.plot(xs, P[:, j], color=colour, lw=1.4, label=name.rsplit(".", 1)[-1], gid=name)
            if truth is not None:
                ax.plot([xs[0], xs[-1]], [truth[j], truth[j]], color=colour, lw=1.0, ls="--",
                        gid=f"truth:{name}")
        if truth is not None:
            ax.plot([], [], color="0.3", ls="--", lw=1.0, label="truth")
        if len(members) > 1 or truth is not None:
            ax.legend(fontsize=7, ncol=4, loc="best", framealpha=0.8)
        figs.append((pid, fig))
        data[pid] = _read_back(ax)

    if products:
        per_row = [products_of(scene.with_params(list(map(float, r.params))).to_dict()) for r in rows]
        for obj in scene.object_names:
            fig, ax = new(f"{obj}: product intensity × albedo, R, G, B")
            for c, colour in enumerate(_RGB):
                ys = np.array([p[obj][c] for p in per_row])
                ax.plot(xs, ys, color=colour, lw=1.4, label="RGB"[c], gid=f"product:{obj}.{'rgb'[c]}")
                if truth_products is not None and obj in truth_products:
                    t = float(truth_products[obj][c])
                    ax.plot([xs[0], xs[-1]], [t, t], color=colour, lw=1.0, ls="--",
                            gid=f"truth:product:{obj}.{'rgb'[c]}")
            if truth_products is not None:
                ax.plot([], [], color="0.3", ls="--", lw=1.0, label="truth")
            ax.legend(fontsize=7, ncol=4, loc="best", framealpha=0.8)
            pid = f"products.{obj}"
            figs.append((pid, fig))
            data[pid] = _read_back(ax)

    fig, ax = new("best fitness per stage (log scale)")
    ax.set_yscale("log")
    fitness = np.array([r.fitness for r in rows], float)
    for i, (stage, start, end) in enumerate(spans):
        sel = (xs >= start) & (xs <= end)
        ax.plot(xs[sel], fitness[sel], color=f"C{i % 10}", lw=1.5, label=stage, gid=f"fitness:{stage}")
    if len(spans) > 1:
        ax.legend(fontsize=7, loc="best", framealpha=0.8)
    figs.append(("fitness", fig))
    data["fitness"] = _read_back(ax)
    return figs, data


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


# --- files -------------------------------------------------------------------------------------------------


_SAFE = re.compile(r"[^A-Za-z0-9_.+-]+")
_OURS = re.compile(r"^(strip_\d+_.*|param_.*)\.png$")


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
) -> Report:
    """Write the fit report of ``result`` (a :class:`FitResult`) to the HTML page ``path``.

    ``objective``: the photo the fit saw (linear float (H, W, 3) at the scene's size, or an image path,
    loaded with :func:`rtloop.load_image`) for the objective / fitted / difference panels and the error
    numbers; without it only the fitted render is shown. ``truth``: the true scene (path, dict or Scene)
    drawn dashed in the plots and compared in the tables. ``generations``: the best individual of every
    generation with all fit parameters, e.g. the ``GenerationInfo`` objects that ``rtloop.fit(...,
    callback=rows.append)`` collects, or (stage, generation[, fitness], params) tuples; without it they
    are rebuilt from ``result.stages[i].history`` (exact for the searched parameters only, see the page).
    ``speed_plot``: a PNG to include as the speed-against-error plot (e.g. the benchmark's
    benches/results/speed_vs_error.png; skipped if the file does not exist; ``speed_vs_error_png`` is its
    older name). Nothing else is read from outside ``result``, ``objective`` and ``truth``.
    ``strip_every``: render every k-th generation in the strip (default: about ten frames).

    The PNGs go into a folder named after the page (``report.html`` -> ``report/``) beside it; they are
    also embedded in the page, which needs nothing else to display. Returns a :class:`Report`.
    """
    from matplotlib.figure import Figure  # noqa: F401  (fail early, before writing anything)

    page_path = Path(path)
    folder = page_path.with_name(page_path.stem if page_path.suffix else page_path.name + "_files")
    folder.mkdir(parents=True, exist_ok=True)
    page = _Page(folder, folder.name)
    scene: Scene = result.scene
    names = scene.param_names()
    fitted = np.asarray(scene.get_params(scene.fit_paths), float)
    bounds = scene.bounds()
    ident = result.identifiability or {}

    true_vals = None
    terr = None
    if truth is not None:
        terr = truth_errors(result, truth)
        true_vals = np.array([terr["values"][n] for n in names], float)

    if generations is not None:
        rows = _rows_given(result, generations, len(names))
        source, notes = "generations", []
    else:
        rows, notes = _rows_from_history(result)
        source = "history"

    heading = title or "rtloop fit report"
    stamp = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    page.add(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{html.escape(heading)}</title><style>{_CSS}</style><script>{_CHECK}</script></head><body>"
        f"<h1>{html.escape(heading)}</h1>"
        f'<p class="sub">{html.escape(result.protocol)} protocol, method '
        f"{html.escape(str(result.settings.get('method', '?')))}, seed {result.seed}, "
        f"{result.evaluations} evaluations in {result.seconds:.2f} s · {scene.width}×{scene.height} · "
        f"{html.escape(stamp)}</p>"
    )

    # 1. objective, fitted, difference ---------------------------------------------------------------------
    metrics: dict[str, float] = {}
    fitted_img = np.asarray(_native.render(scene), np.float64)
    panels = []
    if objective is not None:
        if isinstance(objective, (str, os.PathLike)):
            from .acquisition.objective import load_image

            objective = load_image(objective, scene)
        obj = np.asarray(objective, np.float64)
        if obj.shape != fitted_img.shape:
            raise ValueError(f"objective: shape {obj.shape} does not match the scene's {fitted_img.shape}")
        metrics = image_metrics(fitted_img, obj)
        diff = (np.minimum(fitted_img, 1.0) - obj).mean(axis=2)
        vmax = max(float(np.max(np.abs(diff))), 1e-6)
        panels.append(page.png("objective.png", _png_of_figure(_image_panel("objective (photo)", _srgb(obj))),
                               "the objective"))
        panels.append(page.png("fitted.png", _png_of_figure(_image_panel("fitted render", _srgb(fitted_img))),
                               "the fitted render"))
        panels.append(page.png(
            "difference.png",
            _png_of_figure(_image_panel("render − objective (linear, mean of RGB)", diff, diverging=True,
                                        vmax=vmax)),
            "signed difference, fitted render minus objective",
            "red: render brighter, blue: render darker; symmetric scale",
        ))
    else:
        panels.append(page.png("fitted.png", _png_of_figure(_image_panel("fitted render", _srgb(fitted_img))),
                               "the fitted render"))
    page.add("<h2>Objective, fit and difference</h2>")
    page.add('<div class="row three">' + "".join(panels) + "</div>")
    if metrics:
        page.add(_table(
            ["error (fitted render vs objective)", "value"],
            [["L1, mean |difference| (linear)", metrics["l1_linear"]],
             ["RMSE (linear)", metrics["rmse_linear"]],
             ["PSNR (sRGB, dB)", metrics["psnr_srgb_db"]],
             ["sum |difference| over the image (linear, the fit's L1 loss)", metrics["sum_abs_linear"]]],
        ))
    else:
        page.add('<p class="muted">No objective given: no difference image or error numbers.</p>')

    # 2. the strip ---------------------------------------------------------------------------------------
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

    # 3. parameter evolution and fitness -------------------------------------------------------------------
    plots: dict[str, Any] = {}
    if rows:
        figs, plots = plot_search(
            scene, rows, true_vals, terr["products_true"] if terr else None,
            products=bool(ident.get("degenerate")),
        )
        imgs = [page.png(f"param_{_SAFE.sub('_', pid)}.png" if pid != "fitness" else "fitness.png",
                         _png_of_figure(fig), f"plot: {pid}") for pid, fig in figs]
        page.add("<h2>Parameters and fitness against generation</h2>")
        if true_vals is not None:
            page.add('<p class="muted">Dashed: the true values.</p>')
        page.add('<div class="row plots">' + "".join(imgs) + "</div>")

    # 4. fitted values -----------------------------------------------------------------------------------
    page.add("<h2>Fitted values</h2>")
    if terr is not None:
        body = [[n, fitted[j], terr["values"][n], terr["errors"][n], f"{_fmt(lo, 4)} … {_fmt(hi, 4)}"]
                for j, (n, (lo, hi)) in enumerate(zip(names, bounds))]
        page.add(_table(["parameter", "fitted", "truth", "error", "bounds"], body))
        errs = []
        if "light_position_m" in terr:
            errs.append(["light position error (m)", terr["light_position_m"]])
        for obj, rel in terr["product_relative"].items():
            errs.append([f"{obj}: product relative error", rel])
        if errs:
            page.add(_table(["compared with the truth", "value"], errs))
    else:
        body = [[n, fitted[j], f"{_fmt(lo, 4)} … {_fmt(hi, 4)}"]
                for j, (n, (lo, hi)) in enumerate(zip(names, bounds))]
        page.add(_table(["parameter", "fitted", "bounds"], body))

    # 5. the fit report --------------------------------------------------------------------------------------
    rep = result.report()
    st = rep.get("settings", {})
    page.add("<h2>Fit report</h2>")
    info = [
        ["protocol", str(rep.get("protocol"))],
        ["method", str(st.get("method", "?"))],
        ["seed", str(rep.get("seed"))],
        ["population", _fmt(st.get("population"))],
        ["generations (light stages, colour stages)", _fmt(st.get("generations"))],
        ["F, CR", f"{_fmt(st.get('f'))}, {_fmt(st.get('cr'))}"],
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
    page.add("<h3>Identifiability</h3>")
    if ident.get("degenerate"):
        if ident.get("note"):
            page.add(f'<div class="note">{html.escape(str(ident["note"]))}</div>')
        if ident.get("determined"):
            page.add('<p class="muted">Determined: ' + ", ".join(
                f"<code>{html.escape(str(d))}</code>" for d in ident["determined"]) + "</p>")
    else:
        page.add('<p class="muted">Every fitted parameter is determined by the image separately.</p>')
    prods = rep.get("products") or {}
    if prods:
        page.add("<h3>Products (exposure × intensity × light colour × albedo), R, G, B</h3>")
        if terr is not None:
            body = [[obj, _fmt(p), _fmt(terr["products_true"].get(obj)), terr["product_relative"].get(obj)]
                    for obj, p in prods.items()]
            page.add(_table(["object", "fitted", "truth", "relative error"], body, numeric_from=3))
        else:
            body = [[obj, _fmt(p)] for obj, p in prods.items()]
            page.add(_table(["object", "fitted"], body, numeric_from=2))
    uncertainty = getattr(result, "uncertainty", None) or rep.get("uncertainty")
    if uncertainty:
        page.add("<h3>Uncertainty (1 sigma, Gauss-Newton at the optimum, from the residual)</h3>")
        sigma = uncertainty.get("sigma", uncertainty) if isinstance(uncertainty, dict) else {}
        body = [[f"{k} (rad)" if str(k) in _ANGLE_NAMES else str(k), "not determined" if v is None else _fmt(v)]
                for k, v in sigma.items()]
        cone = uncertainty.get("light_direction") if isinstance(uncertainty, dict) else None
        if isinstance(cone, dict):  # a directional light: its two angles (radians) as one cone, in degrees
            line = ["light direction (angle, degrees)", "not determined"]
            if cone.get("angle_deg") is not None and cone.get("rms_angle_deg") is not None:
                line[1] = (f"{_fmt(cone['angle_deg'], 3)}° along the worse axis, "
                           f"{_fmt(cone['rms_angle_deg'], 3)}° rms")
            after = [i for i, row in enumerate(body) if row[0].startswith("light.direction.")]
            body.insert(after[-1] + 1 if after else len(body), line)
        page.add(_table(["parameter", "sigma"], body))
        for w in (uncertainty.get("warnings", []) if isinstance(uncertainty, dict) else []):
            page.add(f"<p class='note'>{html.escape(str(w))}</p>")

    # 6. speed against error -------------------------------------------------------------------------------
    speed_plot = speed_plot if speed_plot is not None else speed_vs_error_png
    if speed_plot is not None and Path(speed_plot).is_file():
        data = Path(speed_plot).read_bytes()
        page.add("<h2>Speed against error (benchmark)</h2>")
        fig_html = page.png("speed_vs_error.png", data, "speed against error")
        page.add('<div class="row wide">' + fig_html + "</div>")

    page.add(f'<p class="muted">rtloop {html.escape(_native.__version__)} · images also in '
             f"<code>{html.escape(folder.name)}/</code></p></body></html>\n")

    written = {p.name for p in page.files}
    for old in folder.iterdir():
        if old.name not in written and _OURS.match(old.name) and old.is_file():
            old.unlink(missing_ok=True)
    write_bytes(page_path, "".join(page.parts).encode("utf-8"))
    return Report(path=page_path, files=page.files, metrics=metrics, plots=plots, strip=strip, truth=terr,
                  source=source, notes=notes)
