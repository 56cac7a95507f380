"""Triangle meshes (OBJ): a tessellated sphere renders like the analytic one within the bound its
tessellation sets, casts the same shadow, is refused when its file is bad, and is inserted but not fitted."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import rtloop

REPO = Path(__file__).resolve().parents[1]
SCENE = REPO / "examples" / "yellow-ball" / "scene.json"
W, H = 256, 192


def icosphere(levels: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: vertices (on the sphere) and faces (outward, counter-clockwise), 20·4^levels faces."""
    t = (1 + 5**0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(p, float) / np.linalg.norm(p) for p in v]
    faces = f
    for _ in range(levels):
        mid: dict[tuple[int, int], int] = {}

        def m(a: int, b: int, mid: dict[tuple[int, int], int] = mid) -> int:
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = verts[a] + verts[b]
                verts.append(p / np.linalg.norm(p))
                mid[key] = len(verts) - 1
            return mid[key]

        faces = [g for a, b, c in faces
                 for g in ((a, m(a, b), m(c, a)), (b, m(b, c), m(a, b)), (c, m(c, a), m(b, c)),
                           (m(a, b), m(b, c), m(c, a)))]
    return np.array(verts), np.array(faces)


def write_obj(path: Path, v: np.ndarray, f: np.ndarray, normals: bool) -> Path:
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in v]
    if normals:  # the exact sphere normals at the vertices
        lines += [f"vn {x:.17g} {y:.17g} {z:.17g}" for x, y, z in v]
        lines += [f"f {a + 1}//{a + 1} {b + 1}//{b + 1} {c + 1}//{c + 1}" for a, b, c in f]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_ply(path: Path, v: np.ndarray, f: np.ndarray, normals: bool, binary: bool) -> Path:
    """A PLY file written here (not by the crate rtloop reads it with): float vertices (and normals), faces
    as uchar-counted int lists (any polygon), ASCII or binary little-endian."""
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals else [])
    head = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", f"element vertex {len(v)}"]
    head += [f"property float {p}" for p in props]
    head += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    cols = np.hstack([v, v] if normals else [v]).astype("<f4")  # unit-sphere vertices are their normals
    if binary:
        body = b"".join(
            [cols.tobytes()] + [bytes([len(face)]) + np.asarray(face, "<i4").tobytes() for face in f])
        path.write_bytes(("\n".join(head) + "\n").encode() + body)
    else:
        lines = [" ".join(f"{x:.9g}" for x in row) for row in cols]
        lines += [" ".join(str(i) for i in [len(face), *face]) for face in f]
        path.write_text("\n".join(head + lines) + "\n")
    return path


@pytest.fixture(scope="module")
def sphere_ply(tmp_path_factory):
    v, f = icosphere(5)
    d = tmp_path_factory.mktemp("ply")
    return write_ply(d / "flat.ply", v, f, False, True), write_ply(d / "smooth.ply", v, f, True, False)


@pytest.fixture(scope="module")
def sphere_obj(tmp_path_factory):
    v, f = icosphere(5)  # 20480 triangles
    d = tmp_path_factory.mktemp("mesh")
    return v, f, write_obj(d / "flat.obj", v, f, False), write_obj(d / "smooth.obj", v, f, True)


def with_ball_as_mesh(file: Path) -> dict:
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    ball = scene["objects"][0]
    assert ball["shape"] == "sphere" and ball["radius"] == 1.0
    scene["objects"][0] = {"name": "ball", "shape": "mesh", "file": str(file), "position": ball["center"],
                           "scale": 1.0, "material": ball["material"]}
    scene["fit"] = {}
    return scene


