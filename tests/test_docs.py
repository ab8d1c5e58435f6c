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
* A block preceded by ``<!-- docs-test: needs MODULE ... -->`` uses an optional extra: it is
  skipped, saying why, where a module is not installed (and, for ``polyscope``, where
  polyscope cannot open a context: checked once, in a child process). A ``polyscope``
  block runs in a child process of its own (polyscope starts one back-end per process).
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
NEEDS_MARKER = re.compile(r"^<!-- docs-test: needs ([A-Za-z0-9_. ]+) -->$")
FENCE = re.compile(r"^```([A-Za-z]*)[^\n]*\n(.*?)^```\s*$", re.M | re.S)
SHELL = {"bash", "sh", "console", "shell"}


def code_blocks(path: Path):
    """``(language, code, line number, set-up marker before it)`` for each fenced block."""
    return [block[:4] for block in _code_blocks(path)]


def _code_blocks(path: Path):
    """:func:`code_blocks` and the modules a block needs (its ``needs`` marker)."""
    text = path.read_text()
    out = []
    for m in FENCE.finditer(text):
        before = text[: m.start()].rstrip().splitlines()
        last = before[-1].strip() if before else ""
        needs = NEEDS_MARKER.match(last)
        modules = tuple(needs.group(1).split()) if needs else ()
        line = text.count("\n", 0, m.start()) + 1
        out.append((m.group(1).lower(), m.group(2), line, last == SETUP_MARKER, modules))
    return out


def _blocks(languages):
    params = []
    for page in PAGES:
        for lang, code, line, marked, needs in _code_blocks(page):
            if lang in languages:
                rel = page.relative_to(ROOT)
                params.append(pytest.param(page, code, marked, needs, id=f"{rel}:{line}"))
    return params


_CONTEXT: dict[str, str | None] = {}


def skip_unless_available(modules) -> None:
    """Skip the test where a module of ``modules`` is not installed, or (``polyscope``)
    where polyscope cannot open a rendering context."""
    for module in modules:
        pytest.importorskip(module)
        if module == "polyscope":
            if "polyscope" not in _CONTEXT:
                probe = (
                    "import polyscope as ps; ps.set_use_prefs_file(False); "
                    "ps.set_allow_headless_backends(True); ps.init()"
                )
                run = subprocess.run(
                    [sys.executable, "-c", probe], capture_output=True, text=True, timeout=300
                )
                _CONTEXT["polyscope"] = None if run.returncode == 0 else (run.stdout + run.stderr)[-300:]
            if _CONTEXT["polyscope"] is not None:
                pytest.skip(f"polyscope cannot open a context here: {_CONTEXT['polyscope']}")


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
    if words and re.fullmatch(r"(\S*/)?edgevf", words[0]):
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


@pytest.mark.parametrize("page, code, marked, needs", _blocks({"python", "py"}))
def test_python_block(page, code, marked, needs, tmp_path, monkeypatch):
    skip_unless_available(needs)
    if "polyscope" in needs:  # one back-end per process, and settings files in its folder
        run = subprocess.run(
            [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600
        )
        assert run.returncode == 0, run.stderr[-3000:]
        return
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    torch.manual_seed(0)
    namespace = {"__name__": "__main__"}
    exec(compile(code, f"{page.name} block", "exec"), namespace)


@pytest.mark.parametrize("page, code, marked, needs", _blocks(SHELL))
def test_shell_block(page, code, marked, needs, tmp_path):
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


#: programs that the set-up installs into ``.venv``: a block calls them by their path
#: (``.venv/bin/edgevf``) unless it activates the environment first
VENV_PROGRAMS = ("edgevf", "pip", "pip3", "mkdocs", "pytest", "python")


@pytest.mark.parametrize("page, code, marked, needs", _blocks(SHELL))
def test_shell_blocks_call_the_programs_of_the_environment(page, code, marked, needs):
    """``edgevf info`` in a plain shell is "command not found": the set-up never activates
    ``.venv``, so a block names ``.venv/bin/edgevf`` (or activates the environment)."""
    commands = list(shell_commands(code))
    if any(c.startswith(("source .venv/bin/activate", ". .venv/bin/activate")) for c in commands):
        return
    bare = [c for c in commands if c.split(" ", 1)[0] in VENV_PROGRAMS]
    assert not bare, f"{page.name}: call these through .venv/bin/ (or activate .venv): {bare}"


def test_blocks_found():
    """The extraction sees the quick start first and the blocks of every page."""
    first = code_blocks(ROOT / "README.md")
    python = [code for lang, code, _, _ in first if lang == "python"]
    assert python and "backward()" in python[0] and "verts.grad" in python[0]
    assert all(lang in SHELL | {"python", "text", ""} for p in PAGES for lang, *_ in code_blocks(p))
    assert classify(".venv/bin/python -m pytest -q") == ("setup", None)
    assert classify("edgevf info bunny.obj") == ("run", ["info", "bunny.obj"])
    assert classify(".venv/bin/edgevf info bunny.obj") == ("run", ["info", "bunny.obj"])
    assert classify("rm -rf /") == ("unknown", None)
    assert NEEDS_MARKER.match("<!-- docs-test: needs torch_geometric polyscope -->").group(1).split() == [
        "torch_geometric",
        "polyscope",
    ]


#: the optional extras' modules: a block that imports one says so (``needs``), so that the
#: lanes without the extra skip it
OPTIONAL_MODULES = ("torch_geometric", "polyscope", "torch_edgevf.pyg", "torch_edgevf.render.polyscope")


def test_blocks_with_optional_modules_are_marked():
    bad = []
    for page in PAGES:
        for lang, code, line, _, needs in _code_blocks(page):
            if lang not in ("python", "py"):
                continue
            used = {
                m for m in OPTIONAL_MODULES if re.search(rf"^\s*(from|import) {re.escape(m)}\b", code, re.M)
            }
            top = {m.split(".")[-1] if m.startswith("torch_edgevf") else m for m in used}
            top = {"torch_geometric" if m == "pyg" else m for m in top}
            if not top <= set(needs):
                bad.append(f"{page.name}:{line} needs {sorted(top)}, marked {list(needs)}")
    assert not bad, bad


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


def test_the_readme_picture_is_the_demo_on_the_built_in_mesh():
    """The README's one picture is what the demo writes for the built-in mesh, and its
    caption names that mesh with its face count."""
    import torch_edgevf as ev

    text = (ROOT / "README.md").read_text()
    images = re.findall(r"!\[([^\]]*)\]\(([^)]+)\)", text)
    assert len(images) == 1
    caption, path = images[0]
    assert path == "docs/images/edgevf_demo.png" and (ROOT / path).is_file()
    faces = ev.default_mesh().faces.shape[0]
    assert f"built-in Spot ({faces:,} faces)" in caption
