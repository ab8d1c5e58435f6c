"""Seamless (u, v) parametrization of Spot from a curvature-aligned cross field (chapter 4).

Run ``python examples/param_spot.py``; prints the cut, the flip count and the rounding.
Quad extraction from (u, v) is not part of the library (see ``torch_edgevf.fields.param``).
"""

from __future__ import annotations

import logging

import numpy as np

from torch_edgevf.fields.design import curvature_aligned_field
from torch_edgevf.fields.param import parametrize
from torch_edgevf.io import default_mesh

log = logging.getLogger(__name__)


def main(mesh=None, scale: float | None = None, round_integers: bool = True):
    """Return the :class:`~torch_edgevf.fields.param.Parametrization` of Spot (or ``mesh``)."""
    verts, faces = default_mesh() if mesh is None else mesh
    z = curvature_aligned_field(verts, faces, n=4)
    P = parametrize(verts, faces, z, scale=scale, round_integers=round_integers)
    tr = P.translations.numpy()
    log.info(
        "%d faces, %d cones, %d cut edges, %d flipped faces, energy %.4g, max |t - round(t)| = %.2g",
        P.faces.shape[0],
        P.singular_vertices.numel(),
        int(P.cut_edges.sum()),
        P.flipped,
        P.energy,
        float(np.abs(tr - np.rint(tr)).max(initial=0.0)),
    )
    return P


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    main()
