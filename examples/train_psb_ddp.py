"""PSB classification (example ``train_psb.py``) with DistributedDataParallel on CPU.

``world_size`` processes on this machine (gloo backend, rendezvous on 127.0.0.1 at a free
port) each train a replica of :class:`~torch_edgevf.learning.models.EdgeFieldNet` on their shard
of the training set (``DistributedSampler``); DDP averages the gradients, so the replicas
stay identical. The operators come from the shared on-disk cache, which the parent
process fills first (entries are written atomically, so concurrent readers are safe).
Rank 0 evaluates on the test set.

The workers are started with the ``spawn`` method: a fresh interpreter per rank. Forking
after the parent has started torch's OpenMP threads (it has, once the operator cache is
filled) can deadlock the child, and did hang the two-process test. Each child runs this
file by path (see :func:`_spawn_workers`), so the example works both as a script and
loaded by path, as the tests load it.
Run ``python examples/train_psb_ddp.py``.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import os
import socket
import tempfile
import time
from pathlib import Path

import torch
import torch.distributed as dist
from torch.nn.parallel import DistributedDataParallel

from torch_edgevf.learning import collate_meshes

log = logging.getLogger(__name__)


def _train_psb():
    """The sibling example module (works when this file is imported by path)."""
    spec = importlib.util.spec_from_file_location("train_psb", Path(__file__).with_name("train_psb.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _spawn_workers(world_size: int, args: tuple) -> None:
    """Run ``_worker(rank, *args)`` in ``world_size`` fresh interpreters and wait for them.

    ``spawn`` pickles the target by reference, and this file is a script, not an
    importable module (the tests load it by path).  The target is therefore
    :func:`runpy.run_path` on this file under the name ``__ddp_worker__``, which calls
    :func:`_worker` at the end of the file, whichever way the parent loaded it.
    """
    import multiprocessing
    import runpy

    ctx = multiprocessing.get_context("spawn")
    procs = [
        ctx.Process(
            target=runpy.run_path,
            args=(str(Path(__file__).resolve()),),
            kwargs=dict(init_globals={"_WORKER_ARGS": (rank, world_size) + args}, run_name="__ddp_worker__"),
        )
        for rank in range(world_size)
    ]
    for proc in procs:
        proc.start()
    try:
        for proc in procs:
            proc.join()
    finally:
        for proc in procs:
            if proc.is_alive():  # another rank failed and this one waits on it in a collective
                proc.terminate()
                proc.join()
    failed = {rank: proc.exitcode for rank, proc in enumerate(procs) if proc.exitcode != 0}
    if failed:
        raise RuntimeError(f"DDP workers failed (rank: exit code): {failed}")


def _worker(rank: int, world_size: int, port: int, cfg: dict, out_path: str) -> None:
    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world_size)
    try:
        tp = _train_psb()
        train_set, test_set = tp.load_datasets(cfg["ids"], cfg["k_edge"], cfg["k_vertex"], cfg["cache_dir"])
        torch.manual_seed(cfg["seed"])  # same initial weights on every rank (DDP also broadcasts them)
        model = tp.make_model(
            cfg["model"],
            len(train_set.classes),
            train_set[0].features.shape[1],
            cfg["width"],
            cfg["num_blocks"],
        )
        ddp = DistributedDataParallel(model)
        opt = torch.optim.AdamW(ddp.parameters(), lr=cfg["lr"], weight_decay=1e-4)
        sampler = torch.utils.data.distributed.DistributedSampler(
            train_set, num_replicas=world_size, rank=rank, shuffle=True, seed=cfg["seed"]
        )
        loader = torch.utils.data.DataLoader(
            train_set, batch_size=cfg["batch_size"], sampler=sampler, collate_fn=collate_meshes
        )
        steps, losses = 0, []
        start = time.perf_counter()
        for epoch in range(cfg["epochs"]):
            sampler.set_epoch(epoch)
            for batch in loader:
                opt.zero_grad()
                loss = torch.nn.functional.cross_entropy(ddp(batch), batch.labels)
                loss.backward()
                opt.step()
                losses.append(float(loss.detach()))
                steps += 1
                if cfg["max_steps"] is not None and steps >= cfg["max_steps"]:
                    break
            if cfg["max_steps"] is not None and steps >= cfg["max_steps"]:
                break
        seconds = time.perf_counter() - start
        # replicas must be identical: compare a checksum of the parameters across ranks
        flat = torch.cat([p.detach().reshape(-1).double() for p in model.parameters()])
        checksums = [torch.zeros(2, dtype=torch.float64) for _ in range(world_size)]
        dist.all_gather(checksums, torch.stack([flat.sum(), (flat**2).sum()]))
        in_sync = all(torch.allclose(c, checksums[0], rtol=1e-6, atol=1e-8) for c in checksums)
        if rank == 0:
            result = {
                "world_size": world_size,
                "steps": steps,
                "losses": losses,
                "train_seconds": seconds,
                "params_in_sync": bool(in_sync),
                "test_accuracy": tp.evaluate(model, test_set),
                "num_train": len(train_set),
                "num_test": len(test_set),
            }
            Path(out_path).write_text(json.dumps(result))
        # tear down together: a rank that destroyed its process group while rank 0 (which
        # hosts the TCP store) was still evaluating aborted now and then in gloo's teardown
        # ("terminate called without an active exception", about 1 run in 8)
        dist.barrier()
    finally:
        dist.destroy_process_group()


def main(
    world_size: int = 2,
    epochs: int = 2,
    max_steps: int | None = None,
    model: str = "edgefieldnet",
    width: int = 16,
    num_blocks: int = 2,
    batch_size: int = 4,
    lr: float = 3e-3,
    k_edge: int = 32,
    k_vertex: int = 128,
    ids=None,
    cache_dir=None,
    seed: int = 0,
) -> dict:
    """Train with DDP on ``world_size`` local processes; returns rank 0's results."""
    tp = _train_psb()
    cache_dir = str(tp.default_cache_dir() if cache_dir is None else cache_dir)
    tp.load_datasets(ids, k_edge, k_vertex, cache_dir)  # fill the cache once, in the parent
    cfg = dict(
        epochs=epochs,
        max_steps=max_steps,
        model=model,
        width=width,
        num_blocks=num_blocks,
        batch_size=batch_size,
        lr=lr,
        k_edge=k_edge,
        k_vertex=k_vertex,
        ids=None if ids is None else list(ids),
        cache_dir=cache_dir,
        seed=seed,
    )
    with tempfile.TemporaryDirectory() as tmp:
        out_path = os.path.join(tmp, "result.json")
        _spawn_workers(world_size, (free_port(), cfg, out_path))
        return json.loads(Path(out_path).read_text())


if __name__ == "__ddp_worker__":  # a spawned rank (see _spawn_workers)
    _worker(*_WORKER_ARGS)  # noqa: F821 (set by runpy.run_path)

if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    out = main()
    print(
        f"DDP x{out['world_size']}: {out['steps']} steps in {out['train_seconds']:.0f} s, "
        f"loss {out['losses'][0]:.3f} -> {out['losses'][-1]:.3f}, replicas in sync: {out['params_in_sync']}, "
        f"test accuracy {out['test_accuracy']:.3f}"
    )
