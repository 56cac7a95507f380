"""fuzz/fuzz.py's odd values (what every surface puts where a value belongs) and its file surfaces: mesh
files, EXIF focal tags, a camera's and lens's EXIF names (the lens profile) and rtloop-insert's arguments."""

from __future__ import annotations

import contextlib
import copy
import io
import math
import random
from pathlib import Path

import numpy as np

import rtloop

ODD = [
    None,
    True,
    0,
    -1,
    1e300,
    -1e-300,
    float("nan"),
    float("inf"),
    "",
    "x",
    [],
    {},
    [1, 2],
    [0, 0, 0],
    {"min": 1, "max": 0},
    2**70,
]


def odd(rng: random.Random):
    return copy.deepcopy(rng.choice(ODD)) if rng.random() < 0.7 else rng.uniform(-1e3, 1e3)


MESH_HEADS = [
    "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
    "element face {m}\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty double x\nproperty double y\n"
    "property double z\nelement face {m}\nproperty list uint int vertex_indices\nend_header\n",
    "v 0 0 0\nv 1e300 0 0\nv 0 1 0\nf 1 2 {m}\nmtllib /dev/zero\n",
]


def mesh(rng: random.Random, tmp: Path, base: dict) -> None:
    """A mesh file: a header with odd counts and a mutated body (bytes flipped, cut, repeated)."""
    data = bytearray(rng.choice(MESH_HEADS).format(n=rng.choice([0, 3, 2**31, 10**12, -1]),
                                                    m=rng.choice([0, 1, 9, 2**32])).encode())
    for _ in range(rng.randint(0, 4)):
        if data:
            data[rng.randrange(len(data))] = rng.randrange(256)
    data += bytes(rng.randrange(256) for _ in range(rng.randint(0, 64)))
    path = tmp / f"m.{rng.choice(['ply', 'obj', 'PLY'])}"
    path.write_bytes(bytes(data[: rng.randint(0, len(data))] if rng.random() < 0.2 else data))
    scene = copy.deepcopy(base)
    scene["objects"].append({"name": "m", "shape": "mesh", "file": str(path), "scale": rng.choice([1, 1e-9, 1e9])})
    rtloop.render(rtloop.load_scene(scene), 6, 4, 1)


def exif(rng: random.Random, tmp: Path) -> None:
    from PIL import Image

    from rtloop.acquisition.exif import exif_exposure, exif_focal

    exif = Image.Exif()
    exif[0x0112] = rng.randint(-1, 10)
    tags = {t: odd(rng) if rng.random() < 0.5 else rng.choice([4.0, 28, 1600.0, 3, (1, 0), 1e9, 1e-9])
            for t in rng.sample([0x920A, 0xA405, 0xA20E, 0xA210, 0x829A, 0x829D, 0x8827], rng.randint(1, 5))}
    try:
        exif.get_ifd(0x8769).update(tags)
        Image.new("RGB", (8, 6)).save(tmp / "e.jpg", exif=exif)
    except Exception:  # noqa: BLE001 - a value Pillow cannot write
        return
    found = exif_focal(tmp / "e.jpg", rng.choice([8, 6, 1000]), 6)
    if found is not None and not (math.isfinite(found.focal_px) and found.focal_px > 0):
        raise AssertionError(f"focal_px {found.focal_px}")
    exif_exposure(tmp / "e.jpg")


LENS_NAMES = ["Canon", "Canon EOS 600D", "EF-S18-55mm f/3.5-5.6 IS II", "NIKON CORPORATION", "NIKON D90",
              "AF-S DX Nikkor 18-105mm f/3.5-5.6G ED VR", "OLYMPUS IMAGING CORP.", "E-M5", "", "\x00", "x" * 300]


def lens(rng: random.Random, tmp: Path) -> None:
    """EXIF naming a camera and lens (real names, odd strings and numbers): a lens profile whose resampling is
    finite, or None and a one-line reason."""
    from PIL import Image

    from rtloop.acquisition.lens_profile import find_lens_profile, read_lens_exif

    pick = lambda: rng.choice(LENS_NAMES) if rng.random() < 0.7 else odd(rng)  # noqa: E731
    exif = Image.Exif()
    try:
        exif[0x010F], exif[0x0110] = pick(), pick()
        exif.get_ifd(0x8769).update({0xA434: pick(), 0x920A: rng.choice([18.0, 35.0, 105.0, odd(rng)]),
                                     0x829D: rng.choice([3.5, 8.0, odd(rng)])})
        Image.new("RGB", (12, 9)).save(tmp / "lens.png", exif=exif)
    except Exception:  # noqa: BLE001 - a value Pillow cannot write
        return
    profile, why = find_lens_profile(read_lens_exif(tmp / "lens.png"))
    if profile is None:
        if not why or "\n" in why:
            raise AssertionError(f"no profile and no one-line reason: {why!r}")
        return
    remap = profile.remap(12, 9, rng.choice([5.0, 12.0, 300.0]))
    out = remap.correct(np.full((9, 12, 3), 0.5, np.float32))
    if not (np.isfinite(out).all() and np.isfinite(remap.points(np.array([[0.0, 0.0], [11.0, 8.0]]))).all()):
        raise AssertionError("lens profile: a non-finite resampling")


def insert_cli(rng: random.Random, tmp: Path) -> None:
    from rtloop.cli.insert import insert_main

    work = tmp / "ins"
    work.mkdir(exist_ok=True)
    before = sorted(p.name for p in work.iterdir())
    argv = [str(tmp / "scene.json"), str(tmp / "photo.png"), "--add", str(tmp / "objects.json"),
            "--out", str(work / "out")]
    for _ in range(rng.randint(0, 3)):
        flag = rng.choice(["--spp", "--response", "--out", "--force", "--uniform"])
        argv += [flag] if flag in ("--force", "--uniform") else [flag, str(odd(rng))]
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()), \
            contextlib.chdir(work):  # a relative --out stays inside the sandbox
        try:
            insert_main(argv)
        except SystemExit as e:
            if e.code not in (0, 1, 2):
                raise
    outs = {argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--out"}
    made = sorted(p.name for p in work.iterdir() if p.name not in before and p.name not in outs | {"out"})
    if made or not (tmp / "photo.png").is_file() or not (tmp / "objects.json").is_file():
        raise AssertionError(f"rtloop-insert wrote beside --out or lost an input: {made}")
