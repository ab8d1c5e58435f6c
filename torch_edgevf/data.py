"""Data for learning on meshes: per-mesh operators, an on-disk cache, batching, PSB.

* :class:`MeshOperators` holds what the networks of :mod:`torch_edgevf.models` need for
  one mesh (``M_z``, ``G``, ``L_c``, eigenpairs, ...), computed by
  :func:`compute_operators`.
* :class:`OperatorCache` stores them on disk, keyed by the topology, the float64
  positions, the options and the package version; entries are written atomically and
  verified when read (a corrupt or stale entry is rebuilt, with a logged warning). Never
  pickled: ``np.savez`` and ``np.load(allow_pickle=False)``.
* :func:`collate_meshes` batches meshes of different sizes: features are concatenated,
  indices offset, sparse operators made block diagonal, with batch index vectors; it is
  the ``collate_fn`` of a ``DataLoader`` (worker processes included).
* :class:`PSBDataset` reads the Princeton Segmentation Benchmark file
  ``psb_watertight_2k.npz`` with its fixed train/test split.
* :func:`progress` is a progress bar (tqdm when installed) that is silent when stderr is
  not a terminal, and under pytest.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import sys
import tempfile
import zipfile
import zlib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import torch

from . import operators as ops
from ._validation import as_faces, as_verts
from .geometry import face_areas, face_normals
from .topology import Topology

logger = logging.getLogger(__name__)

__all__ = [
    "MeshOperators",
    "compute_operators",
    "heat_kernel_signature",
    "vertex_gradient_operator",
    "OperatorCache",
    "MeshSample",
    "MeshBatch",
    "collate_meshes",
    "progress",
    "PSBDataset",
    "find_degenerate_faces",
    "repair_degenerate_faces",
    "DEFAULT_PSB_PATH",
]

DEFAULT_PSB_PATH = Path("/work/shared/datasets/psb_watertight_2k.npz")
_SPARSE_FIELDS = ("gradient", "connection_laplacian", "vertex_gradient")


# --------------------------------------------------------------------------- progress


def _progress_enabled(enabled: bool | None) -> bool:
    if enabled is not None:
        return bool(enabled)
    if "PYTEST_CURRENT_TEST" in os.environ:
        return False
    return bool(getattr(sys.stderr, "isatty", lambda: False)())


class _SimpleBar:
    """A minimal stderr progress bar (used when tqdm is not installed)."""

    def __init__(self, iterable, total, desc):
        self.iterable, self.total, self.desc = iterable, total, desc

    def __iter__(self):
        total = self.total
        for i, item in enumerate(self.iterable, 1):
            yield item
            shown = f"{i}/{total}" if total else str(i)
            sys.stderr.write(f"\r{self.desc}: {shown}")
            sys.stderr.flush()
        sys.stderr.write("\n")
        sys.stderr.flush()


def progress(iterable: Iterable, total: int | None = None, desc: str = "", enabled: bool | None = None):
    """Wrap ``iterable`` in a progress bar on stderr.

    Uses ``tqdm`` when it is installed, else a small built-in bar. ``enabled=None``
    (default) shows it only when stderr is a terminal and not under pytest.
    """
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)
    if not _progress_enabled(enabled):
        return iterable
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return _SimpleBar(iterable, total, desc)
    return tqdm(iterable, total=total, desc=desc, file=sys.stderr)


# --------------------------------------------------------------------------- operators


@dataclass
class MeshOperators:
    """The operators of one mesh used by the learning layers.

    Attributes
    ----------
    verts : (V, 3) float tensor
    faces : (F, 3) int64 tensor
    edges : (E, 2) int64 tensor, ``i < j``
    face_edges : (F, 3) int64 tensor, the edge opposite each corner
    edge_mass : (E,) real, the diagonal of ``M_z``
    vertex_mass : (V,) real, lumped vertex masses
    face_area : (F,) real
    gradient : (E, V) complex sparse ``G``
    connection_laplacian : (E, E) sparse ``L_c^(n)``
    edge_evals, edge_evecs : (k_e,), (E, k_e)
        Smallest eigenpairs of ``(L_c^(n), M_z)``, ``Phi^H M_z Phi = I``.
    vertex_evals, vertex_evecs : (k_v,), (V, k_v)
        Smallest eigenpairs of a vertex Laplacian with the lumped mass (see
        :func:`compute_operators`), ``Phi^T M_v Phi = I``.
    vertex_gradient : (V, V) complex sparse or None
        Least-squares tangent-plane vertex gradient (the DiffusionNet-style baseline).
    n : int
    """

    verts: torch.Tensor
    faces: torch.Tensor
    edges: torch.Tensor
    face_edges: torch.Tensor
    edge_mass: torch.Tensor
    vertex_mass: torch.Tensor
    face_area: torch.Tensor
    gradient: torch.Tensor
    connection_laplacian: torch.Tensor
    edge_evals: torch.Tensor
    edge_evecs: torch.Tensor
    vertex_evals: torch.Tensor
    vertex_evecs: torch.Tensor
    vertex_gradient: torch.Tensor | None = None
    n: int = 1

    @property
    def num_vertices(self) -> int:
        return int(self.verts.shape[0])

    @property
    def num_edges(self) -> int:
        return int(self.edges.shape[0])

    @property
    def num_faces(self) -> int:
        return int(self.faces.shape[0])

    def to(self, dtype: torch.dtype) -> "MeshOperators":
        """A copy with real tensors in ``dtype`` and complex ones in the matching complex dtype."""
        return MeshOperators(**{f.name: _convert(getattr(self, f.name), dtype) for f in fields(self)})

    def check(self) -> None:
        """Raise ``ValueError`` if the shapes are inconsistent."""
        V, E, F = self.num_vertices, self.num_edges, self.num_faces
        expect = {
            "verts": (V, 3), "faces": (F, 3), "edges": (E, 2), "face_edges": (F, 3), "edge_mass": (E,),
            "vertex_mass": (V,), "face_area": (F,), "gradient": (E, V), "connection_laplacian": (E, E),
            "edge_evals": (self.edge_evals.shape[0],), "edge_evecs": (E, self.edge_evals.shape[0]),
            "vertex_evals": (self.vertex_evals.shape[0],), "vertex_evecs": (V, self.vertex_evals.shape[0]),
        }
        if self.vertex_gradient is not None:
            expect["vertex_gradient"] = (V, V)
        for name, shape in expect.items():
            got = tuple(getattr(self, name).shape)
            if got != shape:
                raise ValueError(f"MeshOperators.{name} has shape {got}, expected {shape}")
        if int(self.faces.max()) >= V or int(self.edges.max()) >= V or int(self.face_edges.max()) >= E:
            raise ValueError("MeshOperators has out-of-range indices")


def _convert(x, dtype: torch.dtype):
    if not isinstance(x, torch.Tensor):
        return x
    if x.is_complex():
        return x.to({torch.float32: torch.complex64, torch.float64: torch.complex128}[dtype])
    if x.is_floating_point():
        return x.to(dtype)
    return x


def _scipy(a: torch.Tensor) -> sp.csc_matrix:
    a = a.coalesce()
    i = a.indices().numpy()
    return sp.csc_matrix((a.values().detach().resolve_conj().numpy(), (i[0], i[1])), shape=tuple(a.shape))


def _single_threaded_blas():
    """Limit BLAS to one thread if threadpoolctl is installed (else a no-op context).

    ARPACK's complex iteration makes many small BLAS calls; with a multi-threaded
    OpenBLAS on a busy machine each call can wait for its threads, which measured 15x
    slower than single-threaded here.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def _smallest_eigenpairs(A: sp.spmatrix, mass: np.ndarray, k: int, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """``k`` smallest eigenpairs of ``A x = lambda diag(mass) x``, ``X^H M X = I``.

    Shift-invert ARPACK on the symmetrised ``M^{-1/2} A M^{-1/2}`` (fast for the
    precomputation; no gradients are needed here), dense for small matrices.
    """
    with _single_threaded_blas():
        return _smallest_eigenpairs_impl(A, mass, k, tol)


def _smallest_eigenpairs_impl(A: sp.spmatrix, mass: np.ndarray, k: int, tol: float):
    n = A.shape[0]
    s = 1.0 / np.sqrt(mass)
    B = (sp.diags(s) @ A @ sp.diags(s)).tocsc()
    if n <= 400 or k >= n - 1:
        import scipy.linalg

        w, Y = scipy.linalg.eigh(B.toarray())
        w, Y = w[:k], Y[:, :k]
    else:
        # a shift just below 0, on the scale of typical entries: the max would put it far below the
        # wanted eigenvalues on meshes with slivers (huge cotangents) and stall ARPACK
        sigma = -1e-6 * float(np.median(np.abs(B.diagonal())))
        ncv = min(n - 1, max(2 * k + 1, 40))  # ARPACK's default 2k+1 restarts endlessly for small k
        w, Y = sla.eigsh(B, k=k, sigma=sigma, which="LM", tol=tol, ncv=ncv, v0=np.ones(n, dtype=B.dtype))
        order = np.argsort(w)
        w, Y = w[order], Y[:, order]
    return np.maximum(w, 0.0), Y * s[:, None]


def vertex_gradient_operator(verts, faces) -> torch.Tensor:
    r"""Least-squares tangent-plane gradient at vertices, complex (the DiffusionNet scheme).

    Each vertex gets a tangent frame ``(x_i, y_i)`` (``x_i`` the projection of its first
    neighbouring edge on the plane normal to the area-weighted vertex normal); the
    gradient :math:`g_i = g_x + \imath g_y` minimises
    :math:`\sum_{j \sim i} (g \cdot a_{ij} - (f_j - f_i))^2` over the neighbours, with
    :math:`a_{ij}` the tangent coordinates of :math:`v_j - v_i`. The frame is arbitrary per
    vertex, so only gauge-invariant features (``|g|``, ``Re(g conj(A g))``) are meaningful.

    Returns
    -------
    (V, V) complex sparse tensor ``D`` with ``g = D f``.
    """
    verts = as_verts(verts).detach()
    topo = faces if isinstance(faces, Topology) else Topology(faces, num_vertices=verts.shape[0])
    v = verts.to(torch.float64).numpy()
    f = topo.faces.numpy()
    e = topo.edges.numpy()
    fn = face_normals(verts.to(torch.float64), topo).numpy() * face_areas(verts.to(torch.float64), topo).numpy()[:, None]
    normal = np.zeros_like(v)
    np.add.at(normal, f.ravel(), np.repeat(fn, 3, axis=0))
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    order = np.lexsort((dst, src))
    src, dst = src[order], dst[order]
    d = v[dst] - v[src]
    first = np.zeros(v.shape[0], dtype=np.int64)
    first[src[::-1]] = np.arange(src.shape[0])[::-1]  # first outgoing edge of each vertex
    x = d[first] - (d[first] * normal).sum(1, keepdims=True) * normal
    x /= np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)
    y = np.cross(normal, x)
    a = np.stack([(d * x[src]).sum(1), (d * y[src]).sum(1)], axis=1)  # (2E, 2)
    N = np.zeros((v.shape[0], 2, 2))
    np.add.at(N, src, a[:, :, None] * a[:, None, :])
    scale = np.trace(N, axis1=1, axis2=2)[:, None, None]
    N += 1e-8 * scale * np.eye(2)
    c = np.einsum("eij,ej->ei", np.linalg.inv(N)[src], a)
    cz = c[:, 0] + 1j * c[:, 1]
    rows = np.concatenate([src, src])
    cols = np.concatenate([dst, src])
    vals = np.concatenate([cz, -cz])
    D = sp.coo_matrix((vals, (rows, cols)), shape=(v.shape[0],) * 2).tocsr().tocoo()
    cdtype = torch.complex128 if verts.dtype == torch.float64 else torch.complex64
    idx = torch.from_numpy(np.stack([D.row, D.col]).astype(np.int64))
    return torch.sparse_coo_tensor(idx, torch.from_numpy(D.data).to(cdtype), D.shape,
                                   check_invariants=False).coalesce()


