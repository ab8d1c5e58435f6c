"""A test molecule segmented by a trained network: ground truth, prediction and errors.

    python experiments/rna_segmentation/figure.py --data DIR --checkpoint runs/edgefieldnet-seed0.pt \\
        --mesh 3CXC_9 -o experiments/rna_segmentation/rna_segmentation.png

The checkpoint is one written by ``run.py`` (its final weights); the molecule is read at the
file's resolution and drawn with :func:`torch_edgevf.render.render_mesh`, one colour per
label (a face takes the label of its first vertex), errors in red.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import run as rna_run  # noqa: E402

from torch_edgevf.learning.batching import collate_meshes  # noqa: E402
from torch_edgevf.learning.datasets.rna import RNA_CLASSES, RNADataset, rna_path  # noqa: E402
from torch_edgevf.render import choose_camera, render_mesh  # noqa: E402


def palette(count: int = RNA_CLASSES, seed: int = 3) -> np.ndarray:
    """``count`` distinct light colours in a fixed random order (neighbouring labels differ)."""
    hues = np.random.default_rng(seed).permutation(count) / count
    sat = 0.45 + 0.35 * (np.arange(count) % 3) / 2
    rgb = np.abs((hues[:, None] * 6 + np.array([0, 4, 2])[None]) % 6 - 3) - 1
    return 1 - sat[:, None] * (1 - np.clip(rgb, 0, 1)) * 0.85


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=None)
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--model", default="edgefieldnet", choices=rna_run.MODELS)
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--inputs", choices=rna_run.INPUTS, default="loghks")
    p.add_argument("--mesh", default="3CXC_9")
    p.add_argument("--cache", default=None)
    p.add_argument("-o", "--output", default="rna_segmentation.png")
    a = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    options = rna_run.dataset_options(a.cache, a.inputs)
    ds = RNADataset(rna_path(a.data), [a.mesh], target_vertices=None, **options)
    mesh, sample = ds.meshes[0], ds[0]
    model = rna_run.build_model(a.model, sample.features.shape[1], a.width)
    model.load_state_dict(torch.load(a.checkpoint, weights_only=False)["model"])
    model.eval()
    with torch.no_grad():
        pred = model(collate_meshes([sample])).argmax(-1).numpy()
    truth = mesh.mesh_labels
    colours = palette()
    first = mesh.faces[:, 0]
    wrong = pred[first] != truth[first]
    error_colours = np.where(wrong[:, None], [[0.85, 0.1, 0.1]], [[0.92, 0.92, 0.92]])
    accuracy = float(np.mean(mesh.carry_back(torch.from_numpy(pred)).numpy() == mesh.labels))
    camera = choose_camera(mesh.verts, mesh.faces)
    panels = [
        ("ground truth", colours[truth[first]]),
        (f"{a.model}: prediction", colours[pred[first]]),
        (f"errors (red): accuracy {100 * accuracy:.1f}%", error_colours),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.4))
    with tempfile.TemporaryDirectory() as tmp:
        for ax, (title, face_colors) in zip(axes, panels):
            png = render_mesh(
                mesh.verts,
                mesh.faces,
                Path(tmp) / "panel.png",
                camera=camera,
                face_colors=face_colors,
                size=600,
            )
            ax.imshow(plt.imread(png))
            ax.set_title(title)
            ax.axis("off")
    fig.suptitle(
        f"RNA molecule {a.mesh} ({len(mesh.labels):,} vertices, test set), {len(np.unique(truth))} labels"
    )
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    fig.savefig(a.output, dpi=80)
    print(f"wrote {a.output}: accuracy {accuracy:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
