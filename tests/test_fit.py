"""End-to-end fits against ground truth the fit never saw, and the fit's contracts (determinism,
identifiability, logging, the fitness it optimises)."""

from __future__ import annotations

import functools
import importlib.util
import itertools
import json

import numpy as np
import pytest

import rtloop
from conftest import SHARED_SCENES, missing, scene_products, shared_case, shared_case_names, wrong_start
from rtloop import _native


def _score(result_dict: dict, truth_dict: dict) -> dict:
    spec = importlib.util.spec_from_file_location("score_result", SHARED_SCENES.parent / "tools" / "score_result.py")
    if spec is None or not (SHARED_SCENES.parent / "tools" / "score_result.py").is_file():
        missing("../shared/tools/score_result.py not found")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.score(result_dict, truth_dict)


def _photo(truth: dict, footprint: bool = True) -> np.ndarray:
    """What a camera would record of the scene: rtloop's render as the default fit models pixels (the
    pixel footprint; ``footprint=False``: at pixel centres, as the fitness evaluates by default), saturated
    at 1."""
    return np.minimum(rtloop.render(truth, footprint=footprint), 1.0)


def _assert_recovered(fitted: dict, truth: dict, light_tol: float, product_tol: float) -> None:
    """The fitted light within ``light_tol`` metres of the truth's, and every object's light x albedo within
    ``product_tol`` of the truth's (relative to its largest channel)."""
    err = np.linalg.norm(np.array(fitted["light"]["position"]) - truth["light"]["position"])
    assert err < light_tol, f"light position error {err:.5f} m"
    want, got = scene_products(truth), scene_products(fitted)
    for name in want:
        rel = np.max(np.abs(got[name] - want[name])) / np.max(want[name])
        assert rel < product_tol, f"{name}: product error {rel:.5f}"


def test_self_rendered_scene_is_recovered_from_awrong_start(ball_scene):
    truth = ball_scene
    photo = _photo(truth)
    result = rtloop.fit(wrong_start(truth), photo, seed=3)
    fitted = result.scene.to_dict()
    # The targets for noise-free scenes rendered by rtloop itself: 1 mm and 0.2 %.
    _assert_recovered(fitted, truth, 0.001, 0.002)
    # The reported products are the fitted scene's.
    got = scene_products(fitted)
    for name, p in result.products.items():
        np.testing.assert_allclose(p, got[name], rtol=1e-9)


def test_paper_protocol_two_stages_recover_the_light(ball_scene):
    truth = ball_scene
    photo = _photo(truth)
    result = rtloop.fit(wrong_start(truth), photo, protocol="paper", seed=1)
    assert [s.name for s in result.stages] == ["light", "colour"]
    assert result.stages[0].param_names == [
        "light.position.x", "light.position.y", "light.position.z", "light.intensity"]
    assert result.stages[1].loss == "l1_rgb" and len(result.stages[1].objectives) == 3
    # Every generation's best is logged, generation 0 included.
    assert [h[0] for h in result.stages[0].history] == list(range(201))
    fits = [h[1] for h in result.stages[0].history]
    assert all(b <= a + 1e-9 for a, b in itertools.pairwise(fits)), "the best fitness never gets worse"
    assert result.evaluations == 60 * 201 * 2
    # The paper's stage 2 (a Pareto search on a few pixels) recovers colours only roughly, as the paper
    # itself concludes; the default method is the one held to 1 %.
    _assert_recovered(result.scene.to_dict(), truth, 0.01, 0.05)


@pytest.mark.parametrize("protocol", ["rtloop", "paper"])
def test_same_seed_same_result_on_any_thread_count(ball_scene, protocol):
    truth = ball_scene
    truth["image"] = {"width": 32, "height": 24}
    photo = _photo(truth)
    runs = [
        rtloop.fit(wrong_start(truth), photo, protocol=protocol, seed=7, population=12, generations=15, threads=n)
        for n in (1, 2, 3)
    ]
    for r in runs[1:]:
        assert r.x == runs[0].x
        for a, b in zip(r.stages, runs[0].stages):
            assert [h[1] for h in a.history] == [h[1] for h in b.history]
    other = rtloop.fit(wrong_start(truth), photo, protocol=protocol, seed=8, population=12, generations=15)
    assert other.x != runs[0].x