def compute_operators(verts, faces, n: int = 1, k_edge: int = 32, k_vertex: int = 32,
                      vertex_laplacian: str = "cotan", vertex_gradient: bool = False,
                      tol: float = 1e-8) -> MeshOperators:
    """Compute the :class:`MeshOperators` of a mesh, in float64.

    Parameters
    ----------
    verts : (V, 3) float tensor or array
    faces : (F, 3) int tensor or array, or a Topology
    n : int >= 1, symmetry order of ``L_c``
    k_edge, k_vertex : int, numbers of eigenpairs of ``(L_c, M_z)`` and of the vertex
        Laplacian (with the lumped vertex mass)
    vertex_laplacian : {"cotan", "edge"}
        ``"cotan"``: cotangent Laplacian (DiffusionNet, and the input features);
        ``"edge"``: ``L = G^* M_z^{-1} G`` of thesis 4.2.
    vertex_gradient : bool
        Also compute :func:`vertex_gradient_operator` (for the baseline).
    tol : float, ARPACK tolerance of the eigenpairs.
    """
    if vertex_laplacian not in ("cotan", "edge"):
        raise ValueError(f"vertex_laplacian must be 'cotan' or 'edge', got {vertex_laplacian!r}")
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    verts = as_verts(verts).detach().to(torch.float64)
    topo = faces if isinstance(faces, Topology) else Topology(faces, num_vertices=verts.shape[0])
    ne, nv = topo.num_edges, topo.num_vertices
    for name, k, size in (("k_edge", k_edge, ne), ("k_vertex", k_vertex, nv)):
        if not isinstance(k, int) or not 1 <= k < size:
            raise ValueError(f"{name} must be an integer in [1, {size - 1}], got {k!r}")
    edge_mass = ops.mass_matrix(verts, topo).values()
    Lc = ops.connection_laplacian(verts, topo, n)
    ew, ev = _smallest_eigenpairs(_scipy(Lc), edge_mass.numpy(), k_edge, tol)
    vmass = ops.vertex_mass(verts, topo, lumped=True).values()
    Lv = ops.cotan_laplacian(verts, topo) if vertex_laplacian == "cotan" else ops.laplace_beltrami(verts, topo)
    vw, vv = _smallest_eigenpairs(_scipy(Lv), vmass.numpy(), k_vertex, tol)
    vv = vv.real
    # a deterministic sign per vertex eigenvector (the models only use sign-invariant quantities)
    vv = vv * np.where(vv[np.abs(vv).argmax(0), np.arange(vv.shape[1])] < 0, -1.0, 1.0)
    out = MeshOperators(
        verts=verts, faces=topo.faces.clone(), edges=topo.edges.clone(), face_edges=topo.face_edges.clone(),
        edge_mass=edge_mass, vertex_mass=vmass, face_area=face_areas(verts, topo),
        gradient=ops.gradient(verts, topo).coalesce(), connection_laplacian=Lc.coalesce(),
        edge_evals=torch.from_numpy(ew), edge_evecs=torch.from_numpy(np.ascontiguousarray(ev)),
        vertex_evals=torch.from_numpy(vw), vertex_evecs=torch.from_numpy(np.ascontiguousarray(vv)),
        vertex_gradient=vertex_gradient_operator(verts, topo) if vertex_gradient else None, n=n,
    )
    return out


