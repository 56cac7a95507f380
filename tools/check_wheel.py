"""Check a built wheel before anyone installs it: its platform tag is manylinux for glibc 2.28 or older, its
extension modules ask for no newer glibc symbol and carry no symbol table or debug sections (stripped), its
METADATA's long description is short (not the whole README), and it installs into a fresh venv where
``import rtloop`` works (from outside the source tree).

    python3 tools/check_wheel.py dist/rtloop-*.whl [--max-glibc 2.28] [--no-install]

Prints one line per check ("ok: ..." or "FAIL: ..."); exits 1 if any failed. Reads ELF files with
pyelftools (installed with auditwheel: tools/wheel-requirements.txt). docs/development.md, "A wheel for
anyone"."""

from __future__ import annotations

import argparse
import email.parser
import io
import os
import re
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

#: The newest glibc the wheel may need: manylinux_2_28 (AlmaLinux 8, Debian 10, Ubuntu 18.10 and later).
MAX_GLIBC = (2, 28)
#: The legacy manylinux tags and the glibc each stands for (PEP 600).
LEGACY = {"manylinux1": (2, 5), "manylinux2010": (2, 12), "manylinux2014": (2, 17)}
#: A long description longer than this (characters) is not "short": the README is ten times that.
MAX_DESCRIPTION = 3000


def platform_glibc(tag: str) -> tuple[int, int] | None:
    """The glibc a platform tag promises (``manylinux_2_28_x86_64`` -> (2, 28), ``manylinux2014_x86_64``
    -> (2, 17)); None for a tag that promises none (``linux_x86_64``, ``win_amd64``, ``any``)."""
    m = re.fullmatch(r"manylinux_(\d+)_(\d+)_\w+", tag)
    if m:
        return int(m.group(1)), int(m.group(2))
    for legacy, glibc in LEGACY.items():
        if tag.startswith(legacy + "_"):
            return glibc
    return None


def wheel_tags(name: str) -> tuple[str, str, list[str]]:
    """(python tag, abi tag, platform tags) of a wheel's file name (PEP 427)."""
    parts = Path(name).name.removesuffix(".whl").split("-")
    if len(parts) not in (5, 6):
        raise ValueError(f"{name}: not a wheel's file name (name-version[-build]-python-abi-platform.whl)")
    return parts[-3], parts[-2], parts[-1].split(".")


def check_tag(name: str, max_glibc: tuple[int, int] = MAX_GLIBC) -> list[str]:
    """Failures of the file name's platform tags: each must be manylinux for ``max_glibc`` or older."""
    _, _, platforms = wheel_tags(name)
    fails = []
    for tag in platforms:
        glibc = platform_glibc(tag)
        if glibc is None:
            fails.append(f"platform tag {tag} is not manylinux: it installs only where it was built")
        elif glibc > max_glibc:
            fails.append(f"platform tag {tag} needs glibc {glibc[0]}.{glibc[1]}, newer than "
                         f"{max_glibc[0]}.{max_glibc[1]}")
    return fails


def elf_facts(data: bytes) -> tuple[list[str], tuple[int, int] | None]:
    """(section names, the newest GLIBC_x.y symbol version it needs, None if none) of an ELF file."""
    from elftools.elf.elffile import ELFFile
    from elftools.elf.gnuversions import GNUVerNeedSection

    elf = ELFFile(io.BytesIO(data))
    names = [s.name for s in elf.iter_sections()]
    newest: tuple[int, int] | None = None
    for section in elf.iter_sections():
        if not isinstance(section, GNUVerNeedSection):
            continue
        for _, auxes in section.iter_versions():
            for aux in auxes:
                m = re.fullmatch(r"GLIBC_(\d+)\.(\d+)(?:\.\d+)?", aux.name)
                if m:
                    v = (int(m.group(1)), int(m.group(2)))
                    newest = v if newest is None or v > newest else newest
    return names, newest


def check_elf(path: str, data: bytes, max_glibc: tuple[int, int] = MAX_GLIBC) -> list[str]:
    """Failures of one extension module: a symbol table or debug sections left in, or a glibc symbol newer
    than ``max_glibc``."""
    names, newest = elf_facts(data)
    fails = []
    unstripped = [n for n in names if n == ".symtab" or n.startswith((".debug", ".zdebug"))]
    if unstripped:
        fails.append(f"{path} is not stripped: it has {', '.join(unstripped)}")
    if newest is not None and newest > max_glibc:
        fails.append(f"{path} needs GLIBC_{newest[0]}.{newest[1]}, newer than {max_glibc[0]}.{max_glibc[1]}")
    return fails


