"""Shared fixtures: small meshes with fixed seeds and the path of the shared real meshes."""

import os

# Small dense problems in the tests run far faster single-threaded, and busy-waiting
# OpenMP threads slow everything down on a shared 2-core machine.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
# Under pytest-xdist (the default run: ``-n auto``) each worker is one process per core:
# one thread each, so that the workers do not oversubscribe the cores.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("MKL_NUM_THREADS", "1")

if os.environ.get("EDGEVF_HIDE_CHOLMOD"):  # test the pip-only / cholespy / cvxopt back-ends in this process
    import sys

    sys.modules["sksparse"] = None
    sys.modules["sksparse.cholmod"] = None
if os.environ.get("EDGEVF_HIDE_CVXOPT"):  # cvxopt's bundled CHOLMOD never beside cholespy's
    import sys

    sys.modules["cvxopt"] = None
    sys.modules["cvxopt.cholmod"] = None

import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np
import pytest
import torch

import torch_edgevf as ev

if os.environ.get("PYTEST_XDIST_WORKER"):
    torch.set_num_threads(1)

#: the studies' tests: their own lane, collected only when named on the command line
#: (``pytest tests/experiments``), never by the default lane
EXPERIMENTS = Path(__file__).resolve().parent / "experiments"


def pytest_ignore_collect(collection_path, config):
    if collection_path != EXPERIMENTS:
        return None
    here = Path(config.invocation_params.dir)
    named = [(here / str(a).split("::")[0]).resolve() for a in config.args]
    return not any(p == EXPERIMENTS or EXPERIMENTS in p.parents for p in named)


#: the real meshes and the PSB file of the data tests (skipped where absent): the folder
#: ``$TORCH_EDGEVF_TEST_DATA``, else ``shared/`` beside the repository
SHARED = Path(os.environ.get("TORCH_EDGEVF_TEST_DATA") or Path(__file__).resolve().parents[2] / "shared")
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load_example(name: str):
    """Import ``examples/<name>.py`` as a module (the examples are scripts, not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def record_instances(monkeypatch, module, name: str) -> list:
    """Replace the class ``module.<name>`` by a subclass that records each instance made."""
    made = []
    base = getattr(module, name)

    class Recorded(base):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(module, name, Recorded)
    return made


def shared_path(*parts: str) -> Path:
    """``<parts>`` inside :data:`SHARED`, or skip the test saying why.

    The real meshes and the PSB file live outside the repository (``$TORCH_EDGEVF_TEST_DATA``
    or ``../shared``); the tests that need them are skipped, with the path, where that
    folder is absent.
    """
    path = SHARED.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} is not available (set $TORCH_EDGEVF_TEST_DATA to the shared data)")
    return path


def psb_file() -> Path:
    """``psb_watertight_2k.npz``: ``$TORCH_EDGEVF_PSB``, else ``datasets/`` in :data:`SHARED`; or skip."""
    env = os.environ.get("TORCH_EDGEVF_PSB")
    if env:
        if not Path(env).is_file():
            pytest.skip(f"TORCH_EDGEVF_PSB={env} is not a file")
        return Path(env)
    return shared_path("datasets", "psb_watertight_2k.npz")


@pytest.fixture
def psb(monkeypatch) -> Path:
    """The PSB file (skip without it), also set as ``$TORCH_EDGEVF_PSB`` for the test."""
    path = psb_file()
    monkeypatch.setenv("TORCH_EDGEVF_PSB", str(path))
    return path


def shared_mesh(name: str):
    """Load ``../shared/meshes/<name>`` (merged), or skip when the folder is absent."""
    path = shared_path("meshes", name)
    from torch_edgevf.io import load_mesh

    return load_mesh(path)


def perturbed_icosphere(level: int = 1, scale: float = 0.05, seed: int = 0, renumber: bool = True):
    """A noisy icosphere with randomly renumbered vertices (mixed edge orientations)."""
    v, f = ev.icosphere(level)
    g = torch.Generator().manual_seed(seed)
    v = v + scale * torch.randn(v.shape, generator=g, dtype=v.dtype)
    if renumber:
        perm = torch.randperm(v.shape[0], generator=g)
        inv = torch.empty_like(perm)
        inv[perm] = torch.arange(perm.numel())
        v, f = v[perm], inv[f]
    return v, f


def perturbed_grid(n: int = 4, scale: float = 0.05, seed: int = 0, flat: bool = False):
    """A noisy grid with boundary and randomly renumbered vertices."""
    v, f = ev.meshes.grid(n, n)
    g = torch.Generator().manual_seed(seed)
    noise = scale / n * torch.randn(v.shape, generator=g, dtype=v.dtype)
    if flat:
        noise[:, 2] = 0
    v = v + noise
    p = v[f]
    normal_z = torch.linalg.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 2]
    if flat:
        assert bool((normal_z > 0).all()), "perturbation too strong: a triangle flipped"
    perm = torch.randperm(v.shape[0], generator=g)
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(perm.numel())
    return v[perm], inv[f]


@pytest.fixture
def closed_mesh():
    return perturbed_icosphere(1, 0.05, seed=1)


@pytest.fixture
def open_mesh():
    return perturbed_grid(4, 0.3, seed=2)


def dense(a: torch.Tensor) -> np.ndarray:
    return a.detach().to_dense().numpy()


@pytest.fixture(params=["fast", pytest.param("full", marks=pytest.mark.slow)])
def gradcheck(request):
    """``torch.autograd.gradcheck`` in two lanes: the whole Jacobian in the slow lane, and in
    the default lane its fast mode, which compares the analytical and numerical Jacobians
    along random directions (``v^T J u``, real and imaginary parts for complex
    functions): the same identity, one projection instead of every entry."""
    fast = request.param == "fast"

    def check(fn, inputs, **kwargs):
        kwargs.setdefault("fast_mode", fast)
        return torch.autograd.gradcheck(fn, inputs, **kwargs)

    return check


def edgevf(*args, cwd=None, timeout=300) -> subprocess.CompletedProcess:
    """``python -m torch_edgevf ARGS`` in a subprocess (one BLAS thread), its output captured."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    return subprocess.run(
        [sys.executable, "-m", "torch_edgevf", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=timeout,
    )
