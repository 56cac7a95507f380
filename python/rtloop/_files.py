"""Writing results safely: atomic writes (a temporary file renamed into place), a staged output
directory moved into place whole, and ``jsonable`` (numpy values as plain JSON)."""

from __future__ import annotations

import json
import math
import os
import re
import secrets
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["PlaceError", "jsonable", "move_into_place", "recover_leftovers", "staging_dir", "umask", "write_bytes",
           "write_json", "write_text"]


def umask() -> int:
    """The process's umask (read without changing it for long)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_bytes(path: str | os.PathLike[str], data: bytes, *, parents: bool = False) -> None:
    """Write a file through a temporary file in the same directory and rename it into place; with
    ``parents``, create the directory first."""
    path = Path(path)
    if parents:
        path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o666 & ~umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_text(path: str | os.PathLike[str], text: str, *, parents: bool = False) -> None:
    """:func:`write_bytes` of ``text`` in UTF-8."""
    write_bytes(path, text.encode("utf-8"), parents=parents)


def jsonable(value: Any) -> Any:
    """``value`` with numpy types made plain and NaN/infinity made None (JSON has neither)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (np.floating, float)):
        v = float(value)
        if not math.isfinite(v):
            return None
        return v
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_json(path: str | os.PathLike[str], data: Any, *, parents: bool = True) -> None:
    """Write ``data`` as indented JSON (numpy values converted, NaN as null), atomically."""
    write_text(path, json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n", parents=parents)


def staging_dir(out: Path, tag: str) -> Path:
    """A new empty directory beside ``out`` (created with its parents) to write the results into, with
    the permissions a plain mkdir would give; :func:`move_into_place` makes it ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.{tag}-p{os.getpid()}-", dir=out.parent))
    os.chmod(tmp, 0o777 & ~umask())  # mkdtemp makes it private
    return tmp


def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (another user's counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def recover_leftovers(out: Path) -> list[str]:
    """Tidy what killed runs left beside ``out`` (names carry the writer's pid: ``.OUT.TAG-pPID-...``; a
    live writer's are kept): a set-aside old ``out`` is renamed back when ``out`` is absent (a kill between
    the two renames of a replace), else deleted, and staging directories are deleted. Returns what was done."""
    done: list[str] = []
    try:
        entries = sorted(out.parent.iterdir()) if out.parent.is_dir() else []
    except OSError:
        return done
    for p in entries:
        m = _LEFTOVER.fullmatch(p.name)
        if not m or m["name"] != out.name or not p.is_dir() or p.is_symlink() or _pid_alive(int(m["pid"])):
            continue
        if m["old"] and not os.path.lexists(out):
            try:
                os.rename(p, out)
                done.append(f"recovered {out} from {p.name}")
            except OSError:
                pass
            continue
        shutil.rmtree(p, ignore_errors=True)
        if not os.path.lexists(p):
            done.append(f"deleted {p.name}")
    return done


def recover_leftovers_in(directory: Path) -> list[str]:
    """:func:`recover_leftovers` for every output in ``directory`` that killed runs left something beside
    (a batch's DIR/<id>/ of the jobs in flight when it was killed)."""
    try:
        names = {m["name"] for p in directory.iterdir() if (m := _LEFTOVER.fullmatch(p.name))}
    except OSError:
        return []
    return [line for name in sorted(names) for line in recover_leftovers(directory / name)]


#: A staging or set-aside directory's name: ``.OUT.TAG-pPID-XXXX`` or ``.OUT.TAG-old-pPID-XXXX``.
_LEFTOVER = re.compile(r"\.(?P<name>.+)\.[A-Za-z0-9-]+?(?P<old>-old)?-p(?P<pid>[0-9]{1,10})-[A-Za-z0-9_]+")


class PlaceError(OSError):
    """The staged results could not be moved into place (the message says which step failed)."""


def move_into_place(tmp: Path, out: Path, replace: bool, tag: str) -> Path | None:
    """Rename the staged ``tmp`` to ``out``; with ``replace`` the old ``out`` is renamed aside first (and
    back if the move fails) and deleted last. Returns the old directory if it could not be deleted."""
    if not replace:
        try:
            os.rename(tmp, out)
        except OSError as e:
            raise PlaceError(f"cannot move the results into place ({e.strerror or e})") from None
        return None
    aside = out.with_name(f".{out.name}.{tag}-old-p{os.getpid()}-{secrets.token_hex(4)}")
    try:
        os.rename(out, aside)
    except OSError as e:
        raise PlaceError(f"cannot move the old directory aside ({e.strerror or e})") from None
    try:
        os.rename(tmp, out)
    except OSError as e:
        os.rename(aside, out)
        raise PlaceError(f"cannot move the results into place ({e.strerror or e})") from None
    shutil.rmtree(aside, ignore_errors=True)
    return aside if os.path.lexists(aside) else None