def check_metadata(text: str, readme: str | None = None) -> list[str]:
    """Failures of a METADATA file: no summary, or a long description that is long (more than
    MAX_DESCRIPTION characters) or is the README (``readme``: its text)."""
    msg = email.parser.Parser().parsestr(text)
    body = msg.get_payload() or msg.get("Description") or ""
    fails = []
    if not (msg.get("Summary") or "").strip():
        fails.append("METADATA has no Summary")
    if len(body) > MAX_DESCRIPTION:
        fails.append(f"METADATA's long description is {len(body)} characters (at most {MAX_DESCRIPTION}): "
                     "the whole README?")
    if readme and readme.strip() and readme.strip()[:400] in body:
        fails.append("METADATA's long description is the README")
    return fails


def check_contents(wheel: str, readme: str | None = None, max_glibc: tuple[int, int] = MAX_GLIBC) -> list[str]:
    """Failures of what the wheel holds: its extension modules and its METADATA."""
    fails, modules = [], 0
    with zipfile.ZipFile(wheel) as z:
        for info in z.infolist():
            name = info.filename
            if name.endswith(".so") or ".so." in name:
                modules += 1
                fails += check_elf(name, z.read(info), max_glibc)
            elif re.fullmatch(r"[^/]+\.dist-info/METADATA", name):
                fails += check_metadata(z.read(info).decode("utf-8"), readme)
    if modules == 0:
        fails.append("no extension module (.so) in the wheel")
    return fails


def check_install(wheel: str, pip_args: list[str] | None = None) -> list[str]:
    """Failures of installing the wheel into a fresh venv and importing rtloop there (from a folder outside
    the source tree, so that the venv's copy is the one imported)."""
    with tempfile.TemporaryDirectory() as td:
        venv = Path(td) / "venv"
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        py = venv / "bin" / "python"
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
        pip = subprocess.run([str(py), "-m", "pip", "install", "-q", "--disable-pip-version-check",
                              *(pip_args or []), os.path.abspath(wheel)], env=env, capture_output=True, text=True)
        if pip.returncode != 0:
            return [f"pip install into a fresh venv failed: {pip.stderr.strip().splitlines()[-1:]}"]
        probe = ("import os, sys, rtloop; f = os.path.realpath(rtloop.__file__); "
                 "v = os.path.realpath(sys.prefix); print(f); sys.exit(0 if f.startswith(v + os.sep) else 3)")
        run = subprocess.run([str(py), "-c", probe], env=env, cwd=td, capture_output=True, text=True)
        if run.returncode == 3:
            return [f"import rtloop found {run.stdout.strip()}, not the venv's copy"]
        if run.returncode != 0:
            return [f"import rtloop failed in the fresh venv: {run.stderr.strip().splitlines()[-1:]}"]
    return []


def _version(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"(\d+)\.(\d+)", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected MAJOR.MINOR such as 2.28 (got {text!r})")
    return int(m.group(1)), int(m.group(2))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("wheel")
    ap.add_argument("--max-glibc", type=_version, default=MAX_GLIBC, metavar="X.Y",
                    help="the newest glibc the wheel may need (default 2.28)")
    ap.add_argument("--readme", type=Path, default=Path(__file__).resolve().parents[1] / "README.md",
                    help="the README the long description must not be (default: the repository's)")
    ap.add_argument("--no-install", action="store_true", help="skip the install into a fresh venv")
    ap.add_argument("--pip-arg", action="append", default=[], metavar="ARG",
                    help="an argument for pip install in the venv (repeat it), e.g. --pip-arg=--no-index")
    a = ap.parse_args(argv)
    readme = a.readme.read_text(encoding="utf-8") if a.readme.is_file() else None
    checks = [("tag", lambda: check_tag(a.wheel, a.max_glibc)),
              ("contents", lambda: check_contents(a.wheel, readme, a.max_glibc))]
    if not a.no_install:
        checks.append(("install", lambda: check_install(a.wheel, a.pip_arg)))
    failed = False
    for what, run in checks:
        try:
            fails = run()
        except (OSError, ValueError, zipfile.BadZipFile) as e:
            fails = [f"{a.wheel}: {e}"]
        for f in fails:
            print(f"FAIL: {what}: {f}")
        if not fails:
            print(f"ok: {what}")
        failed |= bool(fails)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
