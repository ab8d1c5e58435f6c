"""Train the recommended network on the Princeton Segmentation Benchmark (shape classification).

The network is the library's :class:`~torch_edgevf.learning.models.EdgeFieldNet` with its
defaults, on the logarithm of the 16-scale heat kernel signature (what
``experiments/psb_classification`` recommends); ``--model diffusionnet`` trains the faithful
DiffusionNet instead (no dropout, the signatures as they are). The recipe is the study's:
one mesh per step, Adam at 1e-3 halved every 50 epochs, label smoothing 0.2, the file's
fixed split (16 training and 4 test meshes per class).

The data is ``psb_watertight_2k.npz`` (``--data``, else ``$TORCH_EDGEVF_PSB``; ``edgevf
prepare-psb`` builds it). Only the meshes used are precomputed, and their operators are kept
in an :class:`~torch_edgevf.learning.cache.OperatorCache` (``--cache``, else
``$TORCH_EDGEVF_CACHE`` or ``~/.cache/torch_edgevf/operators``), so a second run starts at
once. A small run, from the repository root::

    .venv/bin/python examples/train_psb.py --classes 4 --limit 4 --epochs 10

trains on 4 meshes of each of 4 classes and tests on those classes' 16 test meshes; without
``--classes`` and ``--limit`` it trains on the whole file (60 epochs: about 20 minutes on
one core). ``--device`` moves the batches and the network (default ``cpu``).
"""

from __future__ import annotations

import argparse
import logging
import os
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from torch_edgevf.learning import DiffusionNet, EdgeFieldNet, PSBDataset, collate_meshes, resolve_device
from torch_edgevf.learning.datasets import psb_path

log = logging.getLogger(__name__)

#: the networks by name: the recommended one and the faithful DiffusionNet
MODELS = ("edgefieldnet", "diffusionnet")


def default_cache_dir() -> Path:
    return Path(os.environ.get("TORCH_EDGEVF_CACHE", Path.home() / ".cache" / "torch_edgevf" / "operators"))


def subset_ids(path=None, classes: int | None = None, limit: int | None = None) -> list[int] | None:
    """The psb ids of the first ``classes`` classes, with at most ``limit`` training meshes
    of each (and all of its test meshes); None (every mesh) without either."""
    if classes is None and limit is None:
        return None
    with np.load(psb_path(path), allow_pickle=False) as d:
        labels, split, ids = d["labels"], d["split"], d["psb_ids"]
    kept = []
    for c in range(int(labels.max()) + 1 if classes is None else classes):
        train = ids[(labels == c) & (split == 0)]
        kept += [*train[:limit].tolist(), *ids[(labels == c) & (split == 1)].tolist()]
    return kept


def load_datasets(
    ids=None, k_edge: int = 32, k_vertex: int = 128, cache_dir=None, path=None, log_hks: bool = True
):
    """The train and test :class:`~torch_edgevf.learning.datasets.PSBDataset` of the meshes
    ``ids`` (all when None), their operators computed once and cached."""
    cache_dir = default_cache_dir() if cache_dir is None else cache_dir
    kw = dict(path=path, cache_dir=cache_dir, k_edge=k_edge, k_vertex=k_vertex, ids=ids, log_hks=log_hks)
    return PSBDataset(split="train", **kw), PSBDataset(split="test", **kw)


def make_model(
    name: str, num_classes: int, in_channels: int = 16, width: int = 64, num_blocks: int | None = None
):
    """Model ``name``; ``num_blocks=None``: the model's default (3 for the edge-field network, 4 for
    DiffusionNet)."""
    blocks = {} if num_blocks is None else {"num_blocks": num_blocks}
    if name == "edgefieldnet":
        return EdgeFieldNet(in_channels, num_classes, width=width, **blocks)
    if name == "diffusionnet":  # as DiffusionNet's classification script builds it
        return DiffusionNet(in_channels, num_classes, width=width, dropout=0.0, **blocks)
    raise ValueError(f"model must be one of {MODELS}, got {name!r}")


@torch.no_grad()
def evaluate(model, dataset, batch_size: int = 16, device="cpu") -> float:
    """Classification accuracy of ``model`` on ``dataset``."""
    model.eval()
    loader = torch.utils.data.DataLoader(dataset, batch_size=batch_size, collate_fn=collate_meshes)
    correct = total = 0
    for batch in loader:
        batch = batch.to(device)
        correct += int((model(batch).argmax(1) == batch.labels).sum())
        total += batch.num_meshes
    model.train()
    return correct / max(total, 1)


