"""A batch of scripted SITL flights: each method on the same seeds, flights in parallel pairs.

    python examples/sitl_batch.py --seeds 1 2 --speedup 10

Each flight is a real simulator process talking MAVLink and radio datagrams to the GCS on its
own free loopback ports; results are printed as a table.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ThreadPoolExecutor

from mexgen_gcs.mission.run import SitlPorts, run_sitl


def fly(method: str, seed: int, speedup: float) -> tuple[str, int, str, float | None]:
    r = run_sitl("missions/demo.yaml", seed=seed, speedup=speedup, method=method,
                 ports=SitlPorts.free(), log_dir="flights/batch")
    done = [i["after_s"] for i in r.localised.values()]
    return method, seed, r.end_reason, max(done) if len(done) == 4 else None


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    p.add_argument("--methods", nargs="+", default=["mexgen", "pim"])
    p.add_argument("--speedup", type=float, default=10.0)
    a = p.parse_args()
    jobs = [(m, s) for s in a.seeds for m in a.methods]
    with ThreadPoolExecutor(max_workers=2) as pool:
        rows = list(pool.map(lambda job: fly(job[0], job[1], a.speedup), jobs))
    print(f"{'method':<8} {'seed':>4}  {'end':<16} all localised after")
    for method, seed, end, t in rows:
        print(f"{method:<8} {seed:>4}  {end:<16} {'-' if t is None else f'{t:.0f} s'}")


if __name__ == "__main__":
    main()
