"""The design example runs and its output makes sense (examples are tests)."""

import numpy as np
import torch

from conftest import load_example


def test_design_spot_example(tmp_path):
    result = load_example("design_spot").main(out_dir=tmp_path)
    data = np.load(result["path"])
    nf, ne = data["faces"].shape[0], data["edges"].shape[0]
    for name in ("smoothest", "curvature"):
        assert data[f"z_{name}"].shape == (ne,)
        d = data[f"face_directions_{name}"]
        assert d.shape == (nf, 4, 3)
        # the four directions are tangent to the faces and turn by 90 degrees
        p = data["verts"][data["faces"]]
        normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        assert np.abs((d * normal[:, None]).sum(-1)).max() < 1e-10 * max(1.0, np.abs(d).max())
        assert np.abs((d[:, 0] * d[:, 1]).sum(-1)).max() < 1e-10 * max(1.0, np.abs(d).max() ** 2)
        assert data[f"vertex_directions_{name}"].shape == (data["verts"].shape[0], 4, 3)
    # the smoothest field's eigenvalue is its Rayleigh quotient; the aligned field follows
    # the curvature much better than the smoothest one
    assert result["eigenvalue"] > 0
    assert float(data["eigenvalue"]) == result["eigenvalue"]
    assert result["alignment"]["curvature"] > 0.5
    assert result["alignment"]["curvature"] > 2 * result["alignment"]["smoothest"]
    assert torch.is_tensor(result["smoothest"])