def test_identifiability_is_detected_and_only_products_are_claimed(ball_scene):
    truth = ball_scene
    photo = _photo(truth)
    result = rtloop.fit(wrong_start(truth), photo, seed=2)
    ident = result.identifiability
    assert ident["degenerate"] is True
    assert any("light.intensity" in d and "objects.ball.albedo" in d for d in ident["determined"])
    # The documented resolution: the intensity stays at the scene's value (20) unless an albedo would
    # exceed 1; here the ball's red needs 56 W/sr, so the light is raised until that albedo is exactly 1.
    fitted = result.scene.to_dict()
    albedos = np.array([o["material"]["albedo"] for o in fitted["objects"]])
    assert albedos.max() == pytest.approx(1.0)
    assert fitted["light"]["intensity"] == pytest.approx(56.0, rel=0.01)
    report = result.report()
    json.dumps(report)  # JSON-able
    assert report["identifiability"]["degenerate"] is True


def test_ambient_light_makes_intensity_and_albedo_separable(ball_scene):
    scene = _native.Scene(json.dumps({**ball_scene, "ambient": [0.05, 0.05, 0.05]}))
    from rtloop.fit.identifiability import identifiability

    result_ident = identifiability(scene, scene.fit_paths)
    assert result_ident["degenerate"] is False


def _penalty(norm: str, d: np.ndarray) -> np.ndarray:
    """The per-pixel penalty of ``norm`` (l1, l2 or huber:0.01), written here from its definition."""
    if norm == "l1":
        return np.abs(d)
    if norm == "l2":
        return d * d
    h = 0.01
    return np.where(np.abs(d) <= h, 0.5 * d * d / h, np.abs(d) - 0.5 * h)


@pytest.mark.parametrize("norm", ["l1", "l2", "huber:0.01"])
def test_fitness_is_the_distance_of_the_rendered_image(ball_scene, norm):
    """The fused fitness equals rendering the candidate and summing penalty(min(render, 1) - objective)."""
    rng = np.random.default_rng(0)
    truth = ball_scene
    photo = np.clip(rtloop.render(truth) + rng.normal(0, 0.02, (48, 64, 3)).astype(np.float32), 0, 1)
    scene = rtloop.load_scene(truth)
    paths = scene.fit_paths
    bounds = np.array(scene.bounds(paths))
    pop = bounds[:, 0] + (bounds[:, 1] - bounds[:, 0]) * rng.random((8, len(bounds)))
    got = _native.evaluate(scene, photo, pop, _native.FitnessSpec(paths, norm=norm))[:, 0]

    for x, g in zip(pop, got):
        img = rtloop.render(scene.with_params(list(x)))
        want = _penalty(norm, (np.minimum(img, 1.0) - photo).astype(np.float64)).sum()
        assert g == pytest.approx(want, rel=1e-5)


@pytest.mark.parametrize("norm", ["l2", "huber"])
def test_other_norms_fit_too(ball_scene, norm):
    truth = ball_scene
    rng = np.random.default_rng(11)
    photo = np.clip(_photo(truth) + rng.normal(0, 0.01, (48, 64, 3)), 0, 1).astype(np.float32)
    result = rtloop.fit(wrong_start(truth), photo, seed=1, norm=norm)
    assert result.settings["norm"] == norm
    err = np.linalg.norm(np.array(result.scene.to_dict()["light"]["position"]) - truth["light"]["position"])
    assert err < 0.05
    with pytest.raises(rtloop.RtloopError, match="norm"):
        rtloop.fit(truth, photo, norm="l3")


