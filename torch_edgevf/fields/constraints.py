"""The hard constraints of :meth:`FieldDesigner.constrained`: checked, and eliminated (thesis 3.4).

A value constraint fixes ``z_e``; a direction constraint leaves one real unknown ``t_e``
with ``z_e = t_e w_e / |w_e|``. :func:`constraint_plan` gives the map ``P`` from the
remaining unknowns to ``(Re z, Im z)`` and the fixed values ``x_C`` (see
:mod:`torch_edgevf.fields.design`).
"""

from __future__ import annotations

import numpy as np
import torch

from .._validation import list_some
from .powers import _as_complex


def constraint_plan(edges, values, direction_edges, directions, ne: int, verts, cdtype) -> dict:
    """The elimination of the constraints on the ``ne`` edge values of a mesh (positions ``verts``).

    Returns ``rows``, ``cols``, ``coef`` (the nonzeros of ``P``), ``x_fixed``, ``m`` (the
    free real unknowns), ``has_values``, and the direction constraints' edges and unit
    directions; raises ``ValueError`` on out-of-range edges, mismatched lengths, a zero
    direction, contradictory constraints or no free unknown.
    """
    dtype, dev = verts.dtype, verts.device
    e_val, v_val = _check_pairs(edges, values, ne, "edges", "values", cdtype, dev)
    e_dir, w_dir = _check_pairs(direction_edges, directions, ne, "direction_edges", "directions", cdtype, dev)
    e_val, v_val = _dedupe(e_val, v_val, "values")
    e_dir, w_dir = _dedupe(e_dir, w_dir, "directions", parallel=True)
    zero = torch.nonzero(w_dir.detach().abs() == 0).flatten().tolist()
    if zero:
        raise ValueError(
            f"directions must be nonzero (a zero guide has no direction) at direction_edges "
            f"[{list_some(e_dir[zero].tolist())}]"
        )
    both = np.intersect1d(e_val.cpu().numpy(), e_dir.cpu().numpy())
    if both.size:
        raise ValueError(
            "contradictory constraints: edges given both a value and a direction "
            f"[{list_some(both.tolist())}]; give the value only"
        )
    kind = torch.zeros(ne, dtype=torch.int64, device=dev)  # 0 free, 1 value, 2 direction
    kind[e_val] = 1
    kind[e_dir] = 2
    free = torch.nonzero(kind == 0).flatten()
    nf, nd = free.numel(), e_dir.numel()
    m = 2 * nf + nd
    if m == 0:
        raise ValueError(f"the constraints fix all {ne} edges: no free unknown is left to design")
    ar_f = torch.arange(nf, device=dev)
    ar_d = torch.arange(nd, device=dev) + 2 * nf
    unit = w_dir / w_dir.abs()
    rows = torch.cat([free, free + ne, e_dir, e_dir + ne])
    cols = torch.cat([ar_f, ar_f + nf, ar_d, ar_d])
    coef = torch.cat([torch.ones(2 * nf, dtype=dtype, device=dev), unit.real.to(dtype), unit.imag.to(dtype)])
    x_fixed = torch.zeros(2 * ne, dtype=dtype, device=dev)
    if e_val.numel():
        x_fixed = x_fixed.index_put((e_val,), v_val.real.to(dtype)).index_put(
            (e_val + ne,), v_val.imag.to(dtype)
        )
    return {
        "rows": rows,
        "cols": cols,
        "coef": coef,
        "x_fixed": x_fixed,
        "m": m,
        "has_values": bool(e_val.numel()),
        "direction_edges": e_dir,
        "direction_units": unit,
    }


def _check_pairs(edges, values, ne: int, e_name: str, v_name: str, cdtype, dev):
    if (edges is None) != (values is None):
        raise ValueError(f"{e_name} and {v_name} must be given together")
    if edges is None:
        return (torch.zeros(0, dtype=torch.int64, device=dev), torch.zeros(0, dtype=cdtype, device=dev))
    edges = torch.as_tensor(edges, device=dev)
    if edges.is_floating_point() or edges.is_complex() or edges.dtype == torch.bool:
        raise ValueError(f"{e_name} must be an integer tensor, got {edges.dtype}")
    edges = edges.to(torch.int64).reshape(-1)
    bad = torch.nonzero((edges < 0) | (edges >= ne)).flatten()
    if bad.numel():
        raise ValueError(f"{e_name} out of range (the mesh has {ne} edges): {list_some(edges[bad].tolist())}")
    values = _as_complex(torch.as_tensor(values, device=dev), v_name)
    if values.shape != edges.shape:
        raise ValueError(
            f"{v_name} must have one value per edge of {e_name}: shape {tuple(edges.shape)}, "
            f"got {tuple(values.shape)}"
        )
    if not bool(torch.isfinite(values.detach()).all()):
        raise ValueError(f"{v_name} has NaN or Inf values")
    if values.dtype != cdtype:
        values = values.to(cdtype)
    return edges, values.to(dev)


def _dedupe(edges: torch.Tensor, values: torch.Tensor, name: str, parallel: bool = False):
    """Drop repeated edges with equal (or, for directions, parallel) values; raise otherwise."""
    if edges.numel() == 0:
        return edges, values
    uniq, inverse = torch.unique(edges, return_inverse=True)
    if uniq.numel() == edges.numel():
        return edges, values
    first = torch.full((uniq.numel(),), edges.numel(), dtype=torch.int64, device=edges.device)
    first = first.scatter_reduce(0, inverse, torch.arange(edges.numel(), device=edges.device), reduce="amin")
    ref = values[first][inverse].detach()
    v = values.detach()
    if parallel:
        clash = (ref.real * v.imag - ref.imag * v.real).abs() > 1e-12 * (ref.abs() * v.abs() + 1e-300)
    else:
        clash = (ref - v).abs() > 1e-12 * (ref.abs() + v.abs() + 1e-300)
    if bool(clash.any()):
        bad = torch.unique(edges[clash]).tolist()
        raise ValueError(f"contradictory constraints: edges given two different {name} [{list_some(bad)}]")
    return edges[first], values[first]
