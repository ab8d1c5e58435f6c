"""The networks of :mod:`torch_edgevf.learning.models`, under the name ``torch_edgevf.models``."""

from .learning.models import (
    DiffusionNetBaseline,
    DiffusionNetBlock,
    EdgeDiffusionBlock,
    EdgeFieldNet,
)

__all__ = [
    "EdgeDiffusionBlock",
    "EdgeFieldNet",
    "DiffusionNetBlock",
    "DiffusionNetBaseline",
]
