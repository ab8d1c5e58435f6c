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


def load_script(path: Path, name: str):
    """Import the script at ``path`` as the module ``name`` (scripts are not a package; two
    studies' ``run.py`` get different names, so one test process can hold both)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def load_example(name: str):
    """Import ``examples/<name>.py`` as a module."""
    return load_script(EXAMPLES / f"{name}.py", name)


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


def random_rotation(seed: int = 0) -> np.ndarray:
    """A random proper rotation of R^3 (determinant +1), the same for a seed."""
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


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


# --------------------------------------------------------------------------- learning tasks


def generated_shape(kind: str, rng):
    """A randomly scaled, slightly noisy ellipsoid, torus, capsule or box (trimesh)."""
    import trimesh

    a = rng.uniform(0.7, 1.3, size=3)
    if kind == "ellipsoid":
        m = trimesh.creation.icosphere(subdivisions=2)
    elif kind == "torus":
        m = trimesh.creation.torus(
            major_radius=1.0, minor_radius=rng.uniform(0.3, 0.5), major_sections=24, minor_sections=12
        )
    elif kind == "capsule":
        m = trimesh.creation.capsule(height=rng.uniform(1.5, 2.5), radius=0.5, count=[16, 16])
    else:
        m = trimesh.creation.box(extents=a)
        m = m.subdivide().subdivide().subdivide()
    m.vertices = m.vertices * a
    m.vertices += rng.normal(scale=0.01, size=m.vertices.shape)
    return m


def generated_shapes_task(batch) -> tuple[list, list]:
    """Four classes of generated shapes, 8 each: 6 for training, 2 for testing. ``batch(v, f,
    label, dtype)`` makes one mesh's batch."""
    kinds = ["ellipsoid", "torus", "capsule", "box"]
    rng = np.random.default_rng(0)
    data = []
    for label, kind in enumerate(kinds):
        for _ in range(8):
            m = generated_shape(kind, rng)
            data.append(batch(m.vertices, m.faces, label, dtype=torch.float32))
    test = data[6::8] + data[7::8]
    train = [b for i, b in enumerate(data) if i % 8 < 6]
    return train, test


def psb_classes_task(batch) -> tuple[list, list]:
    """Four PSB classes (human, airplane, table, bird) with the file's split."""
    from torch_edgevf.learning import datasets

    with np.load(psb_file()) as data:  # each array read once, not once per mesh
        d = {name: data[name] for name in data.files}
    train, test = [], []
    for label, c in enumerate([0, 3, 7, 12]):
        for i in np.flatnonzero(d["labels"] == c):
            v, f = datasets.psb_mesh(d, i)
            v = v.astype(np.float64)
            (test if d["split"][i] else train).append(batch(v, f, label, dtype=torch.float32))
    return train, test


def train_classifier(net, train, epochs: int, seed: int = 0) -> None:
    """Adam at 1e-3, one mesh per step, the meshes in a seeded random order each epoch."""
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    g = torch.Generator().manual_seed(seed)
    for _ in range(epochs):
        for i in torch.randperm(len(train), generator=g).tolist():
            opt.zero_grad()
            torch.nn.functional.cross_entropy(net(train[i]), train[i].labels).backward()
            opt.step()


def classification_accuracy(net, batches) -> float:
    """The fraction of one-mesh batches whose label the network predicts (in evaluation mode)."""
    net.eval()
    with torch.no_grad():
        acc = np.mean([int(net(b).argmax(-1)) == int(b.labels) for b in batches])
    net.train()
    return float(acc)
