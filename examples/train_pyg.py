"""Train the recommended network on a PyTorch Geometric dataset built from the PSB file.

The Princeton Segmentation Benchmark meshes (``psb_watertight_2k.npz``: ``--data``, else
``$TORCH_EDGEVF_PSB``; ``edgevf prepare-psb`` builds it) become a PyG ``InMemoryDataset``
of ``Data(pos, face, y)``; :class:`torch_edgevf.pyg.ComputeOperators` is its
``pre_transform``, so the operators and the log heat kernel signatures are computed once,
kept in an operator cache (``--cache``, else ``$TORCH_EDGEVF_CACHE`` or
``~/.cache/torch_edgevf/operators``) and saved with the dataset (``--root``, else
``$TORCH_EDGEVF_PYG_ROOT`` or ``~/.cache/torch_edgevf/pyg``). PyG's ``DataLoader`` batches
the meshes and :class:`~torch_edgevf.learning.models.EdgeFieldNet` takes its batches as
they are. Needs the extra ``pyg`` (``pip install torch_edgevf[pyg]``). A small run, from
the repository root::

    .venv/bin/python examples/train_pyg.py --classes 3 --limit 8 --epochs 10

trains on 8 meshes of each of the first 3 classes and tests on those classes' 12 test
meshes; ``--device cuda`` trains on a GPU.
"""

from __future__ import annotations

import argparse
import hashlib
import logging
import os
import time
from pathlib import Path

import numpy as np
import torch
from torch_geometric.data import Data, InMemoryDataset
from torch_geometric.loader import DataLoader

from torch_edgevf.learning import DiffusionNet, EdgeFieldNet, resolve_device
from torch_edgevf.learning.datasets import psb_path
from torch_edgevf.learning.datasets.psb import psb_mesh
from torch_edgevf.pyg import ComputeOperators

log = logging.getLogger(__name__)

MODELS = ("edgefieldnet", "diffusionnet")


def default_dir(env: str, name: str) -> Path:
    return Path(os.environ.get(env, Path.home() / ".cache" / "torch_edgevf" / name))


class PSBGeometric(InMemoryDataset):
    """The PSB meshes of one split (and of the psb ``ids``, all when None) as a PyG dataset.

    Each item is a ``Data(pos, face, y, psb_id)``, turned by ``pre_transform`` (once, when
    the dataset is first built under ``root``) and by ``transform`` (at every access).
    """

    def __init__(self, root, path=None, split: str = "train", ids=None, pre_transform=None, transform=None):
        if split not in ("train", "test"):
            raise ValueError(f"split must be 'train' or 'test', got {split!r}")
        self.path, self.split = psb_path(path), split
        self.ids = None if ids is None else sorted(int(i) for i in ids)
        with np.load(self.path, allow_pickle=False) as d:
            self.classes = [str(c) for c in d["classes"]]
        super().__init__(str(root), transform, pre_transform)
        self.load(self.processed_paths[0])

    @property
    def raw_file_names(self) -> list[str]:
        return []  # the PSB file is read where it is

    @property
    def processed_dir(self) -> str:
        # one folder per file (its size and time), subset and pre-transform
        stat = self.path.stat()
        what = f"{self.path.resolve()}:{stat.st_size}:{stat.st_mtime_ns}:{self.ids}:{self.pre_transform}"
        return os.path.join(self.root, "processed", hashlib.sha256(what.encode()).hexdigest()[:16])

    @property
    def processed_file_names(self) -> list[str]:
        return [f"psb_{self.split}.pt"]

    def process(self) -> None:
        with np.load(self.path, allow_pickle=False) as data:
            d = {name: data[name] for name in data.files}
        keep = d["split"] == (0 if self.split == "train" else 1)
        if self.ids is not None:
            keep &= np.isin(d["psb_ids"], self.ids)
        data_list = []
        for i in np.nonzero(keep)[0]:
            v, f = psb_mesh(d, int(i))
            item = Data(
                pos=torch.from_numpy(v).float(),
                face=torch.from_numpy(f).t().contiguous(),
                y=int(d["labels"][i]),
                psb_id=int(d["psb_ids"][i]),
            )
            data_list.append(self.pre_transform(item) if self.pre_transform is not None else item)
        self.save(data_list, self.processed_paths[0])


def subset_ids(path=None, classes: int | None = None, limit: int | None = None) -> list[int] | None:
    """The psb ids of the first ``classes`` classes, at most ``limit`` training meshes of each
    (and all their test meshes); None (every mesh) without either."""
    if classes is None and limit is None:
        return None
    with np.load(psb_path(path), allow_pickle=False) as d:
        labels, split, ids = d["labels"], d["split"], d["psb_ids"]
    kept = []
    for c in range(int(labels.max()) + 1 if classes is None else classes):
        kept += [
            *ids[(labels == c) & (split == 0)][:limit].tolist(),
            *ids[(labels == c) & (split == 1)].tolist(),
        ]
    return kept