def heat_kernel_signature(evals, evecs, times=None, count: int = 16, area=None) -> torch.Tensor:
    r"""Heat kernel signature per vertex, scale normalised (intrinsic input features).

    .. math::  h(x, t) = A \sum_i e^{-\lambda_i A t} \phi_i(x)^2

    with ``A`` the total area (so the features of a mesh and of a scaled copy agree),
    :math:`\phi_i` ``M_v``-orthonormal. Invariant to rigid motions, to the numbering
    and to the sign of each eigenvector.

    Parameters
    ----------
    evals : (k,) real tensor
    evecs : (V, k) real tensor
    times : (T,) tensor, default ``logspace(-2, 0, count)``
    area : float or tensor, total surface area (default 1)

    Returns
    -------
    (V, T) tensor.
    """
    if evecs.dim() != 2 or evals.shape != (evecs.shape[1],):
        raise ValueError(f"evals (k,) and evecs (V, k) do not match: {tuple(evals.shape)}, {tuple(evecs.shape)}")
    if times is None:
        times = torch.logspace(-2, 0, count, dtype=evals.dtype)
    area = torch.as_tensor(1.0 if area is None else area, dtype=evals.dtype)
    weights = torch.exp(-evals[None, :] * area * times.to(evals.dtype)[:, None])  # (T, k)
    return area * (evecs ** 2) @ weights.transpose(0, 1)


