"""Test accuracy of a run's intermediate checkpoints: how far a network is from the end of
its learning when the protocol's epochs end.

    python experiments/rna_segmentation/curve.py --data DIR --split SPLIT.json --model diffusionnet \\
        --checkpoints RUNS/split_random1-diffusionnet-seed0-e5.pt ... --json curve.json

Each checkpoint is one written by ``run.py`` (``--run-dir``; a copy taken after some epoch);
its weights are scored as ``run.py`` scores the final ones: every vertex of the test files
of the split (at the file's resolution), each file read once for all the checkpoints. The
curve measures how much accuracy the last epochs still add; it does not choose weights (the
study reports the final ones only).

With ``--part train`` it scores training meshes instead, as the network was trained on them
(decimated), with dropout off: a network that scores no better there than on the test files
is short of capacity or training, not overfitting. (The rows' ``test_*`` keys then hold the
scores of that part.)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import run as rna_run  # noqa: E402

from torch_edgevf.learning.datasets.rna import RNADataset, rna_path, rna_split  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=None, help="the dataset folder (default: $TORCH_EDGEVF_RNA)")
    p.add_argument("--split", default=None, help="the split file of the run (default: official)")
    p.add_argument("--model", required=True, choices=rna_run.MODELS)
    p.add_argument("--checkpoints", nargs="+", required=True, help="checkpoints written by run.py")
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--inputs", choices=rna_run.INPUTS, default="loghks")
    p.add_argument(
        "--part",
        choices=("test", "train"),
        default="test",
        help="score the test files (default), or the training meshes as trained (decimated, in eval mode)",
    )
    p.add_argument("--target-vertices", type=int, default=5000, help="the runs' decimation (train part)")
    p.add_argument("--limit", type=int, default=None, help="first N meshes of the part only")
    p.add_argument("--cache", default=rna_run.DEFAULT_CACHE, help="operator cache folder (as run.py's)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--json", default=None, help="write the rows here")
    a = p.parse_args(argv)
    torch.set_num_threads(a.threads)
    missing = [c for c in a.checkpoints if not Path(c).is_file()]
    try:
        if missing:
            raise ValueError(f"no checkpoint file at {', '.join(missing)}")
        root = rna_path(a.data)
        names = rna_split(root, a.split)[a.part][: a.limit]
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    target = a.target_vertices if a.part == "train" else None
    test = RNADataset(
        root, names, target_vertices=target, in_memory=False, **rna_run.dataset_options(a.cache, a.inputs)
    )
    rows, models = [], []
    for path in a.checkpoints:
        saved = torch.load(path, weights_only=False)
        model = rna_run.build_model(a.model, test[0].features.shape[1], a.width)
        model.load_state_dict(saved["model"])
        models.append(model)
        history = saved["state"]["history"]
        rows.append(
            {
                "model": a.model,
                "split": Path(a.split).name if a.split else "official",
                "part": a.part,
                "meshes": len(names),
                "checkpoint": Path(path).name,
                "epoch": saved["state"]["epoch"],
                "train_accuracy": history[-1]["train_accuracy"] if history else None,
            }
        )
    for row, scored in zip(rows, rna_run.evaluate_many(models, test), strict=True):
        row.update(scored)
        print(
            f"{row['checkpoint']}: epoch {row['epoch']}, test accuracy {row['test_accuracy']:.4f}, "
            f"mIoU {row['test_miou']:.4f}",
            flush=True,
        )
    if a.json:
        Path(a.json).write_text(json.dumps({"curve": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
