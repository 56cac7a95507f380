"""tools/check_wheel.py's checks on wheels made here: the platform tag's glibc, a stripped extension against
one with its symbol table, a glibc symbol newer than the limit, and a long description that is the
README. The extension is the one this test run imports (a release build with its symbol table)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tools"))
import check_wheel  # noqa: E402

pytest.importorskip("elftools", reason="pyelftools (pip install -r tools/wheel-requirements.txt)")

SHORT = "Metadata-Version: 2.4\nName: rtloop\nVersion: 0.1.0\nSummary: light from one photo\n\n# rtloop\n\nShort.\n"


@pytest.mark.parametrize(("tag", "glibc"), [("manylinux_2_28_x86_64", (2, 28)), ("manylinux_2_17_aarch64", (2, 17)),
                                            ("manylinux2014_x86_64", (2, 17)), ("manylinux1_x86_64", (2, 5)),
                                            ("linux_x86_64", None), ("musllinux_1_2_x86_64", None), ("any", None)])
def test_platform_glibc(tag, glibc):
    assert check_wheel.platform_glibc(tag) == glibc


@pytest.mark.parametrize(("name", "ok"), [
    ("rtloop-0.1.0-cp311-abi3-manylinux_2_28_x86_64.whl", True),
    ("rtloop-0.1.0-cp311-abi3-manylinux_2_17_x86_64.manylinux2014_x86_64.whl", True),
    ("rtloop-0.1.0-cp311-abi3-manylinux_2_34_x86_64.whl", False),
    ("rtloop-0.1.0-cp311-abi3-manylinux_2_17_x86_64.linux_x86_64.whl", False),
    ("rtloop-0.1.0-cp311-abi3-linux_x86_64.whl", False),
])
def test_check_tag(name, ok):
    assert (check_wheel.check_tag(name) == []) is ok


def test_a_file_name_that_is_no_wheel_is_refused():
    with pytest.raises(ValueError, match="not a wheel's file name"):
        check_wheel.wheel_tags("rtloop.whl")


def _extension(tmp: Path, strip: bool) -> bytes:
    from rtloop import _native

    lib = tmp / ("stripped.so" if strip else "as-built.so")
    shutil.copy(_native.__file__, lib)
    if strip:
        tool = shutil.which("strip")
        if tool is None:
            pytest.skip("no strip (binutils) to make a stripped copy")
        subprocess.run([tool, "--strip-all", str(lib)], check=True)
    return lib.read_bytes()


def _wheel(tmp: Path, name: str, so: bytes, metadata: str) -> str:
    path = tmp / name
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("rtloop/_native.abi3.so", so)
        z.writestr("rtloop-0.1.0.dist-info/METADATA", metadata)
    return str(path)


def test_a_stripped_extension_passes_and_one_with_its_symbol_table_fails(tmp_path):
    names, newest = check_wheel.elf_facts(_extension(tmp_path, strip=False))
    if ".symtab" not in names:
        pytest.skip("the extension this run imports is stripped already")
    as_built = _wheel(tmp_path, "a-0.1.0-cp311-abi3-manylinux_2_28_x86_64.whl", _extension(tmp_path, False), SHORT)
    fails = check_wheel.check_contents(as_built, max_glibc=(9, 99))
    assert len(fails) == 1 and "is not stripped: it has .symtab" in fails[0]
    stripped = _wheel(tmp_path, "b-0.1.0-cp311-abi3-manylinux_2_28_x86_64.whl", _extension(tmp_path, True), SHORT)
    assert check_wheel.check_contents(stripped, max_glibc=(9, 99)) == []


def test_a_glibc_symbol_newer_than_the_limit_fails(tmp_path):
    """The extension needs some GLIBC_2.x (memcpy, pthread ...): a limit below it fails, one at it passes."""
    so = _extension(tmp_path, strip=True)
    _, newest = check_wheel.elf_facts(so)
    assert newest is not None and newest >= (2, 2)
    assert check_wheel.check_elf("x.so", so, max_glibc=newest) == []
    fails = check_wheel.check_elf("x.so", so, max_glibc=(2, 1))
    assert fails == [f"x.so needs GLIBC_{newest[0]}.{newest[1]}, newer than 2.1"]


def test_the_readme_as_long_description_fails():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    whole = SHORT.split("\n\n")[0] + "\nDescription-Content-Type: text/markdown\n\n" + readme
    fails = check_wheel.check_metadata(whole, readme)
    assert any("characters" in f for f in fails) and any("is the README" in f for f in fails)
    assert check_wheel.check_metadata(SHORT, readme) == []
    assert check_wheel.check_metadata(SHORT.replace("Summary: light from one photo\n", ""), readme) == [
        "METADATA has no Summary"]
    assert check_wheel.check_metadata(SHORT, None) == []


def test_the_short_description_is_what_the_package_declares():
    """pyproject's readme is docs/pypi.md, short, and not the README."""
    import tomllib

    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    text = (REPO / project["readme"]).read_text(encoding="utf-8")
    assert project["readme"] != "README.md" and len(text) <= check_wheel.MAX_DESCRIPTION


def test_a_wheel_without_an_extension_fails(tmp_path):
    path = tmp_path / "rtloop-0.1.0-py3-none-any.whl"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("rtloop-0.1.0.dist-info/METADATA", SHORT)
    assert check_wheel.check_contents(str(path)) == ["no extension module (.so) in the wheel"]
    assert check_wheel.main([str(path), "--no-install"]) == 1
