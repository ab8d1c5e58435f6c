"""The losses of :mod:`torch_edgevf.learning.losses`, under the name ``torch_edgevf.losses``."""

from .learning.losses import (
    alignment_loss,
    curl_loss,
    div_loss,
    laplace_beltrami_spectrum,
    smoothness_loss,
    spectral_loss,
)

__all__ = [
    "smoothness_loss",
    "alignment_loss",
    "curl_loss",
    "div_loss",
    "laplace_beltrami_spectrum",
    "spectral_loss",
]
