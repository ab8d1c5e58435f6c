"""Linear probes on PSB: what pooled gradient fields add to the statistics of the input.

Run from the repository root::

    python experiments/psb_classification/probe.py --data psb_watertight_2k.npz [--cache DIR] [--quick]

A diagnosis for the learning table, not a model: for every mesh, the mass-weighted mean
and standard deviation of features over the mesh, and a multinomial logistic regression
(L2 penalty ``--penalty``, features standardised on the training meshes) on

* the log heat kernel signatures (16 scales), the input of every network;
* the same plus the log moduli of their edge gradient fields ``M_z^{-1} G log h`` (this
  library's operators), or of those fields projected on the ``k_edge`` eigenvectors of
  ``L_c`` (what the networks' field diffusion keeps at ``t = 0``), or of DiffusionNet's
  vertex gradient fields, or both.

The operators, cache, fixed split and stratified folds are those of
``run.py``. A gain here says that the pooled fields carry information that the
pooled input lacks, not that a network will extract it.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import psb_data  # noqa: E402

from torch_edgevf.learning.datasets import psb_path  # noqa: E402
from torch_edgevf.learning.layers import gradient_features, spectral_diffusion  # noqa: E402

FEATURE_SETS = {
    "log-HKS": ("hks",),
    "log-HKS + edge gradients": ("hks", "edge"),
    "log-HKS + edge gradients, L_c-projected": ("hks", "edge_projected"),
    "log-HKS + vertex gradients": ("hks", "vertex"),
    "log-HKS + edge and vertex gradients": ("hks", "edge", "vertex"),
}


def pooled(x: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Mean and standard deviation of the columns of ``x`` weighted by ``w``."""
    w = w / w.sum()
    mean = (w[:, None] * x).sum(0)
    return torch.cat([mean, (w[:, None] * (x - mean) ** 2).sum(0).sqrt()])


def mesh_features(batch) -> tuple[dict[str, torch.Tensor], float]:
    """The pooled features of one mesh, and the share of the edge-gradient energy kept by the projection."""
    h = torch.log(batch.features.double())
    hc = h.to(torch.complex128)
    vmass, emass = batch.vertex_mass.double(), batch.edge_mass.double()
    u = gradient_features(hc, batch.gradient.to(torch.complex128).coalesce(), emass)
    evecs = batch.edge_evecs.to(torch.complex128)
    projected = spectral_diffusion(
        u, batch.edge_evals.double().reshape(-1), evecs, emass, torch.zeros(u.shape[1], dtype=torch.float64)
    )
    gv = gradient_features(hc, batch.vertex_gradient.to(torch.complex128).coalesce())
    kept = float((projected.abs() ** 2 * emass[:, None]).sum() / (u.abs() ** 2 * emass[:, None]).sum())

    def logmod(z):
        return torch.log(z.abs() + 1e-8)

    feats = {
        "hks": pooled(h, vmass),
        "edge": pooled(logmod(u), emass),
        "edge_projected": pooled(logmod(projected), emass),
        "vertex": pooled(logmod(gv), vmass),
    }
    return feats, kept


def probe(x_train, y_train, x_test, y_test, classes: int, penalty: float) -> float:
    """Test accuracy of an L2-penalised multinomial logistic regression (L-BFGS)."""
    mu, sd = x_train.mean(0), x_train.std(0) + 1e-8
    x_train, x_test = (x_train - mu) / sd, (x_test - mu) / sd
    w = torch.zeros(x_train.shape[1], classes, dtype=torch.float64, requires_grad=True)
    b = torch.zeros(classes, dtype=torch.float64, requires_grad=True)
    opt = torch.optim.LBFGS([w, b], max_iter=500, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        loss = torch.nn.functional.cross_entropy(x_train @ w + b, y_train) + penalty * (w**2).sum()
        loss.backward()
        return loss

    opt.step(closure)
    return float(((x_test @ w + b).argmax(1) == y_test).double().mean())


def main(argv=None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default=None, help="psb_watertight_2k.npz (default: $TORCH_EDGEVF_PSB)")
    p.add_argument("--cache", default=None, help="operator cache (default: that of run.py)")
    p.add_argument("--folds", type=int, default=5)
    p.add_argument("--penalty", type=float, default=1e-3)
    p.add_argument("--quick", action="store_true", help="4 classes, 8 meshes each, 2 folds")
    a = p.parse_args(argv)
    try:
        data = psb_path(a.data)
    except ValueError as e:
        p.error(str(e))
    cache = a.cache or os.environ.get(
        "TORCH_EDGEVF_CACHE", str(Path.home() / ".cache" / "torch_edgevf" / "operators")
    )
    torch.set_num_threads(1)
    dataset = psb_data.load_psb(data)
    if a.quick:
        dataset = psb_data.subset(dataset, classes=4, per_class=8)
        a.folds = 2
    batches, _ = psb_data.precompute(dataset, cache)
    per_mesh = [mesh_features(b) for b in batches]
    features = {k: torch.stack([f[k] for f, _ in per_mesh]) for k in per_mesh[0][0]}
    kept = [e for _, e in per_mesh]
    labels = torch.as_tensor(dataset["labels"], dtype=torch.int64)
    classes = len(dataset["classes"])
    evaluations = psb_data.splits(dataset, 0, None) + psb_data.splits(dataset, a.folds, None)
    print(
        f"energy of the edge gradient fields kept by the projection on {batches[0].edge_evecs.shape[1]} "
        f"eigenvectors of L_c: median {statistics.median(kept):.2f} over meshes "
        f"(range {min(kept):.2f}-{max(kept):.2f})"
    )
    print("| pooled features | features | fixed split | cross-validation (mean ± std) |")
    print("|---|---:|---:|---|")
    results = []
    for name, keys in FEATURE_SETS.items():
        x = torch.cat([features[k] for k in keys], dim=1)
        acc = {}
        for split, train, test in evaluations:
            train, test = torch.as_tensor(train), torch.as_tensor(test)
            acc[split] = probe(x[train], labels[train], x[test], labels[test], classes, a.penalty)
        cv = [v for s, v in acc.items() if s.startswith("fold")]
        results.append({"features": name, "fixed": acc["fixed"], "folds": cv})
        print(
            f"| {name} | {x.shape[1]} | {acc['fixed']:.3f} | {np.mean(cv):.3f} ± {np.std(cv, ddof=1):.3f} |"
        )
    return results


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
