"""Build ``psb_watertight_2k.npz`` from the Princeton Segmentation Benchmark's OFF files.

The benchmark (Chen, Golovinskiy, Funkhouser 2009; its meshes are the watertight track of
SHREC 2007) numbers its meshes 1 to 400, 20 per class in a fixed order; the spring class
(261-280) is left out of the benchmark's study and of this file. Its ``data`` folder holds
``off/<id>.off``. Each mesh is decimated to ``faces`` triangles by quadric edge collapse
(fast-simplification, the ``prepare`` extra), centred on its vertex centroid and scaled to
the unit bounding sphere; the layout of the file is documented in :class:`PSBDataset`'s page
(``docs/learning.md``).
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np

logger = logging.getLogger(__name__)

__all__ = ["PSB_CLASSES", "psb_class", "prepare_psb"]

# The benchmark's categories, in the order of their mesh numbers (20 each, from 1).
_CATEGORIES = (
    "human cup glasses airplane ant chair octopus table teddy hand plier fish bird spring "
    "armadillo bust mech bearing vase fourleg"
).split()
_EXCLUDED = "spring"
PSB_CLASSES = tuple(c for c in _CATEGORIES if c != _EXCLUDED)
"""The 19 classes of the file, in the order of their label index."""

TRAIN_PER_CLASS = 16  # the first 16 of each class by id train, the rest test


def psb_class(psb_id: int) -> int | None:
    """Label index of a benchmark mesh number (None: the excluded class or out of range)."""
    if not 1 <= psb_id <= 20 * len(_CATEGORIES):
        return None
    name = _CATEGORIES[(psb_id - 1) // 20]
    return None if name == _EXCLUDED else PSB_CLASSES.index(name)


def _off_files(src: Path) -> dict[int, Path]:
    folder = src / "off" if (src / "off").is_dir() else src
    files = {}
    for path in folder.glob("*.off"):
        m = re.fullmatch(r"(\d+)", path.stem)
        if m:
            files[int(m.group(1))] = path
    return files


def _decimate(verts: np.ndarray, faces: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    if len(faces) <= target:
        return verts, faces
    try:
        import fast_simplification
    except ImportError as error:
        raise ValueError(
            "decimation needs fast-simplification: pip install 'torch_edgevf[prepare]'"
        ) from error
    v, f = fast_simplification.simplify(verts, faces.astype(np.int32), target_count=target)
    used = np.unique(f)  # the decimator may leave collapsed vertices behind
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return np.asarray(v)[used], remap[f]


def prepare_psb(src_dir, out, faces: int = 2000, show_progress: bool | None = None) -> dict:
    """Read the benchmark's OFF files, decimate and normalise them, and write the npz file.

    Parameters
    ----------
    src_dir : the benchmark's ``data`` folder (with ``off/<id>.off``) or the ``off`` folder
    out : path of the ``.npz`` file to write
    faces : int, target number of triangles per mesh (meshes with fewer are kept as they are)
    show_progress : bool or None (auto)

    Returns
    -------
    dict with ``meshes`` (number written), ``skipped`` (psb ids left out, with the reason
    logged as a warning) and ``path``.

    Raises
    ------
    ValueError
        No OFF file of the benchmark's classes in ``src_dir``, or ``faces < 4``.
    """
    import trimesh

    from ..mesh.topology import Topology
    from .progress import progress

    src = Path(src_dir)
    if not src.is_dir():
        raise ValueError(f"{src}: not a folder")
    if faces < 4:
        raise ValueError(f"faces must be at least 4, got {faces}")
    files = {i: p for i, p in sorted(_off_files(src).items()) if psb_class(i) is not None}
    if not files:
        raise ValueError(f"{src}: no benchmark OFF files (off/1.off ... off/400.off)")
    verts, tris, labels, ids, eulers, skipped = [], [], [], [], [], []
    for psb_id, path in progress(list(files.items()), desc="PSB meshes", enabled=show_progress):
        # trimesh reads the file (torch_edgevf.io sits above this layer); process=True
        # merges duplicated vertices and drops degenerate faces
        mesh: trimesh.Trimesh = trimesh.load(path, file_type="off", force="mesh", process=True)  # type: ignore[assignment]
        v, f = _decimate(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces), faces)
        try:
            topo = Topology(f, num_vertices=len(v))
            topo.require_closed()
        except ValueError as error:
            logger.warning("PSB mesh %d left out after decimation: %s", psb_id, error)
            skipped.append(psb_id)
            continue
        v = v - v.mean(axis=0)
        v = v / np.linalg.norm(v, axis=1).max()
        verts.append(v.astype(np.float32))
        tris.append(f.astype(np.int32))
        labels.append(psb_class(psb_id))
        ids.append(psb_id)
        eulers.append(topo.euler_characteristic)
    if not ids:
        raise ValueError(f"{src}: no mesh could be prepared (see the warnings)")
    labels_a = np.asarray(labels, dtype=np.int64)
    ids_a = np.asarray(ids, dtype=np.int64)
    split = np.zeros(len(ids), dtype=np.int8)
    for c in np.unique(labels_a):
        members = np.nonzero(labels_a == c)[0]
        split[members[np.argsort(ids_a[members])][TRAIN_PER_CLASS:]] = 1
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        out,
        verts=np.concatenate(verts),
        faces=np.concatenate(tris),
        vert_offsets=np.concatenate([[0], np.cumsum([len(v) for v in verts])]).astype(np.int64),
        face_offsets=np.concatenate([[0], np.cumsum([len(f) for f in tris])]).astype(np.int64),
        labels=labels_a,
        psb_ids=ids_a,
        split=split,
        euler=np.asarray(eulers, dtype=np.int64),
        classes=np.asarray(PSB_CLASSES),
    )
    return {"meshes": len(ids), "skipped": skipped, "path": out}