@torch.no_grad()
def accuracy(model, dataset, device="cpu") -> float:
    model.eval()
    correct = 0
    for batch in DataLoader(dataset, batch_size=16):
        batch = batch.to(device)
        correct += int((model(batch).argmax(1) == batch.y).sum())
    model.train()
    return correct / max(len(dataset), 1)


def main(
    epochs: int = 30,
    model: str = "edgefieldnet",
    classes: int | None = None,
    limit: int | None = None,
    batch_size: int = 4,
    width: int = 64,
    num_blocks: int | None = None,
    lr: float = 1e-3,
    k_edge: int = 32,
    k_vertex: int = 64,
    path=None,
    root=None,
    cache_dir=None,
    device: str = "cpu",
    seed: int = 0,
) -> dict:
    """Build the PyG datasets of the subset, train ``model``; returns accuracies and losses."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    device = resolve_device(device)  # a ValueError naming a device torch cannot use here
    root = default_dir("TORCH_EDGEVF_PYG_ROOT", "pyg") if root is None else root
    cache_dir = default_dir("TORCH_EDGEVF_CACHE", "operators") if cache_dir is None else cache_dir
    pre = ComputeOperators(
        k_edge=k_edge,
        k_vertex=k_vertex,
        vertex_gradient=model == "diffusionnet",
        features="log_hks" if model == "edgefieldnet" else "hks",
        cache_dir=cache_dir,
    )
    ids = subset_ids(path, classes, limit)
    start = time.perf_counter()
    train_set = PSBGeometric(root, path, "train", ids, pre_transform=pre)
    test_set = PSBGeometric(root, path, "test", ids, pre_transform=pre)
    dataset_seconds = time.perf_counter() - start
    log.info("PSB: %d training and %d test meshes (%.1f s)", len(train_set), len(test_set), dataset_seconds)
    num_classes = int(torch.cat([train_set.y, test_set.y]).max()) + 1
    torch.manual_seed(seed)
    blocks = {} if num_blocks is None else {"num_blocks": num_blocks}
    net = (
        EdgeFieldNet(train_set.num_features, num_classes, width=width, **blocks)
        if model == "edgefieldnet"
        else DiffusionNet(train_set.num_features, num_classes, width=width, dropout=0.0, **blocks)
    ).to(device)
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    loader = DataLoader(
        train_set, batch_size=batch_size, shuffle=True, generator=torch.Generator().manual_seed(seed)
    )
    losses = []
    start = time.perf_counter()
    for epoch in range(epochs):
        total = 0.0
        for batch in loader:
            batch = batch.to(device)
            opt.zero_grad()
            loss = torch.nn.functional.cross_entropy(net(batch), batch.y, label_smoothing=0.2)
            loss.backward()
            opt.step()
            total += float(loss.detach()) * batch.num_graphs
        losses.append(total / len(train_set))
        log.info("epoch %d: loss %.4f", epoch, losses[-1])
    return {
        "num_train": len(train_set),
        "num_test": len(test_set),
        "num_classes": num_classes,
        "losses": losses,
        "train_accuracy": accuracy(net, train_set, device),
        "test_accuracy": accuracy(net, test_set, device),
        "train_seconds": time.perf_counter() - start,
        "dataset_seconds": dataset_seconds,
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="psb_watertight_2k.npz (default: $TORCH_EDGEVF_PSB)")
    parser.add_argument(
        "--root", default=None, help="the PyG dataset folder (default: $TORCH_EDGEVF_PYG_ROOT)"
    )
    parser.add_argument("--cache", default=None, help="operator cache (default: $TORCH_EDGEVF_CACHE)")
    parser.add_argument("--model", choices=MODELS, default="edgefieldnet")
    parser.add_argument(
        "--classes", type=int, default=None, help="the first K classes only (default: all 19)"
    )
    parser.add_argument("--limit", type=int, default=None, help="at most N training meshes per class")
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument("--batch-size", type=int, default=4)
    parser.add_argument("--device", default="cpu", help="where to train: cpu (default), cuda, ...")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    out = main(
        epochs=args.epochs,
        model=args.model,
        classes=args.classes,
        limit=args.limit,
        batch_size=args.batch_size,
        path=args.data,
        root=args.root,
        cache_dir=args.cache,
        device=args.device,
    )
    print(
        f"\nPSB with PyG: {out['num_train']} train / {out['num_test']} test meshes, {out['num_classes']} "
        f"classes: train accuracy {out['train_accuracy']:.3f}, test accuracy {out['test_accuracy']:.3f} "
        f"(chance {1 / out['num_classes']:.3f}); {out['train_seconds']:.0f} s training"
    )
