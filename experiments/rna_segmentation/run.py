"""Per-vertex segmentation of RNA molecular surfaces: the edge-field network against DiffusionNet.

The RNA Surface Segmentation Dataset (Poulenard et al. 2019; DiffusionNet's benchmark),
read as published (``--data``: the folder of
``git clone https://github.com/nmwsharp/RNA-Surface-Segmentation-Dataset``). Protocol,
the same for every model (see README.md):

- training meshes decimated to about ``--target-vertices`` vertices (quadric edge
  collapse), labels from the nearest vertex of the file; test meshes at the file's
  resolution (repaired only), every vertex of the file scored (unreferenced ones through
  the nearest vertex of the mesh);
- inputs: 16 heat kernel signatures (intrinsic: no alignment or augmentation needed);
- Adam at 1e-3, halved every quarter of the epochs, one mesh per step, cross-entropy;
  the final weights are evaluated, once, after the last epoch.

Each run writes its log and a checkpoint per epoch under ``--run-dir`` and resumes from
it. ``--json OUT`` writes ``{"results": [...]}``, one row per model and seed.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

from torch_edgevf.learning import resolve_device
from torch_edgevf.learning.batching import collate_meshes
from torch_edgevf.learning.datasets.rna import RNA_CLASSES, RNADataset, rna_path, rna_split
from torch_edgevf.learning.models import DiffusionNet, EdgeFieldNet

HERE = Path(__file__).resolve().parent
#: the operator cache of the study's commands: $TORCH_EDGEVF_CACHE, else ~/.cache/torch_edgevf/rna
DEFAULT_CACHE = os.environ.get("TORCH_EDGEVF_CACHE", str(Path.home() / ".cache" / "torch_edgevf" / "rna"))

#: the networks, by name: the recommended edge-field network (the library's EdgeFieldNet with
#: its defaults for a per-vertex head: local edge fields), the faithful DiffusionNet, and the
#: edge network's ablations (smooth fields, the default for one output per mesh; no vector
#: stream; vertex gradients in place of G; smooth fields with their divergence and curl added
#: to the MLPs, the PSB study's variant)
MODELS = (
    "edgefieldnet",
    "diffusionnet",
    "edgefieldnet-smooth",
    "edgefieldnet-scalar",
    "edgefieldnet-vertexvec",
    "edgefieldnet-divcurl",
)
DEFAULT_MODELS = ("edgefieldnet", "diffusionnet")


#: the inputs: the logarithms of the heat kernel signatures (default), or the signatures
INPUTS = ("loghks", "hks")


def build_model(name: str, in_channels: int, width: int) -> torch.nn.Module:
    """Network ``name`` with a per-vertex head, ``width`` channels and 4 blocks (DiffusionNet's
    RNA configuration, 4 x 128, for every model). The inputs (the signatures or their
    logarithms, ``--inputs``) are the datasets' features."""
    common = dict(width=width, num_blocks=4, mlp=(width, width), head="vertex")
    if name == "diffusionnet":
        return DiffusionNet(in_channels, RNA_CLASSES, **common)
    if name == "edgefieldnet-divcurl":
        sys.path.insert(0, str(HERE.parent / "psb_classification"))
        from variants import StudyEdgeFieldNet

        # the divergence and curl of the fields in the MLPs as well
        return StudyEdgeFieldNet(in_channels, RNA_CLASSES, vector_width=width // 4, divergence=True, **common)
    # edgefieldnet: the library's defaults, local fields M_z^-1 G (xd W) on every edge (no L_c
    # diffusion, no eigenbasis); smooth: the fields diffused in the truncated L_c eigenbasis
    vector, fields = {
        "edgefieldnet": ("edge", None),
        "edgefieldnet-smooth": ("edge", "smooth"),
        "edgefieldnet-scalar": ("none", None),
        "edgefieldnet-vertexvec": ("vertex", None),
    }[name]
    return EdgeFieldNet(
        in_channels, RNA_CLASSES, vector_width=width // 4, vector=vector, fields=fields, **common
    )


def dataset_options(cache: str | None, inputs: str = "loghks") -> dict:
    """The options of :class:`RNADataset` for every network of the study (one cache entry per
    mesh: 32 eigenpairs of ``L_c``, 128 of the vertex Laplacian, the vertex gradient)."""
    return dict(
        cache_dir=cache,
        k_edge=32,
        k_vertex=128,
        vertex_gradient=True,
        show_progress=False,
        log_hks=inputs == "loghks",
    )


def confusion(pred: np.ndarray, truth: np.ndarray, classes: int = RNA_CLASSES) -> np.ndarray:
    return np.bincount(truth * classes + pred, minlength=classes * classes).reshape(classes, classes)


def scores(conf: np.ndarray) -> tuple[float, float]:
    """Per-vertex accuracy and mean IoU over the classes present in the ground truth."""
    tp = np.diag(conf).astype(np.float64)
    present = conf.sum(1) > 0
    union = conf.sum(0) + conf.sum(1) - tp
    iou = tp[present] / union[present]
    return float(tp.sum() / conf.sum()), float(iou.mean())


@torch.no_grad()
def evaluate(model, dataset: RNADataset, device="cpu") -> dict:
    """Accuracy and mIoU on the file's vertices of every mesh of ``dataset`` (and on the
    network's vertices), the network run on ``device``."""
    return evaluate_many([model], dataset, device)[0]


def evaluate_many(models: list, dataset: RNADataset, device="cpu") -> list[dict]:
    """:func:`evaluate` of several networks, each mesh read once for all of them."""
    conf = np.zeros((len(models), 2, RNA_CLASSES, RNA_CLASSES), dtype=np.int64)
    for model in models:
        model.eval()
    with torch.no_grad():
        for i, mesh in enumerate(dataset.meshes):
            batch = collate_meshes([dataset[i]]).to(device)
            for m, model in enumerate(models):
                pred = model(batch).argmax(-1).cpu()
                conf[m, 0] += confusion(mesh.carry_back(pred).numpy(), mesh.labels)
                conf[m, 1] += confusion(pred.numpy(), mesh.mesh_labels)
    rows = []
    for m, model in enumerate(models):
        model.train()
        acc, miou = scores(conf[m, 0])
        rows.append(
            {
                "test_accuracy": acc,
                "test_miou": miou,
                "test_vertices": int(conf[m, 0].sum()),
                "test_accuracy_mesh_vertices": scores(conf[m, 1])[0],
            }
        )
    return rows


def log(path: Path, message: str) -> None:
    line = f"{time.strftime('%H:%M:%S')} {message}"
    print(line, flush=True)
    with path.open("a") as fh:
        fh.write(line + "\n")


def train_run(
    name,
    seed,
    train_set,
    test_sets: dict,
    epochs,
    width,
    run_dir: Path,
    tag: str,
    inputs: str,
    device="cpu",
) -> dict:
    """Train one model (resuming from its checkpoint) on ``device`` and evaluate its final
    weights on each of ``test_sets`` (by resolution, the first the reported one)."""
    stem = f"{tag}{name}-seed{seed}"
    ckpt, logfile = run_dir / f"{stem}.pt", run_dir / f"{stem}.log"
    torch.manual_seed(seed)
    in_channels = train_set[0].features.shape[1]
    model = build_model(name, in_channels, width).to(device)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=max(1, epochs // 4), gamma=0.5)
    order = torch.Generator().manual_seed(seed)
    state = {"epoch": 0, "seconds": 0.0, "history": []}
    if ckpt.exists():
        saved = torch.load(ckpt, weights_only=False)
        model.load_state_dict(saved["model"])
        opt.load_state_dict(saved["optimizer"])
        sched.load_state_dict(saved["scheduler"])
        order.set_state(saved["order"])
        torch.set_rng_state(saved["rng"])
        state = saved["state"]
        log(logfile, f"resumed {stem} after epoch {state['epoch']}")
    for epoch in range(state["epoch"], epochs):
        start = time.perf_counter()
        loss_sum, correct, total = 0.0, 0, 0
        for i in torch.randperm(len(train_set), generator=order).tolist():
            batch = collate_meshes([train_set[i]]).to(device)  # operators computed on the CPU
            opt.zero_grad()
            logits = model(batch)
            loss = torch.nn.functional.cross_entropy(logits, batch.labels)
            loss.backward()
            opt.step()
            loss_sum += float(loss.detach())
            correct += int((logits.argmax(-1) == batch.labels).sum())
            total += int(batch.labels.numel())
        sched.step()
        seconds = time.perf_counter() - start
        state["seconds"] += seconds
        state["epoch"] = epoch + 1
        state["history"].append(
            {
                "epoch": epoch + 1,
                "loss": loss_sum / len(train_set),
                "train_accuracy": correct / total,
                "seconds": seconds,
            }
        )
        torch.save(
            {
                "model": model.state_dict(),
                "optimizer": opt.state_dict(),
                "scheduler": sched.state_dict(),
                "order": order.get_state(),
                "rng": torch.get_rng_state(),
                "state": state,
            },
            ckpt,
        )
        log(
            logfile,
            f"{stem} epoch {epoch + 1}/{epochs} loss {loss_sum / len(train_set):.4f} "
            f"train acc {correct / total:.4f} {seconds:.0f} s",
        )
    result = {
        "model": name,
        "seed": seed,
        "epochs": epochs,
        "width": width,
        "inputs": inputs,
        "parameters": sum(p.numel() for p in model.parameters()),
        "train_seconds": state["seconds"],
        "seconds_per_step": state["seconds"] / max(1, epochs * len(train_set)),
        "train_accuracy": state["history"][-1]["train_accuracy"] if state["history"] else None,
        "history": state["history"],
    }
    for i, (resolution, test_set) in enumerate(test_sets.items()):
        scored = evaluate(model, test_set, device)
        if i == 0:
            result.update(scored, test_resolution=resolution)
        else:
            result.update({f"{k}_{resolution}": v for k, v in scored.items()})
    log(logfile, f"{stem} test accuracy {result['test_accuracy']:.4f} mIoU {result['test_miou']:.4f}")
    return result


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=None, help="the dataset folder (default: $TORCH_EDGEVF_RNA)")
    p.add_argument(
        "--split", default=None, help='JSON {"train": [names], "test": [names]} (default: official)'
    )
    p.add_argument("--models", nargs="+", default=list(DEFAULT_MODELS), choices=MODELS)
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("--epochs", type=int, default=20)
    p.add_argument("--json", default=None, help="write the results here")
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--inputs", choices=INPUTS, default="loghks", help="the same for every model")
    p.add_argument("--target-vertices", type=int, default=5000, help="decimation of the training meshes")
    p.add_argument(
        "--test-resolution",
        nargs="+",
        choices=("file", "decimated"),
        default=["file", "decimated"],
        help="test meshes at the file's resolution, decimated as the training meshes, or both "
        "(default); the first gives test_accuracy and test_miou, the second test_accuracy_<name>",
    )
    p.add_argument("--limit", type=int, default=None, help="first N training and N test meshes only")
    p.add_argument(
        "--cache",
        default=DEFAULT_CACHE,
        help="operator cache folder (default: $TORCH_EDGEVF_CACHE or ~/.cache/torch_edgevf/rna)",
    )
    p.add_argument("--run-dir", default=str(HERE / "runs"), help="logs and checkpoints")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument(
        "--device", default="cpu", help="where the networks train: cpu (default), cuda, cuda:1, mps, ..."
    )
    p.add_argument("--precompute-only", action="store_true", help="fill the operator cache and stop")
    a = p.parse_args(argv)
    if a.epochs < 1 or a.width < 4 or a.target_vertices < 100:
        p.error("--epochs >= 1, --width >= 4 and --target-vertices >= 100 are needed")
    return a


def main(argv=None) -> int:
    a = parse(argv)
    torch.set_num_threads(a.threads)
    try:
        device = resolve_device(a.device)
        root = rna_path(a.data)
        split = rna_split(root, a.split)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    if a.limit is not None:
        split = {k: v[: a.limit] for k, v in split.items()}
    run_dir = Path(a.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    options = dataset_options(a.cache, a.inputs)
    start = time.perf_counter()
    # the training meshes stay in memory (about 10 MB each), the test meshes are read once
    train_set = RNADataset(root, split["train"], target_vertices=a.target_vertices, **options)
    test_sets = {
        res: RNADataset(
            root,
            split["test"],
            target_vertices=None if res == "file" else a.target_vertices,
            in_memory=False,
            **options,
        )
        for res in dict.fromkeys(a.test_resolution)
    }
    test_set = next(iter(test_sets.values()))
    precompute = time.perf_counter() - start
    computed = dict(train_set.seconds)
    skipped = train_set.skipped + [s for t in test_sets.values() for s in t.skipped]
    names = ": " + ", ".join(n for n, _ in skipped) if skipped else ""
    print(
        f"{len(train_set)} training and {len(test_set)} test meshes ({len(computed)} computed in "
        f"{precompute:.0f} s, {len(skipped)} skipped{names})",
        flush=True,
    )
    empty = ["training"] if not len(train_set) else []
    empty += ["test"] if not all(len(t) for t in test_sets.values()) else []
    if empty:
        reasons = list(dict.fromkeys(why for _, why in skipped))
        more = f" (and {len(reasons) - 3} more)" if len(reasons) > 3 else ""
        print(
            f"error: no {' and no '.join(empty)} mesh could be used: {'; '.join(reasons[:3])}{more}",
            file=sys.stderr,
        )
        return 2
    if a.precompute_only:
        return 0
    tag = "" if a.split is None else Path(a.split).stem + "-"
    if a.inputs != "loghks":
        tag += f"{a.inputs}-"
    if a.limit is not None:
        tag += f"limit{a.limit}-"
    results = []
    for seed in a.seeds:
        for name in a.models:
            r = train_run(name, seed, train_set, test_sets, a.epochs, a.width, run_dir, tag, a.inputs, device)
            r.update(
                split=Path(a.split).name if a.split else "official",
                target_vertices=a.target_vertices,
                train_meshes=len(train_set),
                test_meshes=len(test_set),
                # mean seconds per training mesh, where this run computed them (else None)
                precompute_seconds=(sum(computed.values()) / len(computed)) if computed else None,
                skipped=[n for n, _ in skipped],
            )
            results.append(r)
            print(
                f"{name} seed {seed}: test accuracy {r['test_accuracy']:.4f}, mIoU {r['test_miou']:.4f}, "
                f"{r['seconds_per_step']:.3f} s per step",
                flush=True,
            )
    if a.json:
        Path(a.json).write_text(json.dumps({"results": results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
