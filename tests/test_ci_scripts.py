"""The CI's helper scripts, run against a stand-in cargo in a copy of the repository's layout."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

FAKE_CARGO = """#!/bin/sh
# Records where it was asked to build, and "builds" there.
out="${CARGO_TARGET_DIR:-target}"
mkdir -p "$out/debug"
printf 'hooks built in %s' "$out" > "$out/debug/librtloop.so"
"""


@pytest.fixture
def layout(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    repo = tmp_path / "repo"
    (repo / ".ci").mkdir(parents=True)
    shutil.copy2(REPO / ".ci" / "build-test-hooks", repo / ".ci" / "build-test-hooks")
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    cargo = bin_dir / "cargo"
    cargo.write_text(FAKE_CARGO)
    cargo.chmod(0o755)
    env = {k: v for k, v in os.environ.items() if k != "CARGO_TARGET_DIR"}
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    return repo, env


pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="a bash script")


def hooks(repo: Path) -> str:
    return (repo / "target" / "test-hooks" / "_rtloop_test_hooks.abi3.so").read_text()


def test_build_test_hooks_uses_target_by_default(layout):
    repo, env = layout
    subprocess.run([str(repo / ".ci" / "build-test-hooks")], env=env, check=True, cwd=repo.parent)
    assert hooks(repo) == "hooks built in target"


@pytest.mark.parametrize("relative", [False, True])
def test_build_test_hooks_follows_cargo_target_dir(layout, tmp_path, relative):
    """With CARGO_TARGET_DIR set cargo builds there: the script takes the library from there (a relative
    directory from where it was run), and still puts it where the tests load it."""
    repo, env = layout
    elsewhere = tmp_path / "cargo-out"
    env["CARGO_TARGET_DIR"] = "cargo-out" if relative else str(elsewhere)
    subprocess.run([str(repo / ".ci" / "build-test-hooks")], env=env, check=True, cwd=tmp_path)
    assert hooks(repo) == f"hooks built in {elsewhere}"
    assert not (repo / "target" / "debug").exists()
