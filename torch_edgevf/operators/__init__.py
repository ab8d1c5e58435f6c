"""The edge-based operators: sparse matrices assembled from per-face contributions.

* :mod:`.patterns`: fixed sparsity patterns, sorted once per topology;
* :mod:`.kernels`: the per-face value kernels and the cached assembly plans (the
  internal API of the two modules below);
* :mod:`.functional`: one public function per operator (the table of formulas);
* :mod:`.module`: :class:`EdgeOperators`, all operators of a mesh as an ``nn.Module``.

The functions are re-exported here: ``torch_edgevf.operators.mass_matrix`` etc.
"""

from . import functional, kernels, module, patterns
from .functional import *  # noqa: F403
from .module import EdgeOperators

__all__ = ["functional", "kernels", "module", "patterns", *functional.__all__, "EdgeOperators"]
