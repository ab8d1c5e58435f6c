"""Tangent vector fields: the edge-based representation and what is computed on it.

The package namespace is the representation (:mod:`.representation`: frames,
conversions to ambient vectors, interpolation; :mod:`.powers`: n-RoSy powers and
roots), as ``torch_edgevf.fields.edge_vectors`` etc. The computations on fields are modules:

* :mod:`.design`: smoothest, aligned, constrained and curvature fields (thesis 4), with
  :mod:`.constraints` (the elimination of hard constraints);
* :mod:`.singularities`: indices, singular faces and their location (thesis 3.2);
* :mod:`.poisson`: projection on gradients, the Poisson problem of thesis 4.2;
* :mod:`.transport`: parallel transport by the heat method (thesis 5);
* :mod:`.param`: seamless parametrization from a cross field.

Their entry points (``smoothest_field``, ``singularities``, ``transport``, ...) are
exported by :mod:`torch_edgevf`; they are not re-exported here, so that
``torch_edgevf.fields.singularities`` is the module.
"""

from . import powers, representation
from .powers import *  # noqa: F403
from .representation import *  # noqa: F403

__all__ = [*powers.__all__, *representation.__all__]