# --------------------------------------------------------------------------- cache


def _sha256(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


def _to_arrays(o: MeshOperators) -> dict:
    arrays = {}
    for f in fields(o):
        x = getattr(o, f.name)
        if f.name == "n":
            arrays["n"] = np.asarray(x, dtype=np.int64)
        elif x is None:
            continue
        elif f.name in _SPARSE_FIELDS:
            x = x.coalesce()
            arrays[f"{f.name}.indices"] = x.indices().numpy()
            arrays[f"{f.name}.values"] = x.values().detach().resolve_conj().numpy()
            arrays[f"{f.name}.shape"] = np.asarray(x.shape, dtype=np.int64)
        else:
            arrays[f.name] = x.detach().resolve_conj().numpy()
    return arrays


def _from_arrays(arrays: dict) -> MeshOperators:
    kwargs = {}
    for f in fields(MeshOperators):
        if f.name == "n":
            kwargs["n"] = int(arrays["n"])
        elif f.name in _SPARSE_FIELDS:
            if f"{f.name}.indices" not in arrays:
                if f.name == "vertex_gradient":
                    kwargs[f.name] = None
                    continue
                raise KeyError(f"{f.name}.indices")
            idx = torch.from_numpy(arrays[f"{f.name}.indices"].astype(np.int64))
            shape = tuple(int(s) for s in arrays[f"{f.name}.shape"])
            if idx.dim() != 2 or idx.shape[0] != 2 or (idx.numel() and (idx.min() < 0 or idx[0].max() >= shape[0]
                                                                        or idx[1].max() >= shape[1])):
                raise ValueError(f"{f.name}: indices out of range")
            kwargs[f.name] = torch.sparse_coo_tensor(idx, torch.from_numpy(arrays[f"{f.name}.values"]), shape,
                                                     check_invariants=False).coalesce()
        else:
            kwargs[f.name] = torch.from_numpy(arrays[f.name])
    return MeshOperators(**kwargs)


def _content_hash(arrays: dict) -> str:
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _version() -> str:
    import torch_edgevf

    return str(torch_edgevf.__version__)


class OperatorCache:
    """On-disk cache of :class:`MeshOperators`.

    An entry is keyed by the SHA-256 of the faces (int64 bytes), of the positions
    (float64 bytes), by the options of :func:`compute_operators` and by the package
    version. The file name derives from the first three; the full key (with the
    version) and a SHA-256 of the content are stored inside, and checked when the entry
    is read, together with the shapes. A file that cannot be read, whose content hash
    or key does not match (another version, a collision), or whose shapes are
    inconsistent is logged as a warning and rebuilt. Files are written to a temporary
    file in the same folder and moved into place with ``os.replace``, so readers never
    see half-written entries. Pickle is never used.

    Parameters
    ----------
    root : path, created if needed.
    """

    def __init__(self, root):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    @staticmethod
    def key(verts, faces, **options) -> dict:
        """The cache key of a mesh and options (JSON-serialisable dict)."""
        v = as_verts(verts).detach().to(torch.float64).cpu().numpy()
        f = (faces.faces if isinstance(faces, Topology) else as_faces(faces)).cpu().numpy().astype(np.int64)
        return {"faces": _sha256(f), "verts": _sha256(v), "options": {k: options[k] for k in sorted(options)},
                "version": _version()}

    def path(self, key: dict) -> Path:
        """File of an entry: from the mesh hashes and options (not the version)."""
        stem = {k: key[k] for k in ("faces", "verts", "options")}
        return self.root / (hashlib.sha256(json.dumps(stem, sort_keys=True).encode()).hexdigest()[:40] + ".npz")

    def load(self, key: dict) -> MeshOperators | None:
        """The verified entry for ``key``, or None (missing, or invalid: logged)."""
        path = self.path(key)
        if not path.exists():
            return None
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files}
            stored_key = json.loads(str(arrays.pop("__key__")))
            stored_hash = str(arrays.pop("__hash__"))
            if stored_hash != _content_hash(arrays):
                raise ValueError("content hash mismatch (corrupt file)")
            if stored_key != key:
                diff = [k for k in key if stored_key.get(k) != key[k]]
                raise ValueError(f"key mismatch in {diff} (stored version {stored_key.get('version')!r})")
            out = _from_arrays(arrays)
            out.check()
            return out
        except (OSError, ValueError, KeyError, EOFError, TypeError, zipfile.BadZipFile, zlib.error) as exc:
            logger.warning("operator cache entry %s is invalid (%s: %s); rebuilding it", path.name,
                           type(exc).__name__, exc)
            return None

    def save(self, key: dict, operators: MeshOperators) -> Path:
        """Write an entry atomically; returns its path."""
        arrays = _to_arrays(operators)
        arrays["__hash__"] = np.asarray(_content_hash(arrays))
        arrays["__key__"] = np.asarray(json.dumps(key, sort_keys=True))
        path = self.path(key)
        fd, tmp = tempfile.mkstemp(dir=self.root, prefix=path.stem, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, **arrays)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
        return path

    def get(self, verts, faces, **options) -> MeshOperators:
        """Load the entry of a mesh, or compute (:func:`compute_operators`) and store it."""
        key = self.key(verts, faces, **options)
        out = self.load(key)
        if out is None:
            out = compute_operators(verts, faces, **options)
            self.save(key, out)
        return out


