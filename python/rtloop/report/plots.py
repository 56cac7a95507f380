"""The report's pictures: the search's rows (given, or rebuilt from the history), the parameter and
fitness plots with their data read back, and the image panels. matplotlib is imported only here, when
a report is made."""

from __future__ import annotations

import io
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _srgb as _srgb_codec
from ..fit.products import products_of
from ..scene import Scene

__all__ = ["GenerationRow", "plot_search"]

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


def _rows_given(result: Any, generations: Iterable[Any], names: list[str]) -> list[GenerationRow]:
    """The rows of ``generations``, each a full vector over ``names`` (the fitted scene's parameters): a
    callback's row holds the names of ``result.generation_names()``, without a lobe the fit freed itself,
    which keeps its fitted value. The block bootstrap's refits (stage ``"bootstrap R/N"``) are not the fit's
    search: left out."""
    from ..uncertainty.bootstrap import replicate_of
    n = len(names)
    short = result.generation_names() if hasattr(result, "generation_names") else names
    fill = np.asarray(result.scene.get_params(result.scene.fit_paths), float)
    where = [names.index(m) for m in short]
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
        if replicate_of(str(stage)) is not None:
            continue
        params = np.asarray(params, float).reshape(-1)
        if params.size == len(short) != n:
            full = fill.copy()
            full[where] = params
            params = full
        if params.size != n:
            raise ValueError(
                f"generations: row ({stage!r}, {gen}) has {params.size} parameter values; the scene has {n}"
                + (f" ({len(short)} without the lobes the fit freed)" if len(short) != n else "")
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
    split: Iterable[str] = (),
) -> tuple[list[tuple[str, Any]], dict[str, Any]]:
    """Parameter evolution (one panel per fit path, optionally the products per object) and the fitness
    (log y) against generation across stages: the one loss figure. A panel of parameters in ``split`` (the
    factors of a product the photo fixes, split by convention) says so in its title. Returns [(panel id,
    Figure)] and the plotted data read back from the figures (see :attr:`Report.plots`)."""
    from matplotlib.figure import Figure

    names = scene.param_names()
    xs, spans = _stage_axis(rows)
    P = np.array([r.params for r in rows], float).reshape(len(rows), len(names))
    figs: list[tuple[str, Any]] = []
    data: dict[str, Any] = {"_generation": {"x": xs, "rows": [(r.stage, r.generation) for r in rows]}}

    def new(title: str, ylabel: str = "") -> tuple[Any, Any]:
        fig = Figure(figsize=(5.2, 3.1))
        ax = fig.subplots()
        fig.subplots_adjust(left=0.12, right=0.98, bottom=0.15,
                            top=(0.88 if len(spans) > 1 else 0.9) - (0.08 if "\n" in title else 0.0))
        ax.set_title(title, fontsize=10, pad=13 if len(spans) > 1 else 6)
        ax.set_xlabel("generation (across stages)", fontsize=8)
        if ylabel:
            ax.set_ylabel(ylabel, fontsize=8)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.25)
        _stage_marks(ax, spans)
        return fig, ax

    split = set(split)
    for pid, title, members, colours in _panels_spec(scene, names):
        if any(m in split for m in members):
            title += "\n(a convention: the photo fixes only their product)"
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
