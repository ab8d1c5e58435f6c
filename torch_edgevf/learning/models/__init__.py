"""Networks on meshes: the edge-field network (recommended) and a faithful DiffusionNet.

Both take a :class:`~torch_edgevf.learning.batching.MeshBatch` (one mesh or several)
whose ``features`` are vertex scalars (e.g. heat kernel signatures), and return logits
per mesh (``head="global"``), per vertex (``"vertex"``) or per face (``"face"``).

* :mod:`.edgefieldnet`: :class:`EdgeFieldNet`, scalars on the vertices coupled with edge
  fields through ``G``, and its block;
* :mod:`.diffusionnet`: :class:`DiffusionNet` (Sharp et al. 2022), the vertex-based reference;
* :mod:`.edge_diffusion`: :class:`EdgeDiffusionBlock`, a block on edge fields alone;
* :mod:`.common`: the checks, MLP and readout they share.
"""

from . import diffusionnet, edge_diffusion, edgefieldnet
from .common import mini_mlp
from .diffusionnet import *  # noqa: F403
from .edge_diffusion import *  # noqa: F403
from .edgefieldnet import *  # noqa: F403

__all__ = [*edgefieldnet.__all__, *diffusionnet.__all__, *edge_diffusion.__all__, "mini_mlp"]
