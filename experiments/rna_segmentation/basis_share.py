"""How much of a gradient field the edge network's field basis keeps.

    python experiments/rna_segmentation/basis_share.py --data DIR --meshes 3CXC_9 4P6F_RB

The recommended ``EdgeFieldNet`` keeps its fields in the span of the ``--k-edge`` lowest
eigenvectors ``Phi`` of ``L_c`` (``M_z``-orthonormal). For each mesh, decimated as the study's
training meshes are, this prints the share of the ``M_z`` energy of the gradient fields
``u = M_z^-1 G s`` that the projection ``Phi Phi^H M_z u`` keeps, for two kinds of scalars
``s``: the network's inputs (the logarithms of 16 heat kernel signatures) and the indicator
functions of the mesh's five most frequent labels (the edges of the segments).
"""

from __future__ import annotations

import argparse
import sys

import torch

from torch_edgevf.learning.datasets.rna import prepare_rna_mesh, read_rna_mesh, rna_path
from torch_edgevf.learning.precompute import compute_operators, heat_kernel_signature


def kept_share(gradient, edge_mass, evecs, scalars) -> torch.Tensor:
    """Per column of ``scalars``: ``|Phi^H M_z u|^2 / (u^H M_z u)`` with ``u = M_z^-1 G s``."""
    s = scalars.to(torch.complex128)
    u = (gradient.to(torch.complex128) @ s) / edge_mass[:, None]
    c = evecs.to(torch.complex128).mH @ (edge_mass[:, None] * u)
    return (c.abs() ** 2).sum(0) / (edge_mass[:, None] * u.abs() ** 2).sum(0)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=None, help="the dataset folder (default: $TORCH_EDGEVF_RNA)")
    p.add_argument("--meshes", nargs="+", default=["3CXC_9"])
    p.add_argument("--k-edge", type=int, default=32)
    p.add_argument("--target-vertices", type=int, default=5000)
    a = p.parse_args(argv)
    try:
        root = rna_path(a.data)
        raw = [(name, read_rna_mesh(root, name)) for name in a.meshes]
    except (ValueError, OSError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print("| mesh | vertices | scalars | share kept (median) | range |")
    print("|---|---:|---|---:|---|")
    for name, mesh_data in raw:
        mesh = prepare_rna_mesh(*mesh_data, name=name, target_vertices=a.target_vertices)
        ops = compute_operators(mesh.verts, mesh.faces, k_edge=a.k_edge, k_vertex=128, vertex_gradient=True)
        hks = heat_kernel_signature(ops.vertex_evals, ops.vertex_evecs, count=16, log=True)
        labels = torch.from_numpy(mesh.mesh_labels)
        frequent = torch.bincount(labels).argsort(descending=True)[:5]
        indicators = torch.stack([(labels == c).double() for c in frequent], 1)
        mass = ops.edge_mass.double()
        for kind, s in (("log-HKS", hks), ("label indicators", indicators)):
            share = kept_share(ops.gradient, mass, ops.edge_evecs, s)
            print(
                f"| {name} | {len(mesh.verts):,} | {kind} | {float(share.median()):.3f} "
                f"| {float(share.min()):.3f}-{float(share.max()):.3f} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
