"""Reading inputs and writing results safely: inputs read only from regular files of a bounded size (never a
FIFO or a device, which would hang or never end), atomic writes (a temporary file renamed into place), a
staged output directory moved into place whole (never over the inputs or the working directory), and
``jsonable`` (numpy values as plain JSON)."""

from __future__ import annotations

import json
import math
import os
import re
import secrets
import shutil
import stat
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from .errors import RtloopError

__all__ = ["MAX_IMAGE_BYTES", "MAX_TEXT_BYTES", "InputFileError", "OutputDirError", "PlaceError", "check_out_dir",
           "jsonable", "move_into_place", "open_regular", "read_regular", "recover_leftovers", "staging_dir", "umask",
           "write_bytes", "write_json", "write_text"]

#: The largest photo or mask file read (README: "Input limits"): a 100-megapixel camera's 16-bit TIFF fits.
MAX_IMAGE_BYTES = 1 << 30
#: The largest scene, objects, job or calibration file (JSON) read.
MAX_TEXT_BYTES = 64 << 20


class InputFileError(RtloopError):
    """An input that is not a regular file (a directory, a FIFO, a device), is missing or unreadable, or is
    larger than its limit. ``str()`` names the file; ``reason`` is the message without the name."""

    def __init__(self, name: str, reason: str):
        super().__init__(f"{name}: {reason}")
        self.name, self.reason = name, reason


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def _not_regular(name: str, mode: int, what: str) -> InputFileError:
    kind = next((k for test, k in _KINDS if test(mode)), "not a regular file")
    return InputFileError(name, f"is {kind}, not a regular file; give the {what} as a file")


def open_regular(path: str | os.PathLike[str], *, limit: int, what: str = "input") -> Any:
    """Open ``path`` for reading in binary if it is a regular file (after following links) of at most
    ``limit`` bytes; anything else raises :class:`InputFileError` before a byte is read. The file is opened
    without blocking (a FIFO swapped in after the check cannot hang the open) and checked again once open."""
    name = os.fspath(path)
    try:
        st = os.stat(name)
    except FileNotFoundError:
        raise InputFileError(name, f"no such file (the {what})") from None
    except (OSError, ValueError) as e:
        raise InputFileError(name, f"cannot read the {what} ({getattr(e, 'strerror', None) or e})") from None
    if not stat.S_ISREG(st.st_mode):
        raise _not_regular(name, st.st_mode, what)
    try:
        fd = os.open(name, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as e:
        raise InputFileError(name, f"cannot open the {what} ({e.strerror or e})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise _not_regular(name, st.st_mode, what)
        if st.st_size > limit:
            raise InputFileError(name, f"the {what} is {st.st_size} bytes, more than the {limit} read (the limit)")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: str | os.PathLike[str], *, limit: int, what: str = "input") -> bytes:
    """The bytes of the regular file ``path`` (see :func:`open_regular`), at most ``limit`` of them."""
    with open_regular(path, limit=limit, what=what) as fh:
        try:
            data = fh.read(limit + 1)
        except OSError as e:
            raise InputFileError(os.fspath(path), f"cannot read the {what} ({e.strerror or e})") from None
    if len(data) > limit:  # it grew since it was opened
        raise InputFileError(os.fspath(path), f"the {what} is more than the {limit} bytes read (the limit)")
    return data


class OutputDirError(RtloopError):
    """An output directory that cannot be (re)placed: a link, not a directory, the working directory or one
    above it, not empty without ``force``, or holding one of the inputs."""


def check_out_dir(out: Path, force: bool, inputs: list[Path]) -> bool:
    """Fail early (:class:`OutputDirError`) if ``out`` cannot be replaced whole by a command's results;
    True if something is there to replace at the end. Never the working directory or one above it, and with
    ``force`` never a directory holding one of ``inputs``."""
    if not os.path.lexists(out):
        return False
    if out.is_symlink():
        raise OutputDirError(f"{out}: is a symbolic link; give the directory it points to, or another name")
    if not out.is_dir():
        raise OutputDirError(f"{out}: exists and is not a directory")
    cwd = Path.cwd().resolve()
    resolved = out.resolve()
    if resolved == cwd or resolved in cwd.parents:
        raise OutputDirError(f"{out}: refusing to replace the current directory (or one above it)")
    try:
        empty = not any(out.iterdir())
    except OSError as e:
        raise OutputDirError(f"{out}: cannot read directory ({e.strerror or e})") from None
    if empty:
        return True
    if not force:
        raise OutputDirError(f"{out}: output directory exists and is not empty (use --force to replace it)")
    for p in inputs:
        if resolved in Path(p).resolve().parents:
            raise OutputDirError(f"{out}: refusing to replace it with --force: it contains {p}")
    return True


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
