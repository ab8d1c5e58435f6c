"""Reading mesh files: ``load_mesh`` and ``read_triangles`` against ``trimesh.load(path, process=False)``.

Run from the repository root::

    python benchmarks/bench_io.py                       # the files below, 7 rounds
    python benchmarks/bench_io.py --rounds 3 --out benchmarks/results/bench_io.md

Files (1 MB and larger, and the RNA sample's OFF files of about 0.9 MB):

* the OFF files of the RNA sample (``--rna DIR``, default ``shared/datasets/rna_sample/off``
  next to the repository, or ``$TORCH_EDGEVF_RNA_SAMPLE``);
* the OBJ meshes of ``shared/meshes`` (``$TORCH_EDGEVF_MESHES``) of 1 MB or more, and those
  of its ``wild/`` folder;
* files written by trimesh (``export``) from one RNA mesh, from the ogre and from Spot, in
  every format: OFF, OBJ, binary PLY, ASCII PLY (Spot as trimesh reads it: one vertex per
  corner, so its files are triangle soups that ``load_mesh`` joins back).

Every side runs in this process with one thread (``OMP_NUM_THREADS=1`` and friends set
before numpy is imported, ``torch.set_num_threads(1)``), interleaved round by round
(trimesh, ``load_mesh``, ``read_triangles``, trimesh with ``process=True`` on one file,
then the next round), after one untimed warm-up read of each file. The table gives the
medians of the process CPU time (one thread: the time the work takes, less sensitive to
other processes on a loaded machine than the wall time) and the ratios of the medians to
trimesh's ``process=False`` (below 1: faster than trimesh); the wall-time ratio is given
beside it. ``trimesh.load(path)`` with its default ``process=True`` merges vertices and
drops degenerate and duplicate faces, the clean-up ``load_mesh`` does too.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import gc  # noqa: E402
import logging  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from common import REPO, SHARED_MESHES, machine_info, markdown_table  # noqa: E402

TARGET = 1.0


def _files(rna: Path, meshes: Path, scratch: Path) -> list[Path]:
    import trimesh

    files = sorted(rna.glob("*.off")) if rna.is_dir() else []
    files += [p for p in sorted(meshes.glob("*.obj")) if p.stat().st_size >= 1 << 20]
    files += sorted((meshes / "wild").glob("*.obj"))
    sources = [p for p in files if p.suffix == ".off"][:1]
    sources += [p for p in files if p.name in ("ogre.obj", "spot.obj")]
    for src in sources:
        mesh = trimesh.load(src, process=False)
        for ext, kwargs in (("off", {}), ("obj", {}), ("ply", {}), ("ascii.ply", {"encoding": "ascii"})):
            out = scratch / f"{src.stem}_trimesh.{ext}"
            mesh.export(out, **kwargs)
            files.append(out)
    return files


def _time(fn) -> tuple[float, float]:
    """(CPU seconds of this process, wall seconds) of one call."""
    gc.collect()
    c0, t0 = time.process_time(), time.perf_counter()
    fn()
    return time.process_time() - c0, time.perf_counter() - t0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    default_rna = os.environ.get("TORCH_EDGEVF_RNA_SAMPLE") or REPO.parent / "shared/datasets/rna_sample/off"
    parser.add_argument("--rna", type=Path, default=Path(default_rna), help="folder of RNA OFF files")
    parser.add_argument("--meshes", type=Path, default=SHARED_MESHES, help="folder of OBJ meshes")
    parser.add_argument("--rounds", type=int, default=7, help="timed rounds per file (median)")
    parser.add_argument("--out", type=Path, default=None, help="write the markdown table here")
    args = parser.parse_args(argv)

    import torch
    import trimesh

    from torch_edgevf.io import load_mesh, read_triangles

    torch.set_num_threads(1)
    logging.getLogger("torch_edgevf").setLevel(logging.ERROR)  # no report printing in the timings
    rows, ratios, default_ratios = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        files = _files(args.rna, args.meshes, Path(tmp))
        if not files:
            print("no files found: pass --rna and --meshes", file=sys.stderr)
            return 1
        for path in files:
            sides = {
                "trimesh": lambda p=path: trimesh.load(p, process=False),
                "load_mesh": lambda p=path: load_mesh(p),
                "read_triangles": lambda p=path: read_triangles(p),
                "trimesh_process": lambda p=path: trimesh.load(p),
            }
            for fn in sides.values():  # warm-up: the file in the page cache, imports done
                fn()
            cpu: dict[str, list[float]] = {k: [] for k in sides}
            wall: dict[str, list[float]] = {k: [] for k in sides}
            for _ in range(args.rounds):
                for name, fn in sides.items():
                    c, w = _time(fn)
                    cpu[name].append(c)
                    wall[name].append(w)
            med = {k: statistics.median(v) for k, v in cpu.items()}
            med_wall = {k: statistics.median(v) for k, v in wall.items()}
            mesh = load_mesh(path)
            r_load, r_read = med["load_mesh"] / med["trimesh"], med["read_triangles"] / med["trimesh"]
            r_default = med["load_mesh"] / med["trimesh_process"]
            ratios.append(r_load)
            default_ratios.append(r_default)
            rows.append(
                [
                    path.name,
                    f"{path.stat().st_size / 1e6:.2f}",
                    f"{len(mesh.verts):,} / {len(mesh.faces):,}",
                    f"{mesh.report.merged_vertices:,}",
                    f"{med['trimesh'] * 1e3:.1f}",
                    f"{med['load_mesh'] * 1e3:.1f}",
                    f"{med['read_triangles'] * 1e3:.1f}",
                    f"**{r_load:.2f}**",
                    f"{r_read:.2f}",
                    f"{med_wall['load_mesh'] / med_wall['trimesh']:.2f}",
                    f"{med['trimesh_process'] * 1e3:.1f}",
                    f"**{r_default:.2f}**",
                ]
            )
            print(" | ".join(rows[-1]), flush=True)
    table = markdown_table(
        [
            "file",
            "MB",
            "V / F (load_mesh)",
            "merged",
            "trimesh ms",
            "load_mesh ms",
            "read_triangles ms",
            "load_mesh / trimesh",
            "read_triangles / trimesh",
            "load_mesh / trimesh (wall)",
            "trimesh process=True ms",
            "load_mesh / trimesh process=True",
        ],
        rows,
    )
    info = machine_info()
    text = (
        "# Reading mesh files: torch_edgevf against trimesh\n\n"
        f"`python benchmarks/bench_io.py --rounds {args.rounds}`: one thread per side, interleaved,"
        f" median CPU time of {args.rounds} rounds after a warm-up read; trimesh {trimesh.__version__},"
        f" torch {torch.__version__}, {info.get('cpu', '')}. Target: load_mesh / trimesh <= {TARGET}.\n\n"
        + table
        + f"\n\nload_mesh / trimesh: median {statistics.median(ratios):.2f}, worst {max(ratios):.2f}"
        f" ({sum(r <= TARGET for r in ratios)} of {len(ratios)} files at or under {TARGET}).\n"
        + f"load_mesh / trimesh.load with its default process=True (the same clean-up): median"
        f" {statistics.median(default_ratios):.2f}, worst {max(default_ratios):.2f}"
        f" ({sum(r <= TARGET for r in default_ratios)} of {len(default_ratios)} files"
        f" at or under {TARGET}).\n"
    )
    print(text)
    if args.out is not None:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