def _srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB encoding of IEC 61966-2-1, in float64 (also above 1)."""
    x = np.asarray(x, np.float64)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.abs(x) ** (1 / 2.4) - 0.055)


@pytest.mark.parametrize("clip", [True, False])
@pytest.mark.parametrize("norm", ["l1", "l2", "huber:0.01"])
def test_srgb_fitness_is_the_distance_of_the_encoded_images(ball_scene, norm, clip):
    """With space="srgb" the fitness is Σ penalty(enc(min(render, 1)) - enc(objective)), plain and projected
    (the kernel encodes through a table good to 2e-5, so the sums agree to about that per pixel)."""
    rng = np.random.default_rng(1)
    truth = ball_scene
    photo = np.clip(rtloop.render(truth) + rng.normal(0, 0.02, (48, 64, 3)), 0, 1).astype(np.float32)
    scene = rtloop.load_scene(truth)
    paths = scene.fit_paths
    bounds = np.array(scene.bounds(paths))
    pop = bounds[:, 0] + (bounds[:, 1] - bounds[:, 0]) * rng.random((6, len(bounds)))
    srgb = _native.FitnessSpec(paths, norm=norm, space="srgb", clip=clip)
    got = _native.evaluate(scene, photo, pop, srgb)[:, 0]
    linear = _native.evaluate(scene, photo, pop, _native.FitnessSpec(paths, norm=norm, clip=clip))[:, 0]

    for x, g, lin in zip(pop, got, linear):
        img = rtloop.render(scene.with_params(list(x)))
        model = np.minimum(img, 1.0) if clip else img
        want = _penalty(norm, _srgb(model) - _srgb(photo)).sum()
        assert g == pytest.approx(want, rel=1e-4, abs=1e-4 * photo.size)
        assert g != pytest.approx(lin, rel=1e-2)
    # The projected loss: the same encoded distance at its (linear least-squares) products.
    from rtloop.fit import _product_bounds
    start = rtloop.load_scene(wrong_start(truth))
    pb = _product_bounds(start)
    for light in ([1.0, 5.0, -2.0], [2.5, 4.5, -1.0]):
        spec = _native.FitnessSpec(["light.position"], loss="l1_projected", product_bounds=pb, norm=norm,
                                   space="srgb", clip=clip)
        proj = _native.evaluate(start, photo, np.array([light]), spec)[0, 0]
        d = start.to_dict()
        d["light"]["position"], d["light"]["intensity"], d["fit"] = light, 1.0, {}
        for o, p in zip(d["objects"], _solve_products(start, photo, light, pb, clip=clip)):
            o["material"]["albedo"] = list(p)
        img = rtloop.render(d)
        model = np.minimum(img, 1.0) if clip else img
        want = _penalty(norm, _srgb(model) - _srgb(photo)).sum()
        assert proj == pytest.approx(want, rel=1e-4, abs=1e-4 * photo.size)


def test_srgb_space_recovers_a_self_rendered_scene(ball_scene):
    """Noise-free and rendered by rtloop: the sRGB-space loss is held to the same 1 mm and 0.2 % targets."""
    truth = ball_scene
    result = rtloop.fit(wrong_start(truth), _photo(truth), seed=3, space="srgb")
    assert result.settings["space"] == "srgb" and result.settings["method"] == "projected"
    _assert_recovered(result.scene.to_dict(), truth, 0.001, 0.002)
    # The paper's two stages take the space too (and, asked for, the footprint the photo was rendered with).
    paper = rtloop.fit(wrong_start(truth), _photo(truth), protocol="paper", seed=1, generations=(60, 60),
                       space="srgb", footprint="on")
    assert [s.loss for s in paper.stages] == ["l1", "l1_rgb"] and paper.settings["space"] == "srgb"
    err = np.linalg.norm(np.array(paper.scene.to_dict()["light"]["position"]) - truth["light"]["position"])
    assert err < 0.05
    assert result.report()["settings"]["space"] == "srgb"
    with pytest.raises(rtloop.RtloopError, match="space: unknown loss space 'sRGB'"):
        rtloop.fit(truth, _photo(truth), space="sRGB")
    with pytest.raises(rtloop.RtloopError, match="^space: "):
        _native.FitnessSpec(["light.position"], space="gamma")


def test_optimize_from_a_start_holds_it_and_names_a_bad_one(ball_scene):
    """``x0``: the first member of L-SHADE's initial population, so a search too small to find the light
    alone (4 members, no generation, no polish) ends at the true light when it starts there, and at no
    worse a loss; a start of the wrong length, not finite, or for the paper's DE is refused, naming x0."""
    from rtloop.fit import _product_bounds
    truth = ball_scene
    photo = _photo(truth, footprint=False)
    scene = rtloop.load_scene(wrong_start(truth))
    true_light = list(truth["light"]["position"])
    spec = _native.FitnessSpec(["light.position"], loss="l1_projected", product_bounds=_product_bounds(scene))
    kw = dict(population=4, generations=0, seed=0, method="lshade")
    alone = _native.optimize(scene, photo, spec, **kw)
    held = _native.optimize(scene, photo, spec, x0=true_light, **kw)
    assert np.linalg.norm(np.subtract(alone.x, true_light)) > 0.05
    np.testing.assert_allclose(held.x, true_light, rtol=0, atol=1e-12)
    assert sum(held.objectives) < sum(alone.objectives)
    for bad in ([1.0, 2.0], [1.0, float("nan"), 0.0]):
        with pytest.raises(rtloop.RtloopError, match="x0: needs 3 finite values"):
            _native.optimize(scene, photo, spec, x0=bad, **kw)
    with pytest.raises(rtloop.RtloopError, match="lshade"):
        _native.optimize(scene, photo, spec, x0=true_light, **{**kw, "method": "de"})


