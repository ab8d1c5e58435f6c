"""Singularities of the smoothest cross field on Spot (thesis 3.1 and 4.1).

Run ``python examples/singularities_spot.py``; prints the singularities and checks
Poincare-Hopf (the indices sum to the Euler characteristic, 2).
"""

from __future__ import annotations

import logging

from torch_edgevf.fields.design import smoothest_field
from torch_edgevf.fields.singularities import locate_singularities, singularities
from torch_edgevf.io import default_mesh

log = logging.getLogger(__name__)


def main(mesh=None, n: int = 4):
    """Return the :class:`~torch_edgevf.fields.singularities.Singularities` of the smoothest n-field."""
    verts, faces = default_mesh() if mesh is None else mesh
    z = smoothest_field(verts, faces, n=n)
    s = singularities(verts, faces, z, n=n)
    log.info("%s", s)
    log.info("index counts: %s; sum %.2f = chi %d", s.counts(), s.total, s.euler_characteristic)
    loc = locate_singularities(verts, faces, z, n=n)
    for f, p in zip(loc.faces.tolist(), loc.points.tolist()):
        log.info("face %d singularity at %s", f, [round(c, 4) for c in p])
    return s


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    main()
