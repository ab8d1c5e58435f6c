"""Every code block of the README and of the documentation runs.

* Each ```python block is executed in a fresh namespace, in a temporary working directory.
* Each line of a ```bash, ```sh or ```console block (a leading ``$ `` prompt is dropped;
  ``a && b`` is split into its commands) is classified:
  - an ``edgevf ...`` command of this package, or ``python -m torch_edgevf`` (the demo), is
    run as a subprocess in that block's temporary directory, in order, and must exit 0;
  - a set-up command (creating a virtual environment, ``pip install``, ``export``, running
    the test suite itself or the documentation build, which ``test_docs_build_strict`` runs)
    is not run: it installs or runs what this test already runs in;
  - anything else fails the test, so that a new kind of command is either run here or
    recognised as set-up on purpose.
  A block preceded by ``<!-- docs-test: setup -->`` is skipped as a whole; the test checks
  that every line of such a block is a set-up command.
* ``mkdocs build --strict`` builds the site (slow lane), and fails on a broken link.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SETUP_MARKER = "<!-- docs-test: setup -->"
FENCE = re.compile(r"^```([A-Za-z]*)[^\n]*\n(.*?)^```\s*$", re.M | re.S)
SHELL = {"bash", "sh", "console", "shell"}


def code_blocks(path: Path):
    """``(language, code, line number, set-up marker before it)`` for each fenced block."""
    text = path.read_text()
    out = []
    for m in FENCE.finditer(text):
        before = text[: m.start()].rstrip().splitlines()
        marked = bool(before) and before[-1].strip() == SETUP_MARKER
        out.append((m.group(1).lower(), m.group(2), text.count("\n", 0, m.start()) + 1, marked))
    return out


def _blocks(languages):
    params = []
    for page in PAGES:
        for lang, code, line, marked in code_blocks(page):
            if lang in languages:
                rel = page.relative_to(ROOT)
                params.append(pytest.param(page, code, marked, id=f"{rel}:{line}"))
    return params


SETUP = [
    re.compile(r"^python3? -m venv\b"),
    re.compile(r"^(\S*/)?pip3? install\b"),
    re.compile(r"^export [A-Za-z_][A-Za-z0-9_]*="),
    re.compile(r"^(\S*/)?python3? -m pytest\b"),  # the test suite: this run
    re.compile(r"^(\S*/)?mkdocs (build|serve)\b"),  # test_docs_build_strict
]


def classify(command: str):
    """``("run", argv)`` for a command of this package, ``("setup", None)``, or ``("unknown", None)``."""
    command = command.split(" #", 1)[0].strip()
    if any(p.match(command) for p in SETUP):
        return "setup", None
    words = shlex.split(command)
    if words and words[0] == "edgevf":
        return "run", words[1:]
    if (
        len(words) >= 3
        and re.fullmatch(r"(\S*/)?python3?", words[0])
        and words[1:3] == ["-m", "torch_edgevf"]
    ):
        return "run", words[3:] or ["demo"]
    return "unknown", None


def shell_commands(code: str):
    for line in code.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith("$ "):
            line = line[2:]
        for part in line.split("&&"):
            yield part.strip()


def write_fake_psb(folder: Path, per_class: int = 1) -> None:
    """A tiny stand-in for the benchmark's ``data`` folder: ``off/<id>.off`` icospheres."""
    import numpy as np

    import torch_edgevf as ev

    (folder / "off").mkdir(parents=True, exist_ok=True)
    verts, faces = ev.icosphere(1)
    ids = [k * 20 + 1 + j for k in (0, 1) for j in range(per_class)]
    for i in ids:
        v = verts.numpy() * (1 + 0.1 * i) + np.array([i, 0.0, 0.0])
        lines = ["OFF", f"{len(v)} {len(faces)} 0"]
        lines += [" ".join(f"{x:.9g}" for x in p) for p in v]
        lines += ["3 " + " ".join(str(int(k)) for k in f) for f in faces]
        (folder / "off" / f"{i}.off").write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("page, code, marked", _blocks({"python", "py"}))
def test_python_block(page, code, marked, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    torch.manual_seed(0)
    namespace = {"__name__": "__main__"}
    exec(compile(code, f"{page.name} block", "exec"), namespace)


@pytest.mark.parametrize("page, code, marked", _blocks(SHELL))
def test_shell_block(page, code, marked, tmp_path):
    commands = [(c, *classify(c)) for c in shell_commands(code)]
    unknown = [c for c, kind, _ in commands if kind == "unknown"]
    assert not unknown, f"commands neither run nor set-up (see this test's docstring): {unknown}"
    if marked:
        assert all(kind == "setup" for _, kind, _ in commands), "only set-up blocks may opt out"
        return
    write_fake_psb(tmp_path / "psb")
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(ROOT))
    for command, kind, argv in commands:
        if kind != "run":
            continue
        result = subprocess.run(
            [sys.executable, "-m", "torch_edgevf", *argv],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert result.returncode == 0, f"{command!r} exited {result.returncode}:\n{result.stderr[-2000:]}"


def test_blocks_found():
    """The extraction sees the quick start first and the blocks of every page."""
    first = code_blocks(ROOT / "README.md")
    python = [code for lang, code, _, _ in first if lang == "python"]
    assert python and "backward()" in python[0] and "verts.grad" in python[0]
    assert all(lang in SHELL | {"python", "text", ""} for p in PAGES for lang, *_ in code_blocks(p))
    assert classify(".venv/bin/python -m pytest -q") == ("setup", None)
    assert classify("edgevf info bunny.obj") == ("run", ["info", "bunny.obj"])
    assert classify("rm -rf /") == ("unknown", None)


def _mkdocs(root: Path) -> subprocess.CompletedProcess:
    # no -q: mkdocs counts for --strict only the warnings it logs, and -q logs none
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(root / "site")],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=600,
        env=dict(os.environ, PYTHONPATH=str(ROOT), NO_MKDOCS_2_WARNING="1"),
    )


@pytest.mark.slow
def test_docs_build_strict(tmp_path):
    """``mkdocs build --strict`` succeeds, and the same build with a broken link fails."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    for name in ("docs", "mkdocs.yml"):
        src = ROOT / name
        (shutil.copytree if src.is_dir() else shutil.copy)(src, tmp_path / name)
    good = _mkdocs(tmp_path)
    assert good.returncode == 0, good.stderr[-3000:]
    with open(tmp_path / "docs" / "index.md", "a") as page:
        page.write("\nSee [a page that does not exist](missing.md).\n")
    bad = _mkdocs(tmp_path)
    assert bad.returncode != 0 and "missing.md" in bad.stderr, bad.stderr[-3000:]
