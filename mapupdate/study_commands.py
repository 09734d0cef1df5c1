"""The command of studies: ``sweep``."""

from __future__ import annotations

from studies.study_report import summarise
from studies.sweep import SweepError, run_sweep

from .extras import require


def sweep(args) -> int:
    require("pymunk", "matplotlib", "scipy")
    if args.summarise is not None:
        table = summarise(args.summarise)
        print(f"wrote {args.summarise}/results.csv, summary.md and figures ({table} runs)")
        return 0
    if args.spec is None or args.out is None:
        raise SweepError("mapupdate sweep needs SPEC.yaml and --out DIR (or --summarise DIR)")
    done = run_sweep(args.spec, args.out, workers=args.workers, ray=args.ray,
                     progress=not args.no_progress)
    print(f"wrote {args.out}/results.csv and summary.md ({done} runs)")
    return 0
