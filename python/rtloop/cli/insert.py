"""``rtloop-insert``: put new objects into a fitted photo (:func:`rtloop.insert.insert`) and write the
composite, the matte and the two renders into an output directory moved into place whole."""

from __future__ import annotations

from .._interrupt import importing

with importing:  # a Ctrl-C while a console script starts: one line, exit 130
    import argparse
    import os
    import shutil
    import signal
    import sys
    import threading
    import warnings
    from collections.abc import Sequence
    from pathlib import Path
    from typing import Any

    import numpy as np

    from .._files import check_out_dir, move_into_place, recover_leftovers, staging_dir, write_bytes
    from .._srgb import encode8
    from ..errors import RtloopError, RtloopWarning

PROG = "rtloop-insert"

DESCRIPTION = """\
Insert virtual objects into a photo under the light rtloop-fit found (differential rendering, after
Debevec 1998). The fitted scene is rendered with and without the added objects at the photo's full size;
where the objects are seen the composite is their render, elsewhere it is the photo plus the difference
they make (their shadows on the real floor, their bounce light).

OBJECTS.json holds {"objects": [...]} (or a bare list) in the scene format, for example
  {"objects": [{"name": "ball2", "shape": "sphere", "center": [1.8, 0.5, -1.0], "radius": 0.5,
                "material": {"albedo": [0.2, 0.3, 0.8], "specular": 0.0, "shininess": 0.0}}]}
A triangle mesh is {"name": "bunny", "shape": "mesh", "file": "bunny.obj", "position": [x, y, z], "scale": s,
"material": {...}} (an OBJ or PLY file), its file relative to OBJECTS.json's folder.

Writes into DIR: composite.png (8-bit sRGB), composite_linear16.png (16-bit linear), matte.png (the
objects' pixel coverage), with.png and without.png (the two renders, 8-bit sRGB).

  rtloop-insert out/result.json photo.png --add objects.json --out inserted
"""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="rtloop-insert", description=DESCRIPTION,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("result", metavar="RESULT.json", help="rtloop-fit's result.json (or any scene file)")
    p.add_argument("photo", metavar="PHOTO", help="the photo the scene was fitted to, at any size of its aspect")
    p.add_argument("--add", metavar="OBJECTS.json", required=True, help="the objects to insert")
    p.add_argument("--out", metavar="DIR", required=True, help="output directory (replaced whole with --force)")
    p.add_argument("--spp", type=int, default=16,
                   help="samples per pixel where a pixel is supersampled (default 16, a 4 x 4 grid)")
    p.add_argument("--uniform", action="store_true",
                   help="supersample every pixel, not only those at an edge (object, shadow, crease or colour "
                        "step in either render): the reference, about spp times slower")
    p.add_argument("--response", choices=("srgb", "linear"), default="srgb",
                   help="how the photo's values relate to light (default srgb)")
    p.add_argument("--force", action="store_true", help="replace DIR if it exists and is not empty")
    return p


class _Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C (nothing half-written) but reported as such."""


def _on_sigterm(signum: int, frame: Any) -> None:
    raise _Terminated()


def insert_main(argv: Sequence[str] | None = None) -> int:
    """Exit status: 0 done, 1 bad input, 2 bad command line, 130 interrupted (Ctrl-C), 143 terminated."""
    args = _parser().parse_args(argv)
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        _run(args)
    except _Terminated:
        print(f"\n{PROG}: terminated", file=sys.stderr, flush=True)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print(f"\n{PROG}: interrupted", file=sys.stderr, flush=True)
        return 130
    except (RtloopError, OSError) as e:
        where = f"{e.filename}: " if isinstance(e, OSError) and e.filename else ""
        text = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
        print(f"{PROG}: error: {where}{' '.join(text.split())}", file=sys.stderr)
        return 1
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0


def _inputs(args: argparse.Namespace) -> list[Path]:
    """The files the insertion reads (the mesh files too): an --out holding one is never replaced."""
    from ..insert import load_objects

    paths = [Path(args.result), Path(args.photo), Path(args.add)]
    try:
        paths += [Path(o["file"]) for o in load_objects(args.add) if isinstance(o.get("file"), str)]
    except RtloopError:
        pass  # reported when the insertion loads them
    return paths


def _show_progress(done: int, total: int) -> None:
    print(f"\rrtloop-insert: tiles {done}/{total}", end="", file=sys.stderr, flush=True)


def _png(image: np.ndarray) -> bytes:
    from ..acquisition._common import encode_png

    return encode_png(np.ascontiguousarray(image[..., ::-1] if image.ndim == 3 else image))


def _run(args: argparse.Namespace) -> None:
    from ..insert import insert

    if not 1 <= args.spp <= 4096:
        raise RtloopError(f"--spp: must be 1..4096 (got {args.spp})")
    out = Path(os.path.abspath(args.out))  # normalised: "." and "x/.." have a name and a parent
    replace = check_out_dir(out, args.force, _inputs(args))
    where = "every pixel" if args.uniform else "pixels at edges"
    print(f"{PROG}: rendering with and without the objects ({args.spp} spp at {where})", file=sys.stderr)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RtloopWarning)
        r = insert(args.result, args.photo, args.add, spp=args.spp, response=args.response,
                   adaptive=not args.uniform, progress=_show_progress)
    print(file=sys.stderr)
    for w in caught:
        print(f"{PROG}: warning: {' '.join(str(w.message).split())}", file=sys.stderr)
    recover_leftovers(out)
    tmp = staging_dir(out, "rtloop-insert")
    try:
        write_bytes(tmp / "composite.png", _png(encode8(r.composite)))
        lin16 = np.round(np.clip(r.composite, 0.0, 1.0) * 65535.0).astype(np.uint16)
        write_bytes(tmp / "composite_linear16.png", _png(lin16))
        write_bytes(tmp / "matte.png", _png(np.round(r.matte * 255.0).astype(np.uint8)))
        write_bytes(tmp / "with.png", _png(encode8(r.with_objects)))
        write_bytes(tmp / "without.png", _png(encode8(r.without)))
        move_into_place(tmp, out, replace, "rtloop-insert")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    print(f"wrote {out}/composite.png, composite_linear16.png, matte.png, with.png, without.png")


if __name__ == "__main__":
    sys.exit(insert_main())
