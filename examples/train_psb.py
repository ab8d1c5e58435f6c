"""Shape classification on the Princeton Segmentation Benchmark (19 classes, fixed split).

Protocol: the 380 watertight PSB meshes decimated to 2k faces (``psb_watertight_2k.npz``,
given by ``$TORCH_EDGEVF_PSB``; ``edgevf prepare-psb`` builds it), the file's fixed split
(16 training and 4 test meshes per class), intrinsic input features (16-scale heat
kernel signature of the cotangent Laplacian), no augmentation (the networks are
invariant to rigid motions). Two networks are trained with the same recipe (one mesh per
step, Adam at 1e-3 halved every 50 epochs, label smoothing 0.2) and seeds:

* ``edge``: :class:`torch_edgevf.models.EdgeFieldNet` (scalar and edge-field streams
  coupled through ``G`` and its adjoint, learned ``L_c`` diffusion);
* ``diffusionnet``: :class:`torch_edgevf.models.DiffusionNet` (Sharp et al. 2022, written
  here from the paper, since the ``diffusion-net`` package is not on PyPI).

``benchmarks/bench_learning.py`` runs the same comparison with every option (seeds,
folds, splits, ablations) and writes the README's table.

Operators (eigenpairs of ``L_c`` and of the cotangent Laplacian) are computed once and
kept in an :class:`~torch_edgevf.data.OperatorCache` (``$TORCH_EDGEVF_CACHE`` or
``~/.cache/torch_edgevf/operators``). The script prints a markdown table of test accuracy
and training time per model over the seeds. Run ``python examples/train_psb.py``.
"""

from __future__ import annotations

import functools
import logging
import os
import statistics
import time
from pathlib import Path

import torch

from torch_edgevf import data, models

log = logging.getLogger(__name__)

# the edge-field network takes the logarithm of the heat kernel signatures (their scales
# span orders of magnitude); DiffusionNet takes them as they are, as in its paper
MODELS = {"edge": functools.partial(models.EdgeFieldNet, log_features=True), "diffusionnet": models.DiffusionNet}


def default_cache_dir() -> Path:
    return Path(os.environ.get("TORCH_EDGEVF_CACHE", Path.home() / ".cache" / "torch_edgevf" / "operators"))


def load_datasets(ids=None, k_edge: int = 32, k_vertex: int = 128, cache_dir=None, path=None):
    """The train and test :class:`~torch_edgevf.data.PSBDataset` (operators cached)."""
    cache_dir = default_cache_dir() if cache_dir is None else cache_dir
    kw = dict(path=path, cache_dir=cache_dir, k_edge=k_edge, k_vertex=k_vertex, ids=ids)
    return data.PSBDataset(split="train", **kw), data.PSBDataset(split="test", **kw)


def make_model(name: str, num_classes: int, in_channels: int = 16, width: int = 64, num_blocks: int | None = None,
               dropout: float = 0.5):
    """Model ``name``; ``num_blocks=None``: the model's default (3 for ``edge``, 4 for ``diffusionnet``)."""
    if name not in MODELS:
        raise ValueError(f"model must be one of {sorted(MODELS)}, got {name!r}")
    blocks = {} if num_blocks is None else {"num_blocks": num_blocks}
    return MODELS[name](in_channels, num_classes, width=width, head="global", dropout=dropout, **blocks)


@torch.no_grad()
def evaluate(model, dataset, batch_size: int = 16) -> float:
    """Classification accuracy of ``model`` on ``dataset``."""
    model.eval()
    loader = torch.utils.data.DataLoader(dataset, batch_size=batch_size, collate_fn=data.collate_meshes)
    correct = total = 0
    for batch in loader:
        correct += int((model(batch).argmax(1) == batch.labels).sum())
        total += batch.num_meshes
    model.train()
    return correct / max(total, 1)


