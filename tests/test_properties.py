"""Property tests (Hypothesis): mutated scenes, fit() arguments and image arrays either work or raise
an RtloopError; what works renders finite pixels and fits inside the scene's bounds. Bounded and derandomised so
CI runs the same few hundred cases every time."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import rtloop
from conftest import BALL_ON_FLOOR

SMALL = copy.deepcopy(BALL_ON_FLOOR)
SMALL["image"] = {"width": 16, "height": 12}
PHOTO = rtloop.render(SMALL)

PROPS = settings(max_examples=150, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.too_slow])

#: Numbers an adversary would write: ordinary, zero, negative, tiny, huge, non-finite.
NUMBERS = st.one_of(
    st.floats(-10, 10), st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e8, 1.0000001e8, 1e20, 1e300, -1e300]),
    st.sampled_from([math.nan, math.inf, -math.inf]), st.floats(allow_nan=True, allow_infinity=True),
)

#: (where, how many numbers) of every numeric field of SMALL and its fit section.
FIELDS = [
    (("camera", "position"), 3), (("camera", "look_at"), 3), (("camera", "up"), 3), (("camera", "vfov_deg"), 0),
    (("light", "position"), 3), (("light", "intensity"), 0), (("light", "color"), 3),
    (("objects", 0, "center"), 3), (("objects", 0, "radius"), 0), (("objects", 0, "material", "albedo"), 3),
    (("objects", 1, "point"), 3), (("objects", 1, "normal"), 3), (("ambient",), 3), (("exposure",), 0),
    (("fit", "light.position", "min"), 3), (("fit", "light.position", "max"), 3),
    (("fit", "light.intensity", "min"), 0), (("fit", "light.intensity", "max"), 0),
    (("fit", "objects.ball.albedo", "max"), 3),
]


@st.composite
def mutated(draw, base: dict, fields: list) -> dict:
    """`base` with one to three of its numeric `fields` replaced by random numbers (NaN, inf and huge included)."""
    d = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        where, n = draw(st.sampled_from(fields))
        node = d
        for k in where[:-1]:
            node = node[k]
        node[where[-1]] = draw(NUMBERS) if n == 0 else draw(st.lists(NUMBERS, min_size=n, max_size=n))
    return d


def mutated_scenes():
    return mutated(SMALL, FIELDS)


COATED = copy.deepcopy(SMALL)
COATED["objects"][0]["material"] = {**COATED["objects"][0]["material"], "coat": {"roughness": 0.2, "ior": 1.5}}
COATED["fit"]["objects.ball.roughness"] = {"min": 0.05, "max": 0.5}
COAT_VALUES = st.one_of(NUMBERS, st.sampled_from([None, "x", [], {}, [0.1], True]))


@st.composite
def mutated_coats(draw) -> dict:
    """COATED with its coat's fields, the roughness's bounds or the coat itself replaced or deleted."""
    d = copy.deepcopy(COATED)
    coat = d["objects"][0]["material"]["coat"]
    for _ in range(draw(st.integers(1, 3))):
        which = draw(st.sampled_from(["roughness", "ior", "extra", "coat", "min", "max", "drop"]))
        if which in ("roughness", "ior", "extra"):
            coat[which] = draw(COAT_VALUES)
        elif which == "coat":
            d["objects"][0]["material"]["coat"] = draw(COAT_VALUES)
        elif which == "drop":
            coat.pop(draw(st.sampled_from(["roughness", "ior"])), None)
        else:
            d["fit"]["objects.ball.roughness"][which] = draw(COAT_VALUES)
    return d


def _loaded_or_one_line(d: dict, *names: str):
    """The scene ``d`` loaded, or None after checking its SceneError is one line naming one of ``names`` (any
    field: a non-empty first part before a colon)."""
    try:
        return rtloop.load_scene(d)
    except rtloop.SceneError as e:
        msg = str(e)
        assert "\n" not in msg and (any(n in msg for n in names) if names else msg.split(":")[0]), msg
        return None


@PROPS
@given(mutated_coats())
def test_a_mutated_coat_loads_and_renders_finite_or_is_one_line_naming_it(d):
    scene = _loaded_or_one_line(d, "coat", "roughness")
    if scene is None:
        return
    img = rtloop.render(scene, 8, 6)
    assert np.isfinite(img).all() and (img >= 0).all()


@PROPS
@given(mutated_scenes())
def test_a_mutated_scene_loads_and_renders_finite_or_is_a_scene_error(d):
    try:
        scene = rtloop.load_scene(d)
    except rtloop.SceneError:
        return
    img = rtloop.render(scene, 8, 6)
    assert np.isfinite(img).all()
    assert (rtloop.object_ids(scene, 8, 6) >= -1).all()


def _argument(valid, invalid):
    """Valid four times in five: most drawn fits then run, and each run meets a few invalid arguments."""
    return st.one_of(valid, valid, valid, valid, invalid)


ARGS = st.fixed_dictionaries({}, optional={
    "seed": _argument(st.integers(0, 2**64 - 1), st.one_of(st.integers(max_value=-1), st.integers(2**64),
                                                           st.floats(), st.text(max_size=2))),
    "threads": _argument(st.integers(1, 4), st.one_of(st.integers(max_value=0), st.integers(2**20), st.floats())),
    "population": _argument(st.integers(4, 8), st.one_of(st.integers(max_value=3), st.integers(10**5 + 1),
                                                         st.booleans())),
    "generations": _argument(st.one_of(st.integers(0, 2), st.tuples(st.integers(0, 2), st.integers(0, 2))),
                             st.one_of(st.integers(max_value=-1), st.tuples(st.integers(0, 2)),
                                       st.lists(st.integers(0, 2), min_size=3, max_size=3), st.floats())),
    "f": _argument(st.floats(0.01, 2.0), st.one_of(st.floats(max_value=0.0), st.floats(min_value=2.0001),
                                                   st.just(math.nan))),
    "cr": _argument(st.floats(0.0, 1.0), st.one_of(st.floats(max_value=-1e-9), st.floats(min_value=1.0001),
                                                   st.just(math.nan))),
    "polish": _argument(st.integers(0, 20), st.one_of(st.integers(max_value=-1), st.integers(10**6 + 1))),
    "protocol": _argument(st.sampled_from(["rtloop", "paper"]), st.just("fast")),
    "norm": _argument(st.sampled_from(["auto", "l1", "l2", "huber", "huber:0.1"]),
                      st.sampled_from(["huber:-1", "huber:nan", "huber:", "AUTO", "bogus", None, 2])),
    "framing": _argument(st.sampled_from(["check", "correct", "off"]), st.sampled_from(["CHECK", "on", None, 1, True])),
    "vignetting": _argument(st.one_of(st.sampled_from(["auto", "on", "off"]),
                                      st.tuples(st.floats(-0.6, 0.2), st.floats(-0.3, 0.1))),
                            st.one_of(st.sampled_from(["x", None, 1.0, (1.0,), "0.1,0.2"]),
                                      st.tuples(NUMBERS, NUMBERS))),
    "tone": _argument(st.sampled_from(["auto", "on", "off", "linear"]), st.sampled_from(["srgb", None, 1, "ON"])),
    "flat_field": _argument(
        st.builds(lambda a, b: np.clip(np.full((12, 16, 3), a, np.float32) - b * np.linspace(
            0, 1, 16, dtype=np.float32)[None, :, None], 1e-3, None), st.floats(0.05, 0.95), st.floats(0, 0.04)),
        st.sampled_from([np.zeros((12, 16), np.float32), np.ones((12, 16), np.float32),
                         np.full((12, 16, 3), np.nan, np.float32), np.ones((16, 12), np.float32),
                         np.ones((12, 16), np.uint8), "flat.png"])),
})

#: SMALL's photo with noise of a 16-bit camera's size (a few steps) and a misfit everywhere (its albedo 1.5x
#: in a gradient): the residual the automatic norm takes as dense, so that its L2 refit runs too.
NOISY = np.clip(PHOTO * np.linspace(1.0, 1.5, PHOTO.shape[1], dtype=np.float32)[None, :, None]
                + np.random.default_rng(5).normal(0, 20 / 65535, PHOTO.shape), 0, None).astype(np.float32)


@PROPS
@given(ARGS, st.booleans())
def test_fit_arguments_work_or_raise_rtloop_error(kw, noisy):
    kw.setdefault("generations", 1)
    kw.setdefault("population", 4)
    kw.setdefault("polish", 5)
    try:
        with _quiet():
            result = rtloop.fit(SMALL, NOISY if noisy else PHOTO, uncertainty=False, **kw)
    except rtloop.RtloopError:
        return
    s = result.scene
    for v, (lo, hi) in zip(s.get_params(), s.bounds()):
        assert lo <= v <= hi
    assert all(math.isfinite(v) for row in result.products.values() for v in row)


@PROPS
@given(st.sampled_from(["float32", "float64", "float16", "uint8", "uint16", "int64", "bool", "complex64"]),
       st.sampled_from([(12, 16, 3), (12, 16), (12, 16, 4), (16, 12, 3), (0, 0, 3)]),
       st.sampled_from([0.0, 1.0, -1.0, 300.0, math.nan, math.inf]))
def test_image_arrays_work_or_raise_rtloop_error(dtype, shape, fill):
    with np.errstate(invalid="ignore"):
        image = np.full(shape, 0.5, dtype=np.float64)
        if image.size:
            image.flat[0] = fill
        image = image.astype(dtype)
    try:
        with _quiet():
            result = rtloop.fit(SMALL, image, generations=1, population=4, polish=2, uncertainty=False)
    except rtloop.RtloopError:
        return
    assert np.dtype(dtype).kind == "f" and shape == (12, 16, 3) and math.isfinite(fill)
    assert all(math.isfinite(v) for v in result.x.values())


class _quiet:
    """RtloopWarnings (doubted inputs) are expected here."""

    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", rtloop.RtloopWarning)

    def __exit__(self, *exc):
        return self._w.__exit__(*exc)


# --- batch job lines ---------------------------------------------------------------------------------------

#: JSON values an adversary would put in a job line's field.
JSON_VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(), st.integers(10**20, 10**40), st.floats(), st.text(max_size=8),
              st.sampled_from(["auto", "on", "off", "silhouette", "srgb", "linear", "paper", "rtloop", "l2",
                               "bootstrap"])),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=6,
)
JOB_IDS = st.one_of(st.sampled_from(["a", "b-1", "keep", "results.jsonl", "../out", "/tmp", ".hidden", "", "a/b",
                                     "..", "x" * 129, "ok.1"]), st.integers(-5, 5), st.text(max_size=6), JSON_VALUES)
BATCH_FIELDS = ["seed", "mask", "protocol", "population", "generations", "f", "cr", "norm", "space", "loss_space",
                "optimizer", "polish", "clip", "uncertainty", "pixels_per_object", "environment",
                "interreflection", "highlights", "footprint", "framing", "vignetting", "tone", "lights", "response", "crop",
                "grey_card", "image", "bogus"]


@st.composite
def job_lines(draw) -> str:
    """One line of a JOBS file: mostly an object with the fields a job has, sometimes odd JSON or not JSON."""
    kind = draw(st.integers(0, 9))
    if kind == 0:
        return draw(st.sampled_from(["[" * 5000 + "]" * 5000, '{"id": "a", "id": "b"}', "{", "null", "[]",
                                     '{"id": "a", "seed": 1' + "0" * 5000 + "}", "# a comment", "   "]))
    d: dict = {}
    if draw(st.integers(0, 9)):
        d["id"] = draw(JOB_IDS)
    for key, good in (("scene", "scene.json"), ("photo", "photo.png")):
        if draw(st.integers(0, 9)):
            d[key] = good if draw(st.booleans()) else draw(st.one_of(JSON_VALUES, st.just("missing.png")))
    for key in draw(st.lists(st.sampled_from(BATCH_FIELDS), max_size=3, unique=True)):
        d[key] = draw(JSON_VALUES)
    return json.dumps(d)


def _tree(root) -> dict:
    return {str(p.relative_to(root)): p.read_bytes() if p.is_file() else None for p in sorted(root.rglob("*"))}


@PROPS
@given(st.lists(job_lines(), min_size=1, max_size=3))
def test_random_job_lines_are_fitted_or_one_line_and_touch_only_the_batch_files(lines):
    import contextlib
    import io
    import tempfile
    from pathlib import Path

    from rtloop.cli import batch as batch_cli

    with tempfile.TemporaryDirectory() as td:
        root = Path(td)
        (root / "scene.json").write_text(json.dumps(SMALL))
        rtloop.save_image(root / "photo.png", PHOTO)
        out = root / "out"
        (out / "keep").mkdir(parents=True)
        (out / "keep" / "notes.txt").write_text("keep me")
        (root / "jobs.jsonl").write_text("\n".join(lines) + "\n")
        before = _tree(root)
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), _quiet():
            code = batch_cli.main(["--batch", str(root / "jobs.jsonl"), "--out", str(out), "--no-images", "-q",
                                   "--generations", "1", "--population", "4", "--no-uncertainty"])
        assert code in (0, 1)
        assert len(err.getvalue().splitlines()) <= 1 and "Traceback" not in err.getvalue()
        after = _tree(root)
        for name, data in before.items():  # nothing there before is changed or gone
            assert after.get(name, "gone") == data, name
        for name in set(after) - set(before):  # what is new is inside the output folder
            assert name.startswith("out/"), name


# --- mesh files, EXIF tags, insertion arguments ------------------------------------------------------------

PLY_HEADS = st.sampled_from([
    "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
    "element face {m}\nproperty list uchar int vertex_indices\nend_header\n",
    "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty double x\nproperty double y\n"
    "property double z\nelement face {m}\nproperty list uint int vertex_indices\nend_header\n",
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 {m}\n", "",
])
COUNTS = st.sampled_from([0, 1, 3, 255, 2**31 - 1, 2**32, 10**12, -1])


def _mesh_scene(path) -> dict:
    scene = copy.deepcopy(SMALL)
    scene["objects"].append({"name": "m", "shape": "mesh", "file": str(path), "position": [0, 0.5, 0], "scale": 0.2})
    return scene


@settings(max_examples=200, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(head=PLY_HEADS, n=COUNTS, m=COUNTS, body=st.binary(max_size=300), ext=st.sampled_from(["ply", "obj"]))
def test_mesh_files_load_or_are_refused_in_one_line(tmp_path_factory, head, n, m, body, ext):
    path = tmp_path_factory.mktemp("mesh") / f"m.{ext}"
    path.write_bytes(head.format(n=n, m=m).encode() + body)
    try:
        rtloop.load_scene(_mesh_scene(path))
    except rtloop.SceneError as e:
        assert "\n" not in str(e) and str(e).startswith("objects[2].file: ")


EXIF_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-2**31, 2**32),
                        st.sampled_from([0, 1e-9, 1e9, (1, 0), (0, 0), "x", b"\x00"]))


@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(tags=st.dictionaries(st.sampled_from([0x920A, 0xA405, 0xA20E, 0xA210]), EXIF_VALUES, max_size=4),
       orientation=st.integers(-1, 10), size=st.tuples(st.integers(1, 64), st.integers(1, 64)))
def test_exif_focal_lengths_are_positive_finite_or_absent(tmp_path_factory, tags, orientation, size):
    import warnings

    from PIL import Image

    from rtloop.acquisition.exif import exif_focal

    path = tmp_path_factory.mktemp("exif") / "p.jpg"
    exif = Image.Exif()
    exif[0x0112] = orientation
    try:
        exif.get_ifd(0x8769).update(tags)
        Image.new("RGB", size).save(path, exif=exif)
    except Exception:  # noqa: BLE001 - a value Pillow cannot write: nothing to read back
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        found = exif_focal(path, *size)
    assert found is None or (math.isfinite(found.focal_px) and found.focal_px > 0)


INSERT_FLAGS = st.lists(st.tuples(st.sampled_from(["--spp", "--response", "--out", "--force", "--uniform"]),
                                  st.sampled_from(["1", "0", "-3", "4097", "x", "srgb", "linear", ".", "..", "out",
                                                   "photo.png", "sub/deep", ""])), max_size=3)


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(flags=INSERT_FLAGS)
def test_insertion_arguments_exit_cleanly_and_write_only_into_out(tmp_path_factory, flags):
    import json
    import os

    from rtloop.cli.insert import insert_main

    work = tmp_path_factory.mktemp("insert")
    (work / "scene.json").write_text(json.dumps(SMALL))
    rtloop.save_image(work / "photo.png", PHOTO)
    (work / "objects.json").write_text(json.dumps([{"name": "b2", "shape": "sphere", "center": [0.3, 0.2, 0],
                                                    "radius": 0.2}]))
    before = {p: p.stat().st_mtime_ns for p in work.iterdir()}
    argv = ["scene.json", "photo.png", "--add", "objects.json", "--out", "out"]
    for flag, value in flags:
        argv += [flag] if flag in ("--force", "--uniform") else [flag, value]
    cwd = os.getcwd()
    os.chdir(work)
    try:
        code, _ = _fuzz().run_quietly(insert_main, argv)
    finally:
        os.chdir(cwd)
    assert code in (0, 1, 2)
    assert all(p.exists() and p.stat().st_mtime_ns == t for p, t in before.items())  # inputs untouched
    outs = {a for f, a in flags if f == "--out"} or {"out"}
    made = {p.name for p in work.iterdir()} - {p.name for p in before} - {o.split("/")[0] for o in outs}
    assert not made, made


# --- rtloop-scene --strict: the field of view estimated from the board alone ------------------------------

STRICT_VIEWS = st.fixed_dictionaries({
    "tilt_deg": st.sampled_from([0.0, 0.5, 2.0]) | st.floats(0.0, 70.0),
    "distance": st.floats(0.2, 8.0),
    "vfov_deg": st.floats(10.0, 100.0),
    "noise_px": st.sampled_from([0.0, 0.05, 0.3, 1.0]) | st.floats(0.0, 5.0),
    "keep": st.integers(3, 24),
    "seed": st.integers(0, 2**16),
})


@settings(max_examples=200, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(view=STRICT_VIEWS)
def test_strict_passes_only_a_field_of_view_within_the_target_and_refuses_in_one_line(view):
    """A board's corners seen by a camera of any field of view, tilt (0: head-on), distance and corner noise,
    some corners missing: the estimate without EXIF is either used or refused in one line that names the fixes.
    With --strict it passes only a spread within the 0.3 deg target, and then the same estimate as without;
    whatever is refused without --strict is refused with it."""
    import cv2

    from rtloop.acquisition import AcquisitionError
    from rtloop.acquisition.boards import BoardDetection
    from rtloop.acquisition.camera import centred_camera_matrix, focal_from_vfov
    from rtloop.acquisition.pose import VFOV_LIMIT_DEG, VFOV_TARGET_DEG, estimate_focal_from_board

    w, h = 800, 600
    gx, gy = np.meshgrid(np.arange(6), np.arange(4))
    obj = np.column_stack([gx.ravel() - 2.5, gy.ravel() - 1.5, np.zeros(gx.size)]) * 0.06
    rng = np.random.default_rng(view["seed"])
    keep = np.sort(rng.choice(len(obj), size=view["keep"], replace=False))
    tilt = math.radians(view["tilt_deg"])
    rvec = np.array([tilt, 0.0, 0.0])
    tvec = np.array([0.0, 0.0, view["distance"]])
    k = centred_camera_matrix(focal_from_vfov(view["vfov_deg"], h), w, h)
    img, _ = cv2.projectPoints(obj[keep], rvec, tvec, k, np.zeros(5))
    img = img.reshape(-1, 2) + rng.normal(0.0, view["noise_px"], (len(keep), 2))
    detection = BoardDetection(img.astype(np.float32), obj[keep].astype(np.float32), keep)
    outcome = {}
    for strict in (False, True):
        try:
            outcome[strict] = estimate_focal_from_board(detection, w, h, strict=strict)
        except AcquisitionError as e:
            message = str(e)
            assert "\n" not in message and "--vfov" in message and "EXIF" in message
            outcome[strict] = message
    loose, strict = outcome[False], outcome[True]
    event(f"strict: {'used' if isinstance(strict, tuple) else 'refused'}; "
          f"without: {'used' if isinstance(loose, tuple) else 'refused'}")
    if isinstance(strict, tuple):
        f, std = strict
        assert math.isfinite(f) and f > 0 and 0 <= std <= VFOV_TARGET_DEG
        assert strict == loose
    elif "does not fix the focal length" in strict:
        assert f"{VFOV_TARGET_DEG:g} deg needed with --strict" in strict
    if isinstance(loose, tuple):
        assert math.isfinite(loose[0]) and loose[0] > 0 and 0 <= loose[1] <= VFOV_LIMIT_DEG and math.isfinite(loose[1])
    else:
        assert isinstance(strict, str)


_BOARD_PHOTO: dict = {}


def _fuzz():
    """fuzz/fuzz.py, the fuzz campaign, whose board photo and quiet command runner these tests share."""
    import sys
    from pathlib import Path

    folder = str(Path(__file__).resolve().parents[1] / "fuzz")
    if folder not in sys.path:
        sys.path.insert(0, folder)
    import fuzz

    return fuzz


def _board_photo(tmp_path_factory):
    """A photo without EXIF of a ball beside a board its corners fix the field of view of to +-0.45 deg
    (looser than the 0.3 deg target), made once."""
    if "path" not in _BOARD_PHOTO:
        path = tmp_path_factory.mktemp("board") / "photo.png"
        _fuzz()._board_photo(path)
        _BOARD_PHOTO.update(path=path, board=_fuzz().SCENE_BOARD)
    return _BOARD_PHOTO["path"], _BOARD_PHOTO["board"]


@settings(max_examples=12, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(strict=st.booleans(), vfov=st.sampled_from([None, "50", "0", "x", "nan", "170"]),
       ball=st.sampled_from([None, "470,330,45", "x", "-1,2,3"]),
       thickness=st.sampled_from([None, "0", "0.5mm", "-1", "x", "nan", "0.08", "1e9"]))
def test_scene_with_strict_refuses_a_loose_board_estimate_in_one_line(tmp_path_factory, strict, vfov, ball,
                                                                       thickness):
    """rtloop-scene on a photo without EXIF whose board fixes the field of view only to +-0.45 deg: with
    --strict and no --vfov one line and no scene; otherwise exit 0 (a scene from the board alone only without
    --strict), 1 or 2 with one line; nothing is written beside --out. Any --board-thickness: a scene whose
    floor lies that far under the board, or one line (not under the ball's radius: naming the board's
    thickness)."""
    from rtloop.cli.scene import scene_main

    photo, board = _board_photo(tmp_path_factory)
    work = tmp_path_factory.mktemp("scene")
    argv = [str(photo), "--board", board, "--ball-radius", "0.08", "--out", str(work / "o"), "--width", "40"]
    argv += ["--strict"] * strict + (["--vfov", vfov] if vfov else []) + (["--ball", ball] if ball else [])
    argv += ["--board-thickness", thickness] if thickness else []
    code, text = _fuzz().run_quietly(scene_main, argv)
    lines = text.strip().splitlines()
    assert code in (0, 1, 2) and "Traceback" not in text
    assert set(p.name for p in work.iterdir()) <= {"o"}
    if code == 0:
        scene = json.loads((work / "o" / "scene.json").read_text())
        assert not (strict and scene["meta"]["acquisition"]["camera_model"] == "board")
        floor = next(o for o in scene["objects"] if o["shape"] == "plane")
        assert floor["point"][1] == {None: 0.0, "0": 0.0, "0.5mm": -0.0005}[thickness]
    elif code == 1 and thickness in ("0.08", "1e9") and not (strict and vfov is None) and ball != "-1,2,3":
        assert len(lines) == 1 and "board thickness" in lines[0], lines
    else:
        assert len([ln for ln in lines if "error" in ln or "usage" in ln]) >= 1 and not (work / "o").exists()
    if strict and vfov is None and code != 2:
        assert code == 1 and len(lines) == 1 and "0.3 deg needed with --strict" in lines[0]


#: SMALL under a `lights` list: its light, a sphere fill light, a sun and a window, their geometry free (the
#: window's centre and size).
SMALL_LIGHTS = copy.deepcopy(SMALL)
SMALL_LIGHTS["lights"] = [{"name": "key", **SMALL_LIGHTS.pop("light")},
                          {"name": "fill", "type": "sphere", "position": [-2.0, 3.0, -1.0], "radius": 0.3,
                           "intensity": 8.0},
                          {"name": "sun", "type": "directional", "direction": [0.2, 1.0, 0.1], "intensity": 0.3},
                          {"name": "window", "type": "rectangle", "position": [-3.0, 2.0, 1.0], "size": [1.5, 1.0],
                           "normal": [1.0, -0.3, -0.2], "up": [0.0, 1.0, 0.0], "intensity": 6.0}]
SMALL_LIGHTS["fit"] = {k: v for k, v in SMALL_LIGHTS["fit"].items() if k != "light.intensity"}
SMALL_LIGHTS["fit"]["lights.fill.position"] = {"min": [-4, 0.5, -4], "max": [4, 6, 4]}
SMALL_LIGHTS["fit"]["lights.fill.radius"] = {"min": 0.01, "max": 1.0}
SMALL_LIGHTS["fit"]["lights.window.position"] = {"min": [-5, 0.5, -3], "max": [-1, 4, 3]}
SMALL_LIGHTS["fit"]["lights.window.size"] = {"min": 0.3, "max": 3.0}

LIGHT_FIELDS = [
    (("lights", 0, "position"), 3), (("lights", 0, "intensity"), 0), (("lights", 1, "position"), 3),
    (("lights", 1, "radius"), 0), (("lights", 1, "intensity"), 0), (("lights", 1, "color"), 3),
    (("lights", 2, "direction"), 3), (("lights", 2, "intensity"), 0),
    (("fit", "lights.fill.position", "min"), 3), (("fit", "lights.fill.radius", "max"), 0),
    (("fit", "lights.fill.radius", "min"), 0),
    (("lights", 3, "position"), 3), (("lights", 3, "size"), 2), (("lights", 3, "normal"), 3),
    (("lights", 3, "up"), 3), (("lights", 3, "intensity"), 0), (("fit", "lights.window.position", "max"), 3),
    (("fit", "lights.window.size", "min"), 2), (("fit", "lights.window.size", "max"), 2),
]


def mutated_light_lists():
    return mutated(SMALL_LIGHTS, LIGHT_FIELDS)


@PROPS
@given(mutated_light_lists())
def test_a_mutated_light_list_loads_and_renders_finite_or_is_a_scene_error(d):
    scene = _loaded_or_one_line(d)
    if scene is None:
        return
    assert np.isfinite(rtloop.render(scene, 8, 6)).all()


PHOTO_LIGHTS = rtloop.render(SMALL_LIGHTS)


@PROPS
@given(st.one_of(st.sampled_from([None, 1, 2, 3, "auto"]),
                 st.sampled_from([0, 9, -1, 2.0, "2", True, math.nan, [1]])),
       st.booleans(), st.integers(0, 3),
       st.sampled_from([{}, {}, {"norm": "l2"}, {"norm": "auto"}, {"vignetting": "off"}, {"tone": "auto"},
                        {"footprint": True}, {"footprint": "silhouette"}, {"uncertainty": "bootstrap"},
                        {"protocol": "paper"}, {"tone": "off"}, {"vignetting": "on"}]))
def test_the_lights_argument_fits_or_raises_rtloop_error(lights, listed, seed, other):
    """The lights fit runs, or refuses in one line; an argument it would ignore (one given other than its
    default, and other than the camera terms off, which the lights fit has none of) is refused naming it,
    never dropped."""
    honoured = (("norm", "auto"), ("tone", "auto"), ("vignetting", "off"), ("tone", "off"))
    ignored = {k: v for k, v in other.items() if (k, v) not in honoured}
    try:
        with _quiet():
            result = rtloop.fit(SMALL_LIGHTS if listed else SMALL, PHOTO_LIGHTS if listed else PHOTO,
                                lights=lights, seed=seed, population=4, generations=1,
                                **({"uncertainty": False} | other))
    except rtloop.RtloopError as e:
        assert "\n" not in str(e)
        return
    assert not ignored or not hasattr(result, "lights"), f"the lights fit dropped {ignored}"
    if not hasattr(result, "lights"):
        assert lights in (None, 1) and not listed
        return
    for light in result.lights:
        assert all(math.isfinite(v) for v in light.get("position", light.get("direction", [])))
        assert math.isfinite(light["intensity"]) and light["intensity"] >= 0
        if light["name"] == "window" and listed:  # its size searched within its bounds
            assert all(0.3 <= v <= 3.0 for v in light["size"]), light["size"]
            for bar in light.get("size_error", [None, None]):
                assert bar is None or (math.isfinite(bar) and bar >= 0)
    assert all(math.isfinite(v) for rows in result.products.values() for row in rows for v in row)


# --- the photo's framing ----------------------------------------------------------------------------------

TWO_BALLS = copy.deepcopy(BALL_ON_FLOOR)
TWO_BALLS["image"] = {"width": 48, "height": 36}
TWO_BALLS["objects"].insert(1, {"name": "small", "shape": "sphere", "center": [1.7, 0.5, 0.4], "radius": 0.5,
                                "material": {"albedo": [0.2, 0.3, 0.9]}})
TWO_BALLS["fit"]["objects.small.albedo"] = {"min": [0, 0, 0], "max": [1, 1, 1]}
TWO_BALLS_PHOTO = rtloop.render(TWO_BALLS, spp=4)


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(turn=st.floats(-10, 10), zoom=st.floats(-0.2, 0.2), dx=st.floats(-6, 6), dy=st.floats(-6, 6),
       mode=st.sampled_from(["check", "correct", "off"]), noise=st.sampled_from([0.0, 0.02, 0.3]))
def test_any_warped_photo_fits_with_finite_framing_numbers(turn, zoom, dx, dy, mode, noise):
    """A photo turned, zoomed and shifted by any amount (within a tenth of the frame) and noisy: each
    framing mode fits it within the bounds with finite numbers; a correction keeps the photo finite and
    leaves pixels out only where the warp took them outside the photo."""
    import cv2

    h, w = TWO_BALLS_PHOTO.shape[:2]
    m = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), turn, math.exp(zoom))
    m[:, 2] += [dx, dy]
    photo = cv2.warpAffine(TWO_BALLS_PHOTO, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    photo = np.clip(photo + np.random.default_rng(3).normal(0, noise, photo.shape), 0, None).astype(np.float32)
    with _quiet():
        result = rtloop.fit(TWO_BALLS, photo, framing=mode, population=6, generations=2, polish=10,
                            uncertainty=False)
    for v, (lo, hi) in zip(result.scene.get_params(), result.scene.bounds()):
        assert lo <= v <= hi
    f = result.goodness["framing"]
    numbers = [f[k] for k in ("outline_rms_px", "outline_rms_se_px", "roll_deg", "zoom_percent") if k in f]
    assert all(math.isfinite(v) for v in [*numbers, *f.get("shift_px", [])])
    if f.get("corrected"):
        moved, inside = result.reframed
        assert np.isfinite(moved).all() and inside.any()


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(value=st.one_of(st.sampled_from(["1", "2", "auto", "0", "9", "-1", "2.5", "AUTO", "", "two", "1e1"]),
                       st.text(max_size=4)),
       listed=st.booleans())
def test_the_lights_flag_fits_or_exits_with_one_line(tmp_path_factory, value, listed):
    import contextlib
    import io

    from rtloop.cli.fit import main

    work = tmp_path_factory.mktemp("lights_cli")
    (work / "scene.json").write_text(json.dumps(SMALL_LIGHTS if listed else SMALL))
    rtloop.save_image(work / "photo.png", PHOTO_LIGHTS if listed else PHOTO)
    argv = [str(work / "scene.json"), str(work / "photo.png"), "--out", str(work / "out"), "--lights", value,
            "--population", "4", "--generations", "1", "--final-scale", "1", "--final-spp", "1", "-q"]
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(argv)
    if code == 0:
        report = json.loads((work / "out" / "result.json").read_text())["fit_report"]
        if report.get("method") != "lights":  # --lights 1 on a one-light scene: the ordinary fit
            assert value.strip() == "1" and not listed
            return
        assert report["lights"]
        for light in report["lights"]:
            assert all(math.isfinite(v) for v in light.get("position", [0.0]) + light.get("position_error", [0.0]))
    else:
        assert code in (1, 2), code
        lines = [line for line in err.getvalue().splitlines() if line]
        assert len(lines) == 1 and lines[0].startswith("rtloop-fit: error: "), lines


def _fov_record() -> dict:
    """SMALL's field-of-view record as rtloop-scene writes it: the camera and the ball at one standard
    deviation either side."""
    cam, ball = SMALL["camera"], SMALL["objects"][0]
    return {"vfov_deg": cam["vfov_deg"], "std_deg": 1.0, "alternates": [
        {"vfov_deg": cam["vfov_deg"] + k, "camera": {**cam, "vfov_deg": cam["vfov_deg"] + k},
         "objects": {ball["name"]: {"center": [v + 0.01 * k for v in ball["center"]]}}} for k in (-1, 1)]}


FOV_VALUES = st.one_of(NUMBERS, st.sampled_from([None, "x", [], {}, [0.1], [1, 2, 3], True, {"center": [0, 0, 0]}]))


@st.composite
def mutated_fov_records(draw) -> object:
    """The field-of-view record with one to three of its values (at any depth) replaced or deleted, an
    unknown object named, or the whole record replaced."""
    record: object = _fov_record()
    for _ in range(draw(st.integers(1, 3))):
        if not isinstance(record, dict) or draw(st.integers(0, 9)) == 0:
            return draw(FOV_VALUES)
        path = draw(st.sampled_from([("vfov_deg",), ("std_deg",), ("alternates",), ("alternates", 0),
                                     ("alternates", 1, "camera"), ("alternates", 0, "camera", "position"),
                                     ("alternates", 1, "camera", "vfov_deg"), ("alternates", 0, "objects"),
                                     ("alternates", 1, "objects", "ball"), ("alternates", 0, "objects", "ball",
                                                                           "center")]))
        node = record
        try:
            for k in path[:-1]:
                node = node[k]
            if draw(st.booleans()) and isinstance(node, dict):
                node.pop(path[-1], None)
            elif path[-1] == "objects" and draw(st.booleans()):
                node[path[-1]] = {draw(st.sampled_from(["floor", "nope", ""])): {"center": [0.0, 0.1, 0.0]}}
            else:
                node[path[-1]] = draw(FOV_VALUES)
        except (KeyError, IndexError, TypeError):
            continue
    return record


@PROPS
@given(mutated_fov_records())
def test_a_mutated_field_of_view_record_fits_with_finite_bars_or_is_one_line(tmp_path_factory, record):
    import contextlib
    import io

    from rtloop.cli.fit import main

    work = tmp_path_factory.mktemp("fov")
    (work / "scene.json").write_text(json.dumps({**SMALL, "meta": {"acquisition": {"field_of_view": record}}}))
    rtloop.save_image(work / "photo.png", PHOTO)
    argv = [str(work / "scene.json"), str(work / "photo.png"), "--out", str(work / "out"), "--population", "4",
            "--generations", "1", "--final-scale", "1", "--final-spp", "1", "--snapshot-every", "0", "-q"]
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(argv)
    if code == 0:
        bars = json.loads((work / "out" / "result.json").read_text())["fit_report"]["uncertainty"]["bars"]
        carried = bars.get("field_of_view")
        assert all(v is None or math.isfinite(v) for v in bars["sigma"].values())
        if carried is not None:
            assert all(math.isfinite(v) for v in carried["shift"].values())
    else:
        lines = [line for line in err.getvalue().splitlines() if line]
        assert code == 1 and len(lines) == 1 and "field_of_view" in lines[0], lines
