"""Time and error of a 12 MP (4000 x 3000) insertion: adaptive supersampling against every pixel supersampled.

    python benches/insert_12mp.py [--out benches/results] [--size 4000x3000] [--spp 16]

The example examples/insert-ball (its fitted result.json, its photo upscaled to the size) gets its blue ball
and a turned box mesh (flat faces: creases and a polygonal shadow). ``rtloop.insert`` runs adaptively (one
sample per pixel, the 4 x 4 grid where a neighbour differs) and then with ``adaptive=False`` (the grid in every
pixel, the reference). Reported: wall and CPU seconds of each, the share of pixels supersampled, and the
adaptive result's difference from the reference in 8-bit sRGB codes and in linear units (max and mean) for
the composite and both renders. Writes ``insert_12mp.md`` into ``--out``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

import rtloop
from rtloop import _native
from rtloop._files import write_text
from rtloop._srgb import encode
from rtloop.insert import load_objects

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "insert-ball"
BOX = REPO / "tests" / "fixtures" / "insert" / "direct-side-box" / "box.obj"


def timed(fn):
    t, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - t, time.process_time() - c


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=REPO / "benches" / "results")
    p.add_argument("--size", default="4000x3000", help="WxH (default 4000x3000, 12 MP)")
    p.add_argument("--spp", type=int, default=16)
    args = p.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))

    from PIL import Image

    small = rtloop.load_image(EXAMPLE / "photo.png", (128, 96))
    photo = np.stack([np.asarray(Image.fromarray(small[..., c]).resize((width, height), Image.BICUBIC))
                      for c in range(3)], axis=-1).clip(0, None).astype(np.float32)
    objects = load_objects(EXAMPLE / "objects.json") + [
        {"name": "box", "shape": "mesh", "file": str(BOX), "position": [0.9, 0.0, -0.9], "scale": 1.3,
         "material": {"albedo": [0.7, 0.3, 0.2], "specular": 0.2, "shininess": 30.0}}]
    result = EXAMPLE / "result.json"
    adaptive, t_a, c_a = timed(lambda: rtloop.insert(result, photo, objects, spp=args.spp))
    uniform, t_u, c_u = timed(lambda: rtloop.insert(result, photo, objects, spp=args.spp, adaptive=False))
    base = rtloop.load_scene(result)
    d = rtloop.scene_to_dict(base)
    with_scene = rtloop.load_scene({**d, "objects": d["objects"] + objects})
    _, _, refined = _native.render_layers([base, with_scene], width, height, args.spp, True, len(d["objects"]))

    rows = []
    for name in ("composite", "with_objects", "without"):
        a, b = getattr(adaptive, name), getattr(uniform, name)
        codes = np.abs(encode(a) - encode(b)) * 255
        lin = np.abs(a - b)
        rows.append(f"| {name} | {codes.max():.3f} | {codes.mean():.2e} | {lin.max():.2e} | {lin.mean():.2e} |")
    matte = np.abs(adaptive.matte - uniform.matte)
    text = "\n".join([
        "# 12 MP insertion: adaptive against uniform supersampling",
        "",
        (f"machine: {platform.machine()}, {os.cpu_count()} logical CPUs, Python {sys.version.split()[0]}, "
        f"numpy {np.__version__}; load average at the end {os.getloadavg()[0]:.1f}"),
        (f"image {width} x {height}, spp {args.spp} where supersampled; examples/insert-ball with its ball and a "
        "turned box mesh"),
        "",
        "| sampling | wall s | CPU s | pixels supersampled |",
        "|---|---|---|---|",
        f"| adaptive | {t_a:.2f} | {c_a:.2f} | {refined / (width * height):.2%} |",
        f"| uniform (reference) | {t_u:.2f} | {c_u:.2f} | 100% |",
        "",
        "Adaptive minus uniform:",
        "",
        "| image | max codes | mean codes | max linear | mean linear |",
        "|---|---|---|---|---|",
        *rows,
        f"| matte | | | {matte.max():.2e} | {matte.mean():.2e} |",
        "",
    ])
    write_text(args.out / "insert_12mp.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