# --------------------------------------------------------------------------- batching


@dataclass
class MeshSample:
    """One item of a mesh dataset: operators, vertex features ``(V, C)`` and a label.

    ``label`` is an int (whole-shape), or a ``(V,)`` / ``(F,)`` int tensor (segmentation).
    """

    operators: MeshOperators
    features: torch.Tensor
    label: int | torch.Tensor | None = None
    index: int = -1


def _block_diagonal(mats: Sequence[torch.Tensor], row_offsets, col_offsets) -> torch.Tensor:
    idx, vals = [], []
    for m, r, c in zip(mats, row_offsets, col_offsets):
        m = m.coalesce()
        idx.append(m.indices() + torch.tensor([[r], [c]]))
        vals.append(m.values())
    shape = (int(row_offsets[-1]), int(col_offsets[-1]))
    return torch.sparse_coo_tensor(torch.cat(idx, 1), torch.cat(vals), shape, is_coalesced=True,
                                   check_invariants=False)


@dataclass
class MeshBatch:
    """Several meshes as one disconnected mesh: what the models take.

    Vertices, edges and faces of mesh ``b`` are rows ``offsets[b]:offsets[b+1]`` of the
    concatenated tensors; ``edges``, ``faces`` and ``face_edges`` hold global indices;
    sparse operators are block diagonal; eigenpairs are stacked row-wise with
    ``edge_evals``/``vertex_evals`` of shape ``(B, k)``. A single mesh is a batch of one
    (:meth:`from_operators`).
    """

    features: torch.Tensor
    labels: torch.Tensor | None
    verts: torch.Tensor
    faces: torch.Tensor
    edges: torch.Tensor
    face_edges: torch.Tensor
    edge_mass: torch.Tensor
    vertex_mass: torch.Tensor
    face_area: torch.Tensor
    gradient: torch.Tensor
    connection_laplacian: torch.Tensor
    edge_evals: torch.Tensor
    edge_evecs: torch.Tensor
    vertex_evals: torch.Tensor
    vertex_evecs: torch.Tensor
    vertex_gradient: torch.Tensor | None
    vertex_offsets: torch.Tensor
    edge_offsets: torch.Tensor
    face_offsets: torch.Tensor
    vertex_batch: torch.Tensor
    edge_batch: torch.Tensor
    face_batch: torch.Tensor
    indices: torch.Tensor = field(default_factory=lambda: torch.zeros(0, dtype=torch.int64))

    @property
    def num_meshes(self) -> int:
        return int(self.vertex_offsets.shape[0] - 1)

    @property
    def num_vertices(self) -> int:
        return int(self.verts.shape[0])

    @property
    def num_edges(self) -> int:
        return int(self.edges.shape[0])

    @property
    def num_faces(self) -> int:
        return int(self.faces.shape[0])

    @classmethod
    def from_operators(cls, operators: MeshOperators, features, label=None) -> "MeshBatch":
        return collate_meshes([MeshSample(operators, features, label)])


