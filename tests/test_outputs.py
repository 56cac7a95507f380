"""The files a fit leaves (rtloop.cli.outputs): final.png sampled adaptively yet as close to a many-sample
render as the uniform one, and the snapshots rendered after the search, each distinct individual once."""

from __future__ import annotations

import copy
import types
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import rtloop
from rtloop import _native
from rtloop._srgb import encode8
from rtloop.cli import outputs
from rtloop.cli.outputs import GenerationLog, render_final

from conftest import BALL_ON_FLOOR

REPO = Path(__file__).resolve().parents[1]


def glossy_scene() -> rtloop.Scene:
    """The ball on its floor with a highlight and a dim ambient term: a bright, narrow lobe and soft ramps."""
    d = copy.deepcopy(BALL_ON_FLOOR)
    d["objects"][0]["material"].update(specular=0.3, shininess=40)
    d["ambient"] = [0.02, 0.02, 0.02]
    return rtloop.load_scene(d)


def code_errors(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per value, how many 8-bit sRGB steps ``image`` is off ``reference``."""
    return np.abs(encode8(image).astype(int) - encode8(reference).astype(int))


@pytest.mark.parametrize("scene_of, scale", [
    (lambda: rtloop.load_scene(REPO / "examples" / "yellow-ball" / "scene.json"), 2),
    (glossy_scene, 4),
])
def test_final_is_as_close_to_a_many_sample_render_as_the_uniform_one(scene_of, scale):
    """final.png (16 samples only where a pixel needs them) against a 256-sample uniform render: on
    average within 0.1 of an 8-bit step and at most 0.01 step worse than the uniform 16-sample render
    (measured: 0.051 and 0.055 against its 0.049 and 0.052), and at most 0.1 % more values off by over 2
    steps than it (measured: as many)."""
    scene = scene_of()
    size = (scene.width * scale, scene.height * scale)
    reference = rtloop.render(scene, *size, 256)
    uniform = code_errors(rtloop.render(scene, *size, 16), reference)
    final = code_errors(render_final(scene, scale, 16), reference)
    assert final.mean() < 0.1
    assert final.mean() <= uniform.mean() + 0.01
    assert (final > 2).mean() <= (uniform > 2).mean() + 0.001


def test_final_samples_only_pixels_at_edges_or_bends():
    """Away from the ball's outline and shadow, a pixel of final.png is its centre sample (the one-sample
    render's value), where the uniform render would have spent 16 samples."""
    scene = rtloop.load_scene(REPO / "examples" / "yellow-ball" / "scene.json")
    final = render_final(scene, 4, 16)
    centre = rtloop.render(scene, scene.width * 4, scene.height * 4, 1)
    same = np.all(final == centre, axis=2)
    assert same.mean() > 0.9  # the uniform render's: a few percent (pixels whose average is the centre)
    assert not same.all()  # the edges are supersampled
    assert render_final(scene, 1, 1).tobytes() == rtloop.render(scene, spp=1).tobytes()


def test_render_layers_refine_is_checked():
    scene = glossy_scene()
    with pytest.raises(ValueError, match="refine"):
        _native.render_layers([scene], 8, 6, 4, True, 0, None, "bends")


def info(stage: str, generation: int, params: list[float]) -> types.SimpleNamespace:
    return types.SimpleNamespace(stage=stage, generation=generation, evaluations=10 * generation,
                                 fitness=1.0 / (1 + generation), params=np.array(params))


def test_snapshots_are_rendered_after_the_search_each_individual_once(tmp_path, monkeypatch):
    """The callback renders nothing (the search waits for it); close() renders every distinct individual
    once, one sample per pixel, byte for byte rtloop.render's."""
    scene = glossy_scene()
    base = [float(v) for v in scene.get_params()]
    moved = [base[0] + 0.5, *base[1:]]
    for module, name in ((rtloop, "render"), (_native, "render_many"), (_native, "render")):
        monkeypatch.setattr(module, name, lambda *a, **k: pytest.fail("rendered in the callback"))
    log = GenerationLog(tmp_path, scene, 2)
    for g, params in enumerate([base, base, base, moved, moved]):
        log(info("light", g, params))
    assert list((tmp_path / "snapshots").iterdir()) == []
    monkeypatch.undo()
    log.close()
    names = sorted(p.name for p in (tmp_path / "snapshots").iterdir())
    assert names == ["light_gen0000.bmp", "light_gen0002.bmp", "light_gen0004.bmp"]
    for name, params in zip(names, [base, base, moved]):
        with Image.open(tmp_path / "snapshots" / name) as im:
            got = np.asarray(im.convert("RGB"))
        want = encode8(rtloop.render(scene.with_params(params), spp=1))
        assert np.array_equal(got, want)


def _render_passes(monkeypatch) -> list[int]:
    """Count the batch renders: the list gets the number of scenes of every pass from now on."""
    passes: list[int] = []
    real = _native.render_many
    monkeypatch.setattr(_native, "render_many", lambda scenes: passes.append(len(scenes)) or real(scenes))
    return passes


def test_snapshots_render_each_distinct_individual_once(tmp_path, monkeypatch):
    scene = glossy_scene()
    base = [float(v) for v in scene.get_params()]
    passes = _render_passes(monkeypatch)
    with GenerationLog(tmp_path, scene, 1) as log:
        for g in range(6):
            log(info("light", g, [base[0] + 0.1 * (g // 3), *base[1:]]))
    assert passes == [2]
    assert len(list((tmp_path / "snapshots").iterdir())) == 6


def test_snapshots_in_passes_of_bounded_size(tmp_path, monkeypatch):
    scene = glossy_scene()
    base = [float(v) for v in scene.get_params()]
    passes = _render_passes(monkeypatch)
    monkeypatch.setattr(outputs, "_SNAPSHOT_PIXELS", 2 * scene.width * scene.height)
    with GenerationLog(tmp_path, scene, 1) as log:
        for g in range(5):
            log(info("light", g, [base[0] + 0.1 * g, *base[1:]]))
    assert passes == [2, 2, 1]


def test_a_failed_search_writes_no_snapshots(tmp_path):
    scene = glossy_scene()
    base = [float(v) for v in scene.get_params()]
    with pytest.raises(RuntimeError), GenerationLog(tmp_path, scene, 1) as log:
        log(info("light", 0, base))
        raise RuntimeError("the search failed")
    assert list((tmp_path / "snapshots").iterdir()) == []
    assert (tmp_path / "best_per_generation.csv").read_text().count("\n") == 2
