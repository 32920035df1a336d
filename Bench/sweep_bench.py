#!/usr/bin/python3
"""sweep_bench — throughput of dmplatform.sweep: the same lockstep variants
of examples/scenes/osteotomy.json (the bone-placement coupling stiffness,
8 values from 200 N/m; the whole 3.7 s placement each, without rendering:
about a second of work per variant, loading included) run one after the
other in this process, then on a Dask LocalCluster of 1 and of 2
single-threaded worker processes, each into a fresh folder. Prints variants
per second and the speed-up against the serial run (goal: >= 1.8x with 2
workers on 2 cores), and checks that every table equals the serial one.

    PYTHONPATH=build/Python /usr/bin/python3 Bench/sweep_bench.py [variants] [seconds]
"""
import pathlib
import sys
import tempfile
import time

import distributed

import dmplatform as dm
from dmplatform import sweeps


def main(argv):
    n = int(argv[1]) if len(argv) > 1 else 8
    seconds = float(argv[2]) if len(argv) > 2 else 3.7
    scene = dm.Scene.load(pathlib.Path(__file__).resolve().parents[1] / "examples/scenes/osteotomy.json")
    grid = {"/engines/haptics/bone_placement/coupling_stiffness": [200.0 + 25.0 * i for i in range(n)]}
    rows = {}
    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        rows["serial"] = sweeps.sweep(scene, grid, pathlib.Path(tmp) / "serial", seconds, client="serial")
        times["serial"] = time.perf_counter() - t
        for workers in (1, 2):
            with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                          dashboard_address=":0") as c, distributed.Client(c) as client:
                client.run(lambda: __import__("dmplatform"))  # workers up and the package loaded before timing
                t = time.perf_counter()
                rows[workers] = sweeps.sweep(scene, grid, pathlib.Path(tmp) / f"w{workers}", seconds, client=client)
                times[workers] = time.perf_counter() - t
    print(f"sweep_bench: {n} variants of osteotomy, {seconds:g} s each (lockstep, no rendering)")
    print(f"{'run':<10}{'wall_s':>10}{'variants/s':>12}{'speed-up':>10}  table")
    for k in ("serial", 1, 2):
        name = k if k == "serial" else f"{k} worker" + ("s" if k > 1 else "")
        same = "same" if rows[k] == rows["serial"] else "DIFFERS"
        print(f"{name:<10}{times[k]:>10.2f}{n / times[k]:>12.2f}{times['serial'] / times[k]:>10.2f}  {same}")
    return 0 if all(rows[k] == rows["serial"] for k in rows) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