def train_one(name: str, train_set, test_set, seed: int, epochs: int, width: int, num_blocks: int | None,
              batch_size: int, lr: float, num_workers: int = 0) -> dict:
    """Train one model with one seed; returns test accuracy, train time and losses."""
    torch.manual_seed(seed)
    model = make_model(name, len(train_set.classes), train_set[0].features.shape[1], width, num_blocks)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=50, gamma=0.5)
    g = torch.Generator().manual_seed(seed)
    loader = torch.utils.data.DataLoader(train_set, batch_size=batch_size, shuffle=True, generator=g,
                                         collate_fn=data.collate_meshes, num_workers=num_workers)
    losses = []
    start = time.perf_counter()
    for epoch in range(epochs):
        total = 0.0
        for batch in loader:
            opt.zero_grad()
            loss = torch.nn.functional.cross_entropy(model(batch), batch.labels, label_smoothing=0.2)
            loss.backward()
            opt.step()
            total += float(loss.detach()) * batch.num_meshes
        sched.step()
        losses.append(total / len(train_set))
        log.info("%s seed %d epoch %d: loss %.4f", name, seed, epoch, losses[-1])
    seconds = time.perf_counter() - start
    return {"model": name, "seed": seed, "test_accuracy": evaluate(model, test_set),
            "train_accuracy": evaluate(model, train_set), "train_seconds": seconds, "losses": losses,
            "parameters": sum(p.numel() for p in model.parameters())}


def markdown_table(results: list[dict]) -> str:
    """One row per model: test accuracy per seed, mean and std, training time."""
    lines = ["| model | parameters | test accuracy per seed | mean ± std | train time per seed (s) | total (s) |",
             "|---|---|---|---|---|---|"]
    for name in dict.fromkeys(r["model"] for r in results):
        rs = [r for r in results if r["model"] == name]
        acc = [r["test_accuracy"] for r in rs]
        secs = [r["train_seconds"] for r in rs]
        std = statistics.stdev(acc) if len(acc) > 1 else 0.0
        lines.append(f"| {name} | {rs[0]['parameters']} | {', '.join(f'{a:.3f}' for a in acc)} | "
                     f"{statistics.mean(acc):.3f} ± {std:.3f} | {', '.join(f'{s:.0f}' for s in secs)} | "
                     f"{sum(secs):.0f} |")
    return "\n".join(lines)


def main(epochs: int = 60, width: int = 64, num_blocks: int | None = None, seeds=(0, 1, 2), model_names=("edge", "diffusionnet"),
         batch_size: int = 1, lr: float = 1e-3, k_edge: int = 32, k_vertex: int = 128, ids=None, cache_dir=None,
         num_workers: int = 0, threads: int = 1) -> dict:
    """Run the protocol; returns ``{"results": [...], "table": markdown, "operator_seconds": ...}``."""
    torch.set_num_threads(threads)
    start = time.perf_counter()
    train_set, test_set = load_datasets(ids, k_edge, k_vertex, cache_dir)
    operator_seconds = time.perf_counter() - start
    log.info("PSB: %d training and %d test meshes (operators %.1f s)", len(train_set), len(test_set), operator_seconds)
    results = [train_one(name, train_set, test_set, seed, epochs, width, num_blocks, batch_size, lr, num_workers)
               for name in model_names for seed in seeds]
    return {"results": results, "table": markdown_table(results), "operator_seconds": operator_seconds,
            "num_train": len(train_set), "num_test": len(test_set), "repaired": train_set.repaired + test_set.repaired}


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=60)
    parser.add_argument("--width", type=int, default=64)
    parser.add_argument("--blocks", type=int, default=None, help="default: each model's own")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--models", nargs="+", default=["edge", "diffusionnet"])
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    out = main(epochs=args.epochs, width=args.width, num_blocks=args.blocks, seeds=tuple(args.seeds),
               model_names=tuple(args.models))
    print(f"\nPSB: {out['num_train']} train / {out['num_test']} test meshes, repaired: {out['repaired']}, "
          f"operators loaded/computed in {out['operator_seconds']:.0f} s\n")
    print(out["table"])
