"""The networks of :mod:`torch_edgevf.learning.models`, under the name ``torch_edgevf.models``."""

from .learning.models import (
    DiffusionNet,
    DiffusionNetBaseline,
    DiffusionNetBlock,
    EdgeDiffusionBlock,
    EdgeFieldBlock,
    EdgeFieldNet,
    mini_mlp,
)

__all__ = [
    "EdgeFieldBlock",
    "EdgeFieldNet",
    "EdgeDiffusionBlock",
    "DiffusionNetBlock",
    "DiffusionNet",
    "DiffusionNetBaseline",
    "mini_mlp",
]
