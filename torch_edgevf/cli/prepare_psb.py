"""``edgevf prepare-psb``: psb_watertight_2k.npz built from the PSB benchmark's OFF files."""

from __future__ import annotations


def cmd_prepare_psb(args) -> int:
    from ..learning.prepare import prepare_psb

    if not args.output.lower().endswith(".npz"):
        raise ValueError(f"OUT must be a .npz file, got {args.output}")
    if args.faces < 4:
        raise ValueError(f"--faces must be at least 4, got {args.faces}")
    result = prepare_psb(args.src_dir, args.output, faces=args.faces, show_progress=not args.quiet)
    skipped = f", left out: psb ids {result['skipped']}" if result["skipped"] else ""
    print(f"wrote {result['path']}: {result['meshes']} meshes{skipped}")
    return 0