def train_one(
    name, train_set, test_set, seed, epochs, width=64, num_blocks=None, batch_size=1, lr=1e-3, device="cpu"
):
    """Train one model with one seed; returns its test accuracy, training time and losses."""
    torch.manual_seed(seed)
    model = make_model(name, len(train_set.classes), train_set[0].features.shape[1], width, num_blocks).to(
        device
    )
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=50, gamma=0.5)
    g = torch.Generator().manual_seed(seed)
    loader = torch.utils.data.DataLoader(
        train_set, batch_size=batch_size, shuffle=True, generator=g, collate_fn=collate_meshes
    )
    losses = []
    start = time.perf_counter()
    for epoch in range(epochs):
        total = 0.0
        for batch in loader:
            batch = batch.to(device)
            opt.zero_grad()
            loss = torch.nn.functional.cross_entropy(model(batch), batch.labels, label_smoothing=0.2)
            loss.backward()
            opt.step()
            total += float(loss.detach()) * batch.num_meshes
        sched.step()
        losses.append(total / len(train_set))
        log.info("%s seed %d epoch %d: loss %.4f", name, seed, epoch, losses[-1])
    return {
        "model": name,
        "seed": seed,
        "test_accuracy": evaluate(model, test_set, device=device),
        "train_accuracy": evaluate(model, train_set, device=device),
        "train_seconds": time.perf_counter() - start,
        "losses": losses,
        "parameters": sum(p.numel() for p in model.parameters()),
    }


def markdown_table(results: list[dict]) -> str:
    """One row per model: test accuracy per seed, mean and std, training time."""
    lines = [
        "| model | parameters | test accuracy per seed | mean ± std | train seconds per seed |",
        "|---|---|---|---|---|",
    ]
    for name in dict.fromkeys(r["model"] for r in results):
        rs = [r for r in results if r["model"] == name]
        acc = [r["test_accuracy"] for r in rs]
        std = statistics.stdev(acc) if len(acc) > 1 else 0.0
        seconds = ", ".join(f"{r['train_seconds']:.0f}" for r in rs)
        lines.append(
            f"| {name} | {rs[0]['parameters']:,} | {', '.join(f'{a:.3f}' for a in acc)} | "
            f"{statistics.mean(acc):.3f} ± {std:.3f} | {seconds} |"
        )
    return "\n".join(lines)


def main(
    epochs: int = 60,
    model: str = "edgefieldnet",
    classes: int | None = None,
    limit: int | None = None,
    ids=None,
    seeds=(0,),
    width: int = 64,
    num_blocks: int | None = None,
    batch_size: int = 1,
    lr: float = 1e-3,
    k_edge: int = 32,
    k_vertex: int = 128,
    cache_dir=None,
    path=None,
    device: str = "cpu",
    threads: int = 1,
) -> dict:
    """Train ``model`` on the subset (``classes``, ``limit``, or the psb ``ids``); returns
    ``{"results": [...], "table": markdown, "operator_seconds": ..., ...}``."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    device = resolve_device(device)
    torch.set_num_threads(threads)
    if ids is None:
        ids = subset_ids(path, classes, limit)
    start = time.perf_counter()
    train_set, test_set = load_datasets(
        ids, k_edge, k_vertex, cache_dir, path, log_hks=model == "edgefieldnet"
    )
    operator_seconds = time.perf_counter() - start
    log.info(
        "PSB: %d training and %d test meshes (operators %.1f s)",
        len(train_set),
        len(test_set),
        operator_seconds,
    )
    results = [
        train_one(model, train_set, test_set, seed, epochs, width, num_blocks, batch_size, lr, device)
        for seed in seeds
    ]
    return {
        "results": results,
        "table": markdown_table(results),
        "operator_seconds": operator_seconds,
        "num_train": len(train_set),
        "num_test": len(test_set),
        "repaired": train_set.repaired + test_set.repaired,
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="psb_watertight_2k.npz (default: $TORCH_EDGEVF_PSB)")
    parser.add_argument("--model", choices=MODELS, default="edgefieldnet")
    parser.add_argument(
        "--classes", type=int, default=None, help="the first K classes only (default: all 19)"
    )
    parser.add_argument("--limit", type=int, default=None, help="at most N training meshes per class")
    parser.add_argument("--epochs", type=int, default=60)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument(
        "--cache", default=None, help="operator cache (default: $TORCH_EDGEVF_CACHE or ~/.cache)"
    )
    parser.add_argument("--device", default="cpu", help="where to train: cpu (default), cuda, ...")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    out = main(
        epochs=args.epochs,
        model=args.model,
        classes=args.classes,
        limit=args.limit,
        seeds=tuple(args.seeds),
        cache_dir=args.cache,
        path=args.data,
        device=args.device,
        threads=args.threads,
    )
    print(
        f"\nPSB: {out['num_train']} train / {out['num_test']} test meshes, repaired: {out['repaired']}, "
        f"operators loaded or computed in {out['operator_seconds']:.0f} s\n"
    )
    print(out["table"])