def tessellation_bounds(v: np.ndarray, f: np.ndarray) -> tuple[float, float, float]:
    """Max angle from a face normal to its corners' (true) normals, max angular edge length, and the sagitta
    (how far a face's plane lies inside the unit sphere)."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    corner = max(np.arccos(np.clip((n * p).sum(1), -1, 1)).max() for p in (a, b, c))
    edge = max(np.arccos(np.clip((p * q).sum(1), -1, 1)).max() for p, q in ((a, b), (b, c), (c, a)))
    sagitta = 1.0 - (n * a).sum(1).min()
    return float(corner), float(edge), float(sagitta)


@pytest.mark.parametrize("fmt", ["obj", "ply"])
@pytest.mark.parametrize("smooth", [False, True])
def test_tessellated_sphere_renders_like_the_analytic_sphere(sphere_obj, sphere_ply, smooth, fmt):
    v, f, flat, smooth_file = sphere_obj
    if fmt == "ply":  # flat: binary, smooth: ASCII with normals
        flat, smooth_file = sphere_ply
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    mesh = with_ball_as_mesh(smooth_file if smooth else flat)
    ref, got = rtloop.render(scene, W, H), rtloop.render(mesh, W, H)
    ids_ref, ids_got = rtloop.object_ids(scene, W, H), rtloop.object_ids(mesh, W, H)
    ball = ids_ref == 0
    # Away from the silhouette: ball pixels whose 5x5 neighbourhood is ball in both renders.
    inner = ball & (ids_got == 0)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            inner &= np.roll(ball, (dy, dx), (0, 1)) & np.roll(ids_got == 0, (dy, dx), (0, 1))
    assert inner.sum() > 4000
    # Bound: direct light is K·cos θ with K = exposure·ρ/π·I/d²; a normal off by δ changes cos θ by <= δ,
    # a hit point moved by Δx along the ray turns the normal by <= Δx/(1 - s) and the light by <= Δx/d,
    # and changes 1/d² by <= 2Δx/d. Δx <= s / cos(view) with cos(view) >= that 2.5 px in from the rim.
    corner, edge, s = tessellation_bounds(v, f)
    delta = edge if smooth else corner
    cam, light = np.array(scene["camera"]["position"]), np.array(scene["light"]["position"])
    centre = np.array(scene["objects"][0]["center"])
    r_px = H / 2 / np.tan(np.radians(scene["camera"]["vfov_deg"]) / 2) / np.sqrt(np.sum((cam - centre) ** 2) - 1)
    cos_view = np.sqrt(1 - ((r_px - 2.5) / r_px) ** 2)
    dx = s / cos_view
    d_min = np.linalg.norm(light - centre) - 1.0
    albedo = np.array(scene["objects"][0]["material"]["albedo"])
    k_max = scene["exposure"] * albedo / np.pi * scene["light"]["intensity"] / d_min**2
    bound = k_max * (delta + dx / (1 - s) + 3 * dx / d_min) + 1e-4
    err = np.abs(got - ref)[inner]
    assert (err <= bound).all(), f"max error {err.max(0)} > bound {bound}"
    # The bound is tight to within a small factor (not vacuous): the flat mesh's error reaches a part of it.
    if not smooth:
        assert (err.max(0) > 0.1 * bound).all()
    # The silhouette agrees to the pixel: ids differ only at the rim.
    rim = ball ^ (ids_got == 0)
    assert rim.sum() < 0.02 * ball.sum()


def test_a_mesh_casts_the_analytic_spheres_shadow_on_the_floor(sphere_obj):
    _, _, flat, _ = sphere_obj
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    mesh = with_ball_as_mesh(flat)
    ids = rtloop.object_ids(scene, W, H)
    floor = (ids == 1) & (rtloop.object_ids(mesh, W, H) == 1)
    # No ambient light: the floor in shadow is black.
    shadow_ref = floor & (rtloop.render(scene, W, H).sum(2) == 0)
    shadow_got = floor & (rtloop.render(mesh, W, H).sum(2) == 0)
    assert shadow_ref.sum() > 500
    # They differ only on the analytic shadow's boundary (the mesh lies within 2e-4 radii of the sphere).
    edge = np.zeros_like(shadow_ref)
    for ax in (0, 1):
        for sh in (-1, 1):
            edge |= shadow_ref != np.roll(shadow_ref, sh, ax)
    differ = shadow_ref ^ shadow_got
    assert not (differ & ~edge).any()
    assert differ.sum() < 0.1 * edge.sum()


def test_a_concave_mesh_shadows_itself(tmp_path):
    # A floor square with a wall standing on it across its middle; the light low on one side: the floor on
    # the far side of the wall lies in the wall's shadow (its own triangles), the near side is lit.
    obj = tmp_path / "wall.obj"
    obj.write_text("v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv 0 0 -1\nv 0 0 1\nv 0 1 1\nv 0 1 -1\n"
                   "f 1 2 3\nf 1 3 4\nf 5 6 7\nf 5 7 8\n")
    scene = {"image": {"width": 64, "height": 64},
             "camera": {"position": [0, 6, 0], "look_at": [0, 0, 0], "up": [0, 0, -1], "vfov_deg": 30},
             "light": {"position": [-3, 1.5, 0], "intensity": 10},
             "objects": [{"name": "m", "shape": "mesh", "file": str(obj)}]}
    img = rtloop.render(scene, 64, 64).sum(2)
    ids = rtloop.object_ids(scene, 64, 64)
    # The floor beyond the wall (x > 0, its shadow reaches x = 6) is black, the near side lit; the image's x
    # axis may run either way.
    a, b = img[28:36, 16:28], img[28:36, 36:48]
    assert (ids[28:36, 16:28] == 0).all() and (ids[28:36, 36:48] == 0).all()
    assert ((a > 0).all() and (b == 0).all()) or ((b > 0).all() and (a == 0).all())


PLY_HEAD = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
PLY_FACE = "element face 1\nproperty list uchar int vertex_indices\nend_header\n"


@pytest.mark.parametrize("ext, content, message", [
    ("obj", None, "cannot open the OBJ file"),
    ("obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "index out of"),
    ("obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "vertex 2 is not finite"),
    ("obj", "# nothing\n", "no triangles"),
    ("obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "degenerate"),
    ("obj", "v 0 0 0\nv 1e30 0 0\nv 0 1 0\nf 1 2 3\n", r"triangle 1 lies beyond \+-1e8 m"),
    ("ply", None, "cannot open the PLY file"),
    ("ply", "solid nothing\n", "not a valid PLY file"),
    ("ply", PLY_HEAD + PLY_FACE + "0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n", "face 1: vertex index 9 is out of range"),
    ("ply", "nan, binary", "vertex 2 is not finite"),  # an ASCII nan is not a PLY number
    ("ply", PLY_HEAD + "end_header\n0 0 0\n1 0 0\n0 1 0\n", "no triangles"),
    ("ply", PLY_HEAD + PLY_FACE + "0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n", "degenerate"),
    ("ply", PLY_HEAD.replace("property float z\n", "") + PLY_FACE + "0 0\n1 0\n0 1\n3 0 1 2\n", 'vertex 1 has no number "z"'),
])
def test_bad_mesh_files_are_refused_naming_the_field_and_file(tmp_path, ext, content, message):
    bad = tmp_path / f"bad.{ext}"
    if content == "nan, binary":
        write_ply(bad, np.array([[0, 0, 0], [np.nan, 0, 0], [0, 1, 0]]), [[0, 1, 2]], False, True)
    elif content is not None:
        bad.write_text(content)
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    scene["objects"].append({"name": "m", "shape": "mesh", "file": str(bad)})
    with pytest.raises(rtloop.SceneError, match=rf"objects\[2\]\.file: .*bad\.{ext}: .*" + message):
        rtloop.load_scene(scene)


def test_ply_polygons_render_as_the_same_obj(tmp_path):
    # The insertion fixture's box: OBJ quads (split by tobj) against PLY quads (split by rtloop), both formats.
    box = REPO / "tests" / "fixtures" / "insert" / "direct-side-box" / "box.obj"
    lines = box.read_text().split("\n")
    v = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    f = [[int(i) - 1 for i in ln.split()[1:]] for ln in lines if ln.startswith("f ")]
    assert len(f) == 6 and all(len(q) == 4 for q in f)
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    def render(file: Path) -> np.ndarray:
        obj = {"name": "box", "shape": "mesh", "file": str(file), "position": [1.5, 0, -1.0],
               "material": {"albedo": [0.7, 0.3, 0.2]}}
        return rtloop.render({**scene, "objects": [*scene["objects"], obj]}, W, H)
    want = render(box)
    for binary in (False, True):
        assert np.array_equal(render(write_ply(tmp_path / f"box{binary}.ply", v, f, False, binary)), want)
    assert (want != rtloop.render(scene, W, H)).any()


def test_bad_mesh_fields_are_refused(tmp_path):
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    for extra, message in [({"scale": 0}, r"objects\[2\]\.scale: must be > 0"),
                           ({"radius": 1}, r"objects\[2\]\.radius: not a field of a mesh"),
                           ({}, r"objects\[2\]\.file: missing")]:
        scene["objects"] = scene["objects"][:2] + [{"name": "m", "shape": "mesh", **extra}]
        if "file" not in message:
            scene["objects"][2]["file"] = "x.obj"
        with pytest.raises(rtloop.SceneError, match=message):
            rtloop.load_scene(scene)
    scene["objects"] = scene["objects"][:1] + [{**scene["objects"][1], "file": "x.obj"}]
    with pytest.raises(rtloop.SceneError, match=r"objects\[1\]\.file: not a field of a plane"):
        rtloop.load_scene(scene)


def test_relative_mesh_files_resolve_against_the_scene_file_folder(tmp_path, sphere_obj, monkeypatch):
    _, _, flat, _ = sphere_obj
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "ball.obj").write_bytes(flat.read_bytes())
    scene = with_ball_as_mesh(Path("ball.obj"))
    (tmp_path / "sub" / "scene.json").write_text(json.dumps(scene))
    monkeypatch.chdir(tmp_path)
    loaded = rtloop.scene_to_dict(rtloop.load_scene(tmp_path / "sub" / "scene.json"))
    assert loaded["objects"][0]["file"] == str(tmp_path / "sub" / "ball.obj")  # written out absolute
    with pytest.raises(rtloop.SceneError, match="ball.obj: cannot open"):
        rtloop.load_scene(scene)  # a dict: relative to the current directory, where there is none
    monkeypatch.chdir(tmp_path / "sub")
    assert rtloop.scene_to_dict(rtloop.load_scene(scene))["objects"][0]["file"] == loaded["objects"][0]["file"]


def test_meshes_are_inserted_but_not_fitted(tmp_path, sphere_obj):
    _, _, flat, _ = sphere_obj
    (tmp_path / "ball.obj").write_bytes(flat.read_bytes())
    added = {"name": "ball2", "shape": "mesh", "file": "ball.obj", "position": [1.8, 0.5, -1.0], "scale": 0.5,
             "material": {"albedo": [0.2, 0.3, 0.8]}}
    (tmp_path / "objects.json").write_text(json.dumps({"objects": [added]}))
    photo = rtloop.render(SCENE, 128, 96, 4)
    r = rtloop.insert(SCENE, photo, tmp_path / "objects.json", spp=4)
    ball2 = {"name": "ball2", "shape": "sphere", "center": added["position"], "radius": 0.5,
             "material": added["material"]}
    sphere = rtloop.insert(SCENE, photo, [ball2], spp=4)
    # The mesh ball covers the sphere's pixels and darkens the floor as the sphere does.
    assert abs(r.matte.sum() - sphere.matte.sum()) < 0.02 * sphere.matte.sum()
    assert np.abs(r.composite - sphere.composite).mean() < 0.01
    with pytest.raises(rtloop.RtloopError, match="meshes can be rendered and inserted, not fitted"):
        rtloop.fit(with_ball_as_mesh(flat) | {"fit": {"light.intensity": {"min": 1, "max": 100}}}, photo)


def load_with_mesh(path: Path) -> None:
    scene = rtloop.scene_to_dict(rtloop.load_scene(SCENE))
    scene["objects"].append({"name": "m", "shape": "mesh", "file": str(path)})
    rtloop.load_scene(scene)


def test_a_fifo_mesh_is_refused_without_waiting_for_a_writer(tmp_path):
    import os
    import subprocess

    fifo = tmp_path / "pipe.obj"
    os.mkfifo(fifo)
    # A reader that blocked in open() (holding the GIL) would wait for ever: another process lets it through.
    writer = subprocess.Popen(["sh", "-c", 'sleep 10; : > "$0"', str(fifo)])
    try:
        with pytest.raises(rtloop.SceneError, match=r"objects\[2\]\.file: .*pipe\.obj: .*FIFO"):
            load_with_mesh(fifo)
    finally:
        writer.kill()
        writer.wait()


@pytest.mark.parametrize("ext", ["obj", "ply"])
def test_a_device_mesh_is_refused_before_it_is_read(tmp_path, ext):
    link = tmp_path / f"dev.{ext}"
    link.symlink_to("/dev/null")  # /dev/zero would be read for ever; both are devices
    with pytest.raises(rtloop.SceneError, match=r"dev\.\w+: .*(character device|FIFO or device)"):
        load_with_mesh(link)


@pytest.mark.parametrize("count, message", [
    (1_000_000, r"declares 1000001 elements, more than its 26 bytes of data can hold"),
    (1_000_000_000, r"declares 1000000001 elements, more than the 10000000 read \(the limit\)"),
])
def test_ply_element_counts_are_bounded_by_the_file_size_and_a_cap(tmp_path, count, message):
    bad = tmp_path / "huge.ply"
    bad.write_text(PLY_HEAD.replace("vertex 3", f"vertex {count}") + PLY_FACE + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    with pytest.raises(rtloop.SceneError, match=message):
        load_with_mesh(bad)


def test_ply_errors_are_one_line_and_quote_nothing_from_the_file(tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("zq9:x:0:0:the first line of a system file\nsecond line\n")
    link = tmp_path / "mesh.ply"
    link.symlink_to(secret)
    with pytest.raises(rtloop.SceneError) as info:
        load_with_mesh(link)
    message = str(info.value)
    assert "not a valid PLY file" in message
    assert "\n" not in message and "zq9" not in message and "system file" not in message
    body = tmp_path / "body.ply"
    body.write_text(PLY_HEAD + PLY_FACE + "0 0 0\nsecret 0 0\n0 1 0\n3 0 1 2\n")
    with pytest.raises(rtloop.SceneError) as info:
        load_with_mesh(body)
    assert "\n" not in str(info.value) and "secret" not in str(info.value)


@pytest.mark.parametrize("ext", ["obj", "ply"])
def test_a_huge_vertex_is_out_of_range_not_infinite(tmp_path, ext):
    bad = tmp_path / f"far.{ext}"
    rows = "0 0 0\n1e300 0 0\n0 1 0\n"
    if ext == "obj":
        bad.write_text("".join(f"v {r}\n" for r in rows.splitlines()) + "f 1 2 3\n")
    else:
        bad.write_text(PLY_HEAD.replace("float", "double") + PLY_FACE + rows + "3 0 1 2\n")
    with pytest.raises(rtloop.SceneError, match=r"vertex 2 is out of range") as info:
        load_with_mesh(bad)
    assert "inf" not in str(info.value)