def test_projected_fitness_equals_l1_at_the_solved_products(ball_scene):
    """Variable projection: the closed-form loss is the plain L1 loss of the scene with the solved products."""
    truth = ball_scene
    photo = _photo(truth, footprint=False)
    scene = rtloop.load_scene(wrong_start(truth))
    from rtloop.fit import _product_bounds
    pb = _product_bounds(scene)
    spec = _native.FitnessSpec(["light.position"], loss="l1_projected", product_bounds=pb)
    for light in ([1.0, 5.0, -2.0], [-3.0, 2.0, 1.0], [2.5, 4.5, -1.0]):
        out = _native.optimize(scene, photo, spec, population=4, generations=0, seed=0)
        assert out.generations == 0
        proj = _native.evaluate(scene, photo, np.array([light]), spec)[0, 0]
        # Re-render with intensity 1 and albedo = product: the same image, the same L1.
        d = scene.to_dict()
        d["light"]["position"] = light
        d["light"]["intensity"] = 1.0
        products = _solve_products(scene, photo, light, pb)
        for o, p in zip(d["objects"], products):
            o["material"]["albedo"] = list(p)
        d["fit"] = {}
        img = rtloop.render(d)
        assert proj == pytest.approx(np.abs(np.minimum(img, 1) - photo).sum(), rel=1e-4, abs=1e-3)
    # At the truth the loss vanishes.
    at_truth = _native.evaluate(scene, photo, np.array([truth["light"]["position"]]), spec)[0, 0]
    assert at_truth < 1e-3


def _solve_products(scene, photo, light, pb, clip=True):
    """Independent NumPy least squares of the products for a given light (the reference for the Rust solve):
    interior pixels only (a silhouette pixel mixes two surfaces in a photo), unsaturated ones only (all
    without ``clip``)."""
    d = scene.to_dict()
    d["light"]["position"] = light
    d["light"]["intensity"] = 1.0
    for o in d["objects"]:
        o["material"]["albedo"] = [1.0, 1.0, 1.0]
    d["fit"] = {}
    g = rtloop.render(d)[..., 0]
    ids = rtloop.object_ids(d)
    pad = np.pad(ids, 1, mode="edge")
    interior = ((pad[1:-1, :-2] == ids) & (pad[1:-1, 2:] == ids) & (pad[:-2, 1:-1] == ids)
                & (pad[2:, 1:-1] == ids))
    out = []
    for k in range(len(d["objects"])):
        p = []
        for c in range(3):
            m = (ids == k) & interior & (g > 0) & ((photo[..., c] < 0.999) | (not clip))
            assert (g[m] ** 2).sum() > 0, "these scenes always have lit interior pixels"
            v = (photo[..., c][m] * g[m]).sum() / (g[m] ** 2).sum()
            p.append(float(np.clip(v, pb[k, c, 0], pb[k, c, 1])))
        out.append(p)
    return out


def test_callback_sees_every_generation_and_can_stop(ball_scene):
    truth = ball_scene
    truth["image"] = {"width": 32, "height": 24}
    photo = _photo(truth)
    seen = []

    def cb(info):
        seen.append((info.stage, info.generation, info.fitness, info.params.copy()))
        return info.generation < 4

    result = rtloop.fit(wrong_start(truth), photo, protocol="paper", population=8, generations=10, callback=cb)
    assert [g for s, g, *_ in seen if s == "light"] == [0, 1, 2, 3, 4]
    assert result.stages[0].generations == 4
    names = rtloop.load_scene(truth).param_names()
    assert all(len(p) == len(names) for *_, p in seen)


def test_callback_exception_propagates(ball_scene):
    truth = ball_scene
    truth["image"] = {"width": 16, "height": 12}

    def boom(info):
        raise KeyError("from the callback")

    with pytest.raises(KeyError, match="from the callback"):
        rtloop.fit(truth, _photo(truth), population=6, generations=3, callback=boom)


