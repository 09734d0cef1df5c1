"""Sweep benchmark: runs per minute on a local process pool against one process, Ray's
overhead per run, and how a 10 000-run study would split over a cluster.

The same study (generated 30 x 20 m warehouses, quick routes, four sessions, methods paper and
fuse; the layouts written beforehand, so only runs are timed) is run three times into fresh
folders: one run after another in this process (``--workers 1``), on a pool of ``--workers``
processes, and as Ray tasks on a local Ray of as many CPUs. Ray's overhead per run is its wall
time minus the pool's, divided by the runs (its start-up is listed apart), and the cost of an
empty task is measured too. The cluster table divides 10 000 runs of the measured cost over N
machines of this kind with the measured pool efficiency.

Bar (exit 1 when missed): the pool does at least 1.7x the runs per minute of one process on 2
cores, and Ray's overhead is at most 1 s per run.

    python benchmarks/bench_sweep.py [--layouts 3] [--seeds 2] [--workers 2]
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

# one thread per process, in this one and in the workers it starts (they inherit it): the pool
# is then compared with one process that uses one core, as each of its workers does
for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"

# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(Path(__file__).resolve().parents[1]))

STUDY_RUNS = 10_000


def write_spec(folder: Path, layouts: int, seeds: int) -> Path:
    """The layouts' files and a spec naming them (so no sweep times their generation)."""
    from scenarios.generator import write_generated

    files = [str(write_generated(100 + k, folder / f"layout_{k}.yaml")) for k in range(layouts)]
    spec = folder / "spec.yaml"
    spec.write_text(f"scenarios: {files}\nseeds: {list(range(1, seeds + 1))}\n"
                    "methods: [paper, fuse]\nquick: true\n")
    return spec


def timed_sweep(spec: Path, out: Path, **kw) -> float:
    from studies.sweep import run_sweep

    t0 = time.perf_counter()
    run_sweep(spec, out, progress=False, **kw)
    return time.perf_counter() - t0


def empty_task_cost(ray, n: int = 200) -> float:
    """[s] per task of a Ray task that does nothing, submitted n at a time."""
    @ray.remote
    def nothing():
        return None

    ray.get([nothing.remote() for _ in range(20)])        # workers started
    t0 = time.perf_counter()
    ray.get([nothing.remote() for _ in range(n)])
    return (time.perf_counter() - t0) / n


def _children_cpu() -> float:
    """[s] CPU time of the finished child processes (the pool's workers)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def measure(layouts: int, seeds: int, workers: int) -> dict:
    from studies import sweep_ray

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        spec = write_spec(tmp, layouts, seeds)
        n = layouts * seeds * 2
        # one run first, so that the kernels are compiled and cached before anything is timed
        timed_sweep(write_spec(tmp / "warm", 1, 1), tmp / "warm_out", workers=1)
        sequential = timed_sweep(spec, tmp / "sequential", workers=1)
        cpu0 = _children_cpu()
        pool = timed_sweep(spec, tmp / "pool", workers=workers)
        pool_cpu = _children_cpu() - cpu0
        t0 = time.perf_counter()
        ray = sweep_ray.start("auto", workers)
        ray_start = time.perf_counter() - t0
        on_ray = timed_sweep(spec, tmp / "ray", ray="auto", workers=workers)
        empty = empty_task_cost(ray)
        ray.shutdown()
    return {"runs": n, "workers": workers, "sequential_s": sequential, "pool_s": pool,
            "pool_cpu_s": pool_cpu,
            "ray_s": on_ray, "ray_start_s": ray_start, "empty_task_s": empty}


def print_tables(m: dict) -> bool:
    n, w = m["runs"], m["workers"]
    per_min = {k: 60.0 * n / m[f"{k}_s"] for k in ("sequential", "pool", "ray")}
    speedup = per_min["pool"] / per_min["sequential"]
    overhead = (m["ray_s"] - m["pool_s"]) / n
    print(f"| {n} runs (30 x 20 m, quick, 4 sessions) | wall s | runs per minute | "
          f"against one process |")
    print("|---|---|---|---|")
    for key, label in (("sequential", "one process"), ("pool", f"pool of {w}"),
                       ("ray", f"Ray, {w} CPUs")):
        print(f"| {label} | {m[f'{key}_s']:.1f} | {per_min[key]:.2f} | "
              f"{per_min[key] / per_min['sequential']:.2f}x |")
    print(f"\nThe pool's workers used {m['pool_cpu_s']:.1f} s of CPU in its {m['pool_s']:.1f} s: "
          f"{m['pool_cpu_s'] / m['pool_s']:.2f} cores busy on average (one process: "
          f"{m['sequential_s'] / n:.1f} s per run).")
    print(f"\nRay: start-up {m['ray_start_s']:.1f} s once; overhead per run against the pool "
          f"{overhead:+.2f} s; an empty task {1000 * m['empty_task_s']:.2f} ms.")
    cost = m["sequential_s"] / n                  # [s] of one core per run
    efficiency = speedup / w
    print(f"\n{STUDY_RUNS} runs at {cost:.1f} s each on one core, pool efficiency "
          f"{efficiency:.2f} per core:\n")
    print("| machines of 2 cores | cores | study wall time |")
    print("|---|---|---|")
    for machines in (1, 4, 16, 64):
        cores = 2 * machines
        hours = STUDY_RUNS * (cost / efficiency + max(overhead, 0.0)) / cores / 3600
        print(f"| {machines} | {cores} | {hours:.1f} h |")
    ok = (w < 2 or speedup >= 1.7) and overhead <= 1.0
    print(f"\nbars: pool {speedup:.2f}x (bar >= 1.7x on 2 cores), Ray overhead "
          f"{overhead:+.2f} s per run (bar <= 1 s): {'met' if ok else 'missed'}")
    return ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--layouts", type=int, default=3)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    return 0 if print_tables(measure(args.layouts, args.seeds, args.workers)) else 1


if __name__ == "__main__":
    raise SystemExit(main())