def collate_meshes(samples: Sequence[MeshSample]) -> MeshBatch:
    """Batch meshes of different sizes (the ``collate_fn`` of a ``DataLoader``).

    Parameters
    ----------
    samples : sequence of :class:`MeshSample`, all with the same feature width, numbers
        of eigenpairs, ``n``, dtypes and kind of label.

    Returns
    -------
    MeshBatch
    """
    if not samples:
        raise ValueError("collate_meshes needs at least one sample")
    for s in samples:
        if not isinstance(s, MeshSample):
            raise ValueError(f"collate_meshes expects MeshSample items, got {type(s).__name__}")
    ops_list = [s.operators for s in samples]
    first = ops_list[0]
    for o, s in zip(ops_list, samples):
        if o.edge_evals.shape != first.edge_evals.shape or o.vertex_evals.shape != first.vertex_evals.shape:
            raise ValueError("all meshes of a batch need the same numbers of eigenpairs")
        if o.n != first.n or o.verts.dtype != first.verts.dtype:
            raise ValueError("all meshes of a batch need the same n and dtype")
        if (o.vertex_gradient is None) != (first.vertex_gradient is None):
            raise ValueError("either all or no meshes of a batch have a vertex_gradient")
        if s.features.dim() != 2 or s.features.shape[0] != o.num_vertices:
            raise ValueError(f"features must have shape (V, C) with V = {o.num_vertices}, got {tuple(s.features.shape)}")
        if s.features.shape[1] != samples[0].features.shape[1]:
            raise ValueError("all samples of a batch need the same number of feature channels")
    nv = torch.tensor([0] + [o.num_vertices for o in ops_list]).cumsum(0)
    ne = torch.tensor([0] + [o.num_edges for o in ops_list]).cumsum(0)
    nf = torch.tensor([0] + [o.num_faces for o in ops_list]).cumsum(0)
    cat = torch.cat

    def batch_vector(offsets):
        return torch.repeat_interleave(torch.arange(len(samples)), offsets[1:] - offsets[:-1])

    labels = [s.label for s in samples]
    if all(lab is None for lab in labels):
        label_t = None
    elif all(isinstance(lab, (int, np.integer)) or (isinstance(lab, torch.Tensor) and lab.dim() == 0)
             for lab in labels):
        label_t = torch.tensor([int(lab) for lab in labels], dtype=torch.int64)
    elif all(isinstance(lab, torch.Tensor) and lab.dim() == 1 for lab in labels):
        label_t = cat([lab.to(torch.int64) for lab in labels])
    else:
        raise ValueError("labels must be all ints, all 1-D tensors, or all None")
    return MeshBatch(
        features=cat([s.features for s in samples]),
        labels=label_t,
        verts=cat([o.verts for o in ops_list]),
        faces=cat([o.faces + nv[b] for b, o in enumerate(ops_list)]),
        edges=cat([o.edges + nv[b] for b, o in enumerate(ops_list)]),
        face_edges=cat([o.face_edges + ne[b] for b, o in enumerate(ops_list)]),
        edge_mass=cat([o.edge_mass for o in ops_list]),
        vertex_mass=cat([o.vertex_mass for o in ops_list]),
        face_area=cat([o.face_area for o in ops_list]),
        gradient=_block_diagonal([o.gradient for o in ops_list], ne, nv),
        connection_laplacian=_block_diagonal([o.connection_laplacian for o in ops_list], ne, ne),
        edge_evals=torch.stack([o.edge_evals for o in ops_list]),
        edge_evecs=cat([o.edge_evecs for o in ops_list]),
        vertex_evals=torch.stack([o.vertex_evals for o in ops_list]),
        vertex_evecs=cat([o.vertex_evecs for o in ops_list]),
        vertex_gradient=(None if first.vertex_gradient is None
                         else _block_diagonal([o.vertex_gradient for o in ops_list], nv, nv)),
        vertex_offsets=nv, edge_offsets=ne, face_offsets=nf,
        vertex_batch=batch_vector(nv), edge_batch=batch_vector(ne), face_batch=batch_vector(nf),
        indices=torch.tensor([s.index for s in samples], dtype=torch.int64),
    )