@pytest.mark.parametrize("bad, match", [
    (np.zeros((10, 10, 3), np.float32), "shape"),
    (np.full((48, 64, 3), np.nan, np.float32), "NaN"),
])
def test_bad_objective_arrays_are_clear_errors(ball_scene, bad, match):
    with pytest.raises(rtloop.RtloopError, match=match):
        rtloop.fit(ball_scene, bad)


def test_bad_options_are_clear_errors(ball_scene):
    photo = _photo(ball_scene)
    with pytest.raises(rtloop.RtloopError, match="protocol"):
        rtloop.fit(ball_scene, photo, protocol="fast")
    with pytest.raises(rtloop.RtloopError, match="population"):
        rtloop.fit(ball_scene, photo, population=2)
    no_fit = {**ball_scene, "fit": {}}
    with pytest.raises(rtloop.RtloopError, match="fit"):
        rtloop.fit(no_fit, photo)


@functools.cache
def _fit_reference_case(case: str) -> dict:
    path = shared_case(case)
    scene = rtloop.load_scene(path / "scene_input.json")
    photo = rtloop.load_image(path / "objective.png", scene)
    result = rtloop.fit(scene, photo, seed=0)
    truth = json.loads((path / "scene.json").read_text())
    return _score(result.scene.to_dict(), truth)


@pytest.mark.parametrize("case", shared_case_names())
def test_reference_scenes_light_within_2cm(case):
    """Scenes rendered by Mitsuba 3: the fit never saw scene.json. Each light within 2 cm and every colour
    product within 1 % (the noisy scene is the worst: about 13 mm and 0.7 %)."""
    s = _fit_reference_case(case)
    assert s["light_err_m"] < 0.02, s
    assert max(s["product_rel_err"].values()) < 0.01, s


def test_reference_scenes_median_targets():
    """The docs' figure for the default over the Mitsuba scenes, 4.0 mm and 0.15 % (medians of the light
    error and of each scene's worst product; benches/speed_vs_error.py over three seeds), held here on one
    seed with half again as margin: 6 mm and 0.25 %."""
    names = shared_case_names()
    if not SHARED_SCENES.is_dir():
        missing(f"{SHARED_SCENES} not found: the reference scenes live in ../shared/scenes beside the repo")
    scores = [_fit_reference_case(n) for n in names]
    assert np.median([s["light_err_m"] for s in scores]) < 0.006, scores
    assert np.median([max(s["product_rel_err"].values()) for s in scores]) < 0.0025, scores


def test_mask_leaves_out_what_the_scene_does_not_model(ball_scene, tmp_path):
    """A bright patch the scene cannot make (a reflection, another object) biases an unmasked fit; masked
    out, the fit is as good as on the clean photo."""
    truth = ball_scene
    photo = _photo(truth)
    damaged = photo.copy()
    damaged[30:44, 2:20] = 0.9  # a bright rectangle on the floor, left of the ball
    mask_img = np.ones((48, 64, 3), np.float32)
    mask_img[28:46, 0:22] = 0.0
    rtloop.save_image(tmp_path / "mask.png", mask_img)
    mask = rtloop.load_mask(tmp_path / "mask.png", rtloop.load_scene(truth))
    assert mask.shape == (48, 64) and mask.dtype == bool
    assert not mask[30:44, 2:20].any() and mask[:20].all()

    def light_err(r):
        return np.linalg.norm(np.array(r.scene.to_dict()["light"]["position"]) - truth["light"]["position"])

    unmasked = rtloop.fit(wrong_start(truth), damaged, seed=4)
    masked = rtloop.fit(wrong_start(truth), damaged, seed=4, mask=mask)
    assert light_err(masked) < 0.01
    assert light_err(unmasked) > 3 * light_err(masked)
    assert masked.settings["masked_pixels"] == int((~mask).sum())
    for name in ("ball", "floor"):
        want = scene_products(truth)[name]
        got = np.array(masked.products[name])
        assert np.max(np.abs(got - want)) / np.max(want) < 0.01
    with pytest.raises(rtloop.RtloopError, match="mask"):
        rtloop.fit(truth, photo, mask=np.zeros((48, 64), bool))
    with pytest.raises(rtloop.RtloopError, match="mask"):
        rtloop.fit(truth, photo, mask=np.ones((10, 10), bool))
    rtloop.save_image(tmp_path / "black.png", np.zeros((48, 64, 3), np.float32))
    with pytest.raises(rtloop.AcquisitionError, match="black.png"):
        rtloop.load_mask(tmp_path / "black.png", rtloop.load_scene(truth))
