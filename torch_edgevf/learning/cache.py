"""An on-disk cache of :class:`~torch_edgevf.learning.precompute.MeshOperators`.

Entries are keyed by the topology, the float64 positions, the options, the package
version and the version of the computation (:data:`COMPUTATION`); they are written
atomically and verified when read (a corrupt or stale entry is rebuilt, with a logged
warning). A mesh whose operators raise ``ValueError`` is recorded as such, so that it is
refused at once the next time instead of being computed again. Never pickled:
``np.savez``, ``np.load(allow_pickle=False)`` and JSON.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
import zipfile
import zlib
from dataclasses import fields
from pathlib import Path

import numpy as np
import torch

from .._validation import as_faces, as_verts, is_mesh_batch, mesh_list
from .._version import __version__
from ..mesh.topology import Topology
from .precompute import MeshOperators, compute_operators

logger = logging.getLogger(__name__)

__all__ = ["COMPUTATION", "OperatorCache"]

#: The version of what :func:`compute_operators` returns, in the key of every entry: raised
#: whenever a fix changes the operators of some mesh, so that entries computed before it
#: are rebuilt even where the package version is unchanged. 2: ``eigsh`` raises where it
#: returned pairs that are no eigenpairs (a pencil it cannot resolve: a cap face's
#: cotangent weight of ``1e13``); entries of 1 may hold those pairs. 3: meshes with
#: zero-area faces get the operators of their mollified edge lengths, where they raised
#: (recorded failures of 2 are tried again).
COMPUTATION = 3

_SPARSE_FIELDS = ("gradient", "connection_laplacian", "vertex_gradient")


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
    kwargs: dict[str, object] = {}
    for f in fields(MeshOperators):
        if f.name == "n":
            kwargs["n"] = int(arrays["n"])
        elif f.name in _SPARSE_FIELDS:
            if f"{f.name}.indices" not in arrays:
                if f.name == "vertex_gradient":
                    kwargs[f.name] = None
                    continue
                raise KeyError(f"{f.name}.indices")
            raw = arrays[f"{f.name}.indices"].astype(np.int64)
            shape = tuple(int(s) for s in arrays[f"{f.name}.shape"])
            if raw.ndim != 2 or raw.shape[0] != 2:
                raise ValueError(f"{f.name}: indices of shape {raw.shape}, expected (2, nnz)")
            if raw.size:
                if raw.min() < 0 or raw[0].max() >= shape[0] or raw[1].max() >= shape[1]:
                    raise ValueError(f"{f.name}: indices out of range")
                # entries are written coalesced: sorted row-major without repeats
                key = raw[0] * shape[1] + raw[1]
                if (np.diff(key) <= 0).any():
                    raise ValueError(f"{f.name}: indices not sorted (not written by this cache)")
            kwargs[f.name] = torch.sparse_coo_tensor(
                torch.from_numpy(raw),
                torch.from_numpy(arrays[f"{f.name}.values"]),
                shape,
                is_coalesced=True,
                check_invariants=False,
            )
        else:
            kwargs[f.name] = torch.from_numpy(arrays[f.name])
    return MeshOperators(**kwargs)  # type: ignore[arg-type]  # types checked by out.check()


def _content_hash(arrays: dict) -> str:
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


class OperatorCache:
    """On-disk cache of :class:`MeshOperators`.

    An entry is keyed by the SHA-256 of the faces (int64 bytes), of the positions
    (float64 bytes), by the options of :func:`compute_operators`, by the package
    version and by :data:`COMPUTATION`. The file name derives from the first three; the
    full key (with the versions) and a SHA-256 of the content are stored inside, and
    checked when the entry is read, together with the shapes. A file that cannot be
    read, whose content hash or key does not match (another version, a collision), or
    whose shapes are inconsistent is logged as a warning, removed and rebuilt (so that
    an entry whose recomputation raises is not read again). Files are written to a
    temporary file in the same folder and moved into place with ``os.replace``, so
    readers never see half-written entries. Pickle is never used.

    A ``ValueError`` of :func:`compute_operators` in :meth:`get` (a mesh that cannot be
    handled, an eigenproblem that ``eigsh`` refuses) is recorded next to where the entry
    would be (``.failed.json``, with the full key), and later calls with the same key raise
    it again without computing; the message names the record, whose removal makes the
    next call try again. A record of another package version or computation is removed
    and the mesh computed again. See :meth:`failure` and :meth:`record_failure`.

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
        return {
            "faces": _sha256(f),
            "verts": _sha256(v),
            "options": {k: options[k] for k in sorted(options)},
            "version": __version__,
            "computation": COMPUTATION,
        }

    def path(self, key: dict) -> Path:
        """File of an entry: from the mesh hashes and options (not the version)."""
        stem = {k: key[k] for k in ("faces", "verts", "options")}
        return self.root / (
            hashlib.sha256(json.dumps(stem, sort_keys=True).encode()).hexdigest()[:40] + ".npz"
        )

    def load(self, key: dict) -> MeshOperators | None:
        """The verified entry for ``key``, or None (missing, or invalid: logged and removed)."""
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
            path.unlink(missing_ok=True)
            logger.warning(
                "operator cache entry %s is invalid (%s: %s); removed it, to be rebuilt",
                path.name,
                type(exc).__name__,
                exc,
            )
            return None

    def save(self, key: dict, operators: MeshOperators) -> Path:
        """Write an entry atomically (removing a failure recorded for ``key``); returns its path."""
        arrays = _to_arrays(operators)
        arrays["__hash__"] = np.asarray(_content_hash(arrays))
        arrays["__key__"] = np.asarray(json.dumps(key, sort_keys=True))
        path = self.path(key)
        self._write(path, lambda fh: np.savez(fh, **arrays))
        self.failure_path(key).unlink(missing_ok=True)
        return path

    def _write(self, path: Path, write) -> None:
        fd, tmp = tempfile.mkstemp(dir=self.root, prefix=path.stem, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                write(fh)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)

    def failure_path(self, key: dict) -> Path:
        """File of the failure recorded for ``key`` (beside :meth:`path`)."""
        return self.path(key).with_suffix(".failed.json")

    def record_failure(self, key: dict, error: BaseException) -> Path:
        """Record that the operators of ``key`` raised ``error``; returns the record's path."""
        record = json.dumps({"key": key, "error": str(error), "type": type(error).__name__}, sort_keys=True)
        path = self.failure_path(key)
        self._write(path, lambda fh: fh.write(record.encode()))
        return path

    def failure(self, key: dict) -> str | None:
        """The error recorded for ``key``, or None (none, or one of another version or
        computation, or unreadable: then removed, with a logged warning)."""
        path = self.failure_path(key)
        if not path.exists():
            return None
        try:
            record = json.loads(path.read_text())
            if record["key"] == key:
                return str(record["error"])
            other = record["key"]
            reason = (
                f"another key: version {other.get('version')!r}, computation {other.get('computation')!r}"
            )
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            reason = f"{type(exc).__name__}: {exc}"
        path.unlink(missing_ok=True)
        logger.warning("operator cache failure record %s does not apply (%s); removed it", path.name, reason)
        return None

    def get(self, verts, faces=None, device=None, **options):
        """Load the entry of a mesh, or compute (:func:`compute_operators`) and store it.

        The entry is returned on ``device``, by default the device of ``verts`` (the CPU
        for arrays); entries are computed and stored on the CPU. A batch of meshes with
        ``verts_list()`` / ``faces_list()`` (a ``pytorch3d.structures.Meshes``; ``faces``
        left out) gives a list, one entry per mesh.

        Raises the recorded ``ValueError`` at once for a mesh whose operators raised before
        (see the class docstring), and records a new one.
        """
        if is_mesh_batch(verts):
            return [self.get(v, f, device=device, **options) for v, f in mesh_list(verts, faces)]
        if faces is None:
            raise ValueError("OperatorCache.get needs faces (or a batch of meshes with faces_list())")
        if device is None:
            device = verts.device if isinstance(verts, torch.Tensor) else torch.device("cpu")
        return self._get(verts, faces, **options).to(device)

    def _get(self, verts, faces, **options) -> MeshOperators:
        key = self.key(verts, faces, **options)
        out = self.load(key)
        if out is None:
            recorded = self.failure(key)
            if recorded is not None:
                raise ValueError(
                    f"{recorded} (recorded in the operator cache: {self.failure_path(key)}; "
                    "remove that file to compute again)"
                )
            try:
                out = compute_operators(verts, faces, device="cpu", **options)
            except ValueError as exc:
                self.record_failure(key, exc)
                raise
            self.save(key, out)
        return out