# --------------------------------------------------------------------------- degenerate faces


def find_degenerate_faces(verts, faces) -> np.ndarray:
    """Indices of the faces that the operators reject as zero-area (same criterion, float64)."""
    v = np.asarray(verts, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    p = v[f]
    e = p[:, [2, 0, 1]] - p[:, [1, 2, 0]]
    lmax = np.linalg.norm(e, axis=2).max(1)
    double_area = np.linalg.norm(np.cross(e[:, 0], e[:, 1]), axis=1)
    return np.nonzero(double_area <= 8 * np.finfo(np.float64).eps * lmax * lmax)[0]


def repair_degenerate_faces(verts, faces) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """Repair zero-area faces of a closed manifold mesh by collapsing one of their short edges.

    Procedure, for each zero-area face in turn: its edges, shortest first, are tried as
    an edge collapse ``u -> w``, both directions for each edge. A collapse moves no
    vertex: ``u`` is removed, every face using ``u`` uses ``w`` instead, and the
    two faces sharing the edge ``uw`` (the degenerate face and its neighbour) are
    deleted. A collapse is accepted only if the link condition holds (``u`` and ``w``
    share exactly two neighbours), no face becomes degenerate and the result is still a
    valid :class:`~torch_edgevf.topology.Topology` (manifold, oriented); otherwise the
    next edge is tried, and ``ValueError`` is raised when none works. The Euler
    characteristic is unchanged (one vertex, three edges and two faces fewer).

    Returns
    -------
    verts : (V', 3) array, the kept vertices (a copy)
    faces : (F', 3) int64 array, reindexed
    kept : (V',) int64 array, original index of each kept vertex (to carry per-vertex data)
    repaired : list of the original indices of the repaired faces
    """
    v = np.asarray(verts)
    f = np.array(faces, dtype=np.int64)
    orig_face = np.arange(len(f))
    kept = np.arange(len(v))
    repaired = []
    while True:
        bad = find_degenerate_faces(v, f)
        if len(bad) == 0:
            break
        t = int(bad[0])
        original = int(orig_face[t])
        p = v[f[t]].astype(np.float64)
        lengths = np.linalg.norm(p[[2, 0, 1]] - p[[1, 2, 0]], axis=1)  # opposite each corner
        done = False
        for k in np.argsort(lengths):  # edge opposite corner k: (f[t, k+1], f[t, k+2])
            e0, e1 = int(f[t, (k + 1) % 3]), int(f[t, (k + 2) % 3])
            for u, w in ((e0, e1), (e1, e0)):
                g = _collapse(v, f, u, w)
                if g is not None:
                    f = g[0]
                    orig_face = orig_face[g[1]]
                    done = True
                    break
            if done:
                break
        if not done:
            raise ValueError(f"cannot repair the zero-area face {original}: no valid edge collapse")
        repaired.append(original)
    used = np.unique(f)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return np.array(v[used]), remap[f], kept[used], repaired


def _collapse(v: np.ndarray, f: np.ndarray, u: int, w: int):
    """Faces after collapsing vertex ``u`` into ``w`` (positions unchanged), or None if invalid."""
    def neighbours(x):
        rows = f[(f == x).any(1)]
        return set(rows.ravel().tolist()) - {x}

    if len(neighbours(u) & neighbours(w)) != 2:
        return None
    keep = ~((f == u).any(1) & (f == w).any(1))
    g = np.where(f == u, w, f)[keep]
    if len(find_degenerate_faces(v, g)):
        return None
    try:
        Topology(torch.from_numpy(g), num_vertices=len(v))
    except ValueError:
        return None
    return g, np.nonzero(keep)[0]


# --------------------------------------------------------------------------- PSB


class PSBDataset(torch.utils.data.Dataset):
    """The Princeton Segmentation Benchmark (watertight, 2k faces) for shape classification.

    Items are :class:`MeshSample` with heat-kernel-signature vertex features (from the
    cotangent Laplacian's eigenpairs: intrinsic) and the class index as label; batch them
    with :func:`collate_meshes`. Operators are computed once (with a progress bar) and
    kept in an :class:`OperatorCache`.

    Degenerate faces: one mesh (psb id 351) has a zero-area face, which the operators
    reject. ``degenerate="repair"`` (default) collapses a short edge of each such face
    (:func:`repair_degenerate_faces`: one vertex and two faces fewer, no vertex moved)
    and logs a warning naming the psb ids; ``"skip"`` leaves such meshes out, with a warning listing their ids;
    ``"error"`` raises ``ValueError``.

    Parameters
    ----------
    path : path of ``psb_watertight_2k.npz``
    split : {"train", "test", "all"} (the file's fixed split: 16 / 4 meshes per class)
    cache_dir : path of the operator cache; None computes without caching
    n, k_edge, k_vertex, vertex_gradient : options of :func:`compute_operators`
    hks_count : int, number of HKS times
    dtype : torch.float32 (default) or torch.float64, for the returned tensors
    degenerate : {"repair", "skip", "error"}
    ids : optional sequence of psb ids to keep (small subsets for tests)
    show_progress : bool or None (auto: a terminal, not pytest)
    """

    def __init__(self, path=DEFAULT_PSB_PATH, split: str = "train", cache_dir=None, n: int = 1,
                 k_edge: int = 32, k_vertex: int = 32, vertex_gradient: bool = True, hks_count: int = 16,
                 dtype: torch.dtype = torch.float32, degenerate: str = "repair", ids=None,
                 show_progress: bool | None = None):
        if split not in ("train", "test", "all"):
            raise ValueError(f"split must be 'train', 'test' or 'all', got {split!r}")
        if degenerate not in ("repair", "skip", "error"):
            raise ValueError(f"degenerate must be 'repair', 'skip' or 'error', got {degenerate!r}")
        if dtype not in (torch.float32, torch.float64):
            raise ValueError(f"dtype must be torch.float32 or torch.float64, got {dtype}")
        path = Path(path)
        if not path.exists():
            raise ValueError(f"PSB file not found: {path}")
        with np.load(path, allow_pickle=False) as data:
            d = {name: data[name] for name in data.files}
        self.classes = [str(c) for c in d["classes"]]
        keep = np.ones(len(d["labels"]), dtype=bool)
        if split != "all":
            keep &= d["split"] == (0 if split == "train" else 1)
        if ids is not None:
            keep &= np.isin(d["psb_ids"], np.asarray(list(ids)))
        self.options = dict(n=n, k_edge=k_edge, k_vertex=k_vertex, vertex_laplacian="cotan",
                            vertex_gradient=vertex_gradient)
        self.cache = OperatorCache(cache_dir) if cache_dir is not None else None
        self.dtype, self.hks_count = dtype, hks_count
        meshes, repaired, skipped = [], [], []
        for i in np.nonzero(keep)[0]:
            v = d["verts"][d["vert_offsets"][i]:d["vert_offsets"][i + 1]]
            f = d["faces"][d["face_offsets"][i]:d["face_offsets"][i + 1]].astype(np.int64)
            pid = int(d["psb_ids"][i])
            if len(find_degenerate_faces(v, f)):
                if degenerate == "error":
                    raise ValueError(f"PSB mesh {pid} has zero-area faces {find_degenerate_faces(v, f).tolist()}")
                if degenerate == "skip":
                    skipped.append(pid)
                    continue
                v, f, _, _ = repair_degenerate_faces(v, f)
                repaired.append(pid)
            meshes.append((pid, int(d["labels"][i]), v, f))
        if skipped:
            logger.warning("PSB: skipped %d mesh(es) with zero-area faces: psb ids %s", len(skipped), skipped)
        if repaired:
            logger.warning("PSB: repaired zero-area faces (edge collapse) of psb ids %s", repaired)
        self.skipped, self.repaired = skipped, repaired
        self.psb_ids = [m[0] for m in meshes]
        self.labels = [m[1] for m in meshes]
        self.samples: list[MeshSample] = []
        for j, (pid, label, v, f) in enumerate(progress(meshes, desc=f"PSB {split} operators",
                                                        enabled=show_progress)):
            o = self.cache.get(v, f, **self.options) if self.cache else compute_operators(v, f, **self.options)
            area = float(o.face_area.sum())
            feats = heat_kernel_signature(o.vertex_evals, o.vertex_evecs, count=hks_count, area=area)
            self.samples.append(MeshSample(o.to(dtype), feats.to(dtype), label, j))

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, i: int) -> MeshSample:
        return self.samples[i]
