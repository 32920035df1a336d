"""Fitting scene parameters to a measured force trace, candidates in parallel.

    import dmplatform as dm
    measured = dm.read_forces("measured.csv")          # or (t, force) arrays
    best = dm.fit("examples/scenes/tissue_press.json",
                  {"/objects/1/soft/youngs_modulus": (5e3, 8e4)},
                  measured, duration=2.0, out_dir="out/fit", log=True)
    best["value"]   # {"/objects/1/soft/youngs_modulus": 20110.0}

Each round is one sweep (dmplatform.sweep: on a Dask cluster, a
LocalCluster by default, or "serial"): a grid of `candidates` values per
parameter over the current bracket (log-spaced with log=True), each variant
scored by the RMS difference between its force trace's `column` and the
measured one at the measured times; the bracket then narrows to the best
candidate's neighbours. Rounds are written to out_dir/round_NN (a sweep's
folder: a restarted fit resumes). A grid search cannot stop in a local
minimum between candidates as a gradient method can, and every candidate of
a round runs at once. docs/sweeps.md, "Fitting".
"""
import json
import pathlib
import sys

import numpy as _np

from .sweeps import sweep


def _trace(measured, column):
    """(t, values) of a measured trace: read_forces's structured array, or a
    pair of arrays."""
    if isinstance(measured, _np.ndarray) and measured.dtype.names:
        return _np.asarray(measured["t"], float), _np.asarray(measured[column], float)
    t, f = measured
    return _np.asarray(t, float), _np.asarray(f, float)


def _grid(lo, hi, n, log):
    if n == 1:
        return [_np.sqrt(lo * hi) if log else 0.5 * (lo + hi)]
    return list(_np.geomspace(lo, hi, n) if log else _np.linspace(lo, hi, n))


def score(forces_csv, t, f, column="fz"):
    """RMS difference (N) between a run's forces.csv column, interpolated at
    the times t, and the values f."""
    from . import read_forces

    run = read_forces(forces_csv)
    sim = _np.interp(t, run["t"], run[column])
    return float(_np.sqrt(_np.mean((sim - f) ** 2)))


def fit(scene, parameters, measured, duration, out_dir, client=None, candidates=7, rounds=3, log=False,
        column="fz", progress=None):
    """Fits `parameters` ({json pointer: (low, high)}) of `scene` so that its
    force trace's `column` matches `measured`; returns {"value": {pointer:
    estimate} (the last round's best candidate refined by a parabola through
    its RMS and its neighbours'), "candidate": {pointer: the best candidate
    run}, "rms": its RMS (N), "rounds": [{"bracket", "table"}]} (see the
    module doc).
    A candidate that fails is scored inf; a round where every one failed
    raises RuntimeError naming the first error."""
    if candidates < 3:
        raise ValueError(f"candidates={candidates}: at least 3 per parameter, to narrow around the best")
    for p, b in parameters.items():
        lo, hi = b
        if not (lo < hi) or (log and lo <= 0):
            raise ValueError(f"parameter {p!r}: bracket {b} must be (low, high) with low < high"
                             + (" and low > 0 for log=True" if log else ""))
    t, f = _trace(measured, column)
    out_dir = pathlib.Path(out_dir)
    bracket = {p: tuple(map(float, b)) for p, b in parameters.items()}
    history = []
    best = None
    for r in range(rounds):
        axes = {p: _grid(lo, hi, candidates, log) for p, (lo, hi) in bracket.items()}
        folder = out_dir / f"round_{r:02d}"
        table = sweep(scene, axes, folder, duration, client=client, progress=progress)  # the grid: their product
        for row in table:
            forces = folder / "variants" / f"{row['variant']:05d}" / "forces.csv"
            row["rms"] = score(forces, t, f, column) if not row["error"] and forces.exists() else _np.inf
        ok = [row for row in table if _np.isfinite(row["rms"])]
        if not ok:
            raise RuntimeError(f"round {r}: every candidate failed; the first: {table[0]['error']}")
        best = min(ok, key=lambda row: row["rms"])
        history.append({"bracket": dict(bracket), "table": table})
        (folder / "fit.json").write_text(json.dumps({"bracket": bracket, "best": best}, indent=2, default=float))
        # Narrow each parameter to the best candidate's neighbours on its axis.
        for p, values in axes.items():
            i = int(_np.argmin(_np.abs(_np.array(values) - best[p])))
            bracket[p] = (values[max(i - 1, 0)], values[min(i + 1, len(values) - 1)])
    return {"value": _refine(history[-1]["table"], best, parameters, log),
            "candidate": {p: best[p] for p in parameters}, "rms": best["rms"], "rounds": history}


def _refine(table, best, parameters, log):
    """Each parameter's minimum of the parabola through the best candidate's
    RMS and its two neighbours' on that parameter's axis (the others held),
    in log space with log=True; the best candidate's value where it lies on
    the bracket's edge or the three do not make a minimum."""
    out = {}
    for p in parameters:
        line = sorted((row[p], row["rms"]) for row in table
                      if all(row[q] == best[q] for q in parameters if q != p) and _np.isfinite(row["rms"]))
        xs = [x for x, _ in line]
        i = xs.index(best[p])
        out[p] = best[p]
        if 0 < i < len(line) - 1:
            (x0, y0), (x1, y1), (x2, y2) = line[i - 1], line[i], line[i + 1]
            if log:
                x0, x1, x2 = _np.log(x0), _np.log(x1), _np.log(x2)
            den = (x0 - x1) * (x0 - x2) * (x1 - x2)
            a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / den
            b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / den
            if a > 0:
                x = min(max(-b / (2 * a), x0), x2)
                out[p] = float(_np.exp(x) if log else x)
    return out


def _main(argv):
    import argparse

    p = argparse.ArgumentParser(prog="python3 -m dmplatform.fit",
                                description="Fit scene parameters to a measured force trace (docs/sweeps.md).")
    p.add_argument("fit", help='FIT.json: {"scene", "parameters": {pointer: [low, high]}, "measured": '
                               'forces.csv, "duration", "out_dir", optional "candidates", "rounds", "log", '
                               '"column"}')
    p.add_argument("--scheduler", help="a Dask scheduler's address, e.g. tcp://HOST:8786")
    p.add_argument("--serial", action="store_true", help="run the candidates one after the other here")
    args = p.parse_args(argv)
    from . import Error, read_forces

    spec_path = pathlib.Path(args.fit)
    spec = json.loads(spec_path.read_text())
    known = {"scene", "parameters", "measured", "duration", "out_dir", "candidates", "rounds", "log", "column"}
    unknown = sorted(set(spec) - known)
    if unknown:
        print(f"{spec_path}: unknown key {unknown[0]!r} (known: {', '.join(sorted(known))})", file=sys.stderr)
        return 2
    base = spec_path.parent
    client = "serial" if args.serial else None
    if args.scheduler:
        from distributed import Client

        client = Client(args.scheduler)
    try:
        result = fit(base / spec["scene"], {k: tuple(v) for k, v in spec["parameters"].items()},
                     read_forces(base / spec["measured"]), float(spec["duration"]), base / spec["out_dir"],
                     client=client, candidates=int(spec.get("candidates", 7)), rounds=int(spec.get("rounds", 3)),
                     log=bool(spec.get("log", False)), column=spec.get("column", "fz"))
    except (Error, ValueError, KeyError, RuntimeError, OSError) as e:
        print(f"{spec_path}: {e}", file=sys.stderr)
        return 1
    out = {"value": result["value"], "candidate": result["candidate"], "rms": result["rms"]}
    (base / spec["out_dir"] / "fit.json").write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
