"""Sweeps: many lockstep variants of one scene, on a Dask cluster or here.

    import dmplatform as dm
    table = dm.sweep("examples/scenes/box_push.json",
                     {"/objects/1/mass": [0.1, 0.2, 0.4], "/objects/1/contact/friction": [0.2, 0.4]},
                     out_dir="out/sweep", duration=3.0)

A variant is the scene with the parameters' values put at their JSON
pointers (docs/scene-format.md's keys, arrays by index), run in lockstep:
the results do not depend on where or in which order variants run, so a
sweep on a cluster gives exactly what the same variants give one after the
other here. Each finished variant is written at once (out_dir/variants/
NNNNN/: variant.json, summary.json, forces.csv, log.txt) and the table
(out_dir/results.csv) is rewritten; a sweep restarted on the same out_dir
reruns only what is missing. A variant that fails is a row with its error;
the sweep goes on. Command line: /usr/bin/python3 -m dmplatform.sweeps
SWEEP.json [--scheduler tcp://HOST:8786] [--workers N] (docs/sweeps.md).
"""
import csv
import hashlib
import itertools
import json
import os
import pathlib
import random
import sys
import tempfile
import time

# Keys of summary.json that describe the machine or the wall clock, not the
# simulation: left out of the table, which is identical wherever it ran.
_UNSTABLE = {"wall_s", "engines", "host", "outputs", "render", "mode"}


def _scene_dict(scene):
    from . import Scene

    if isinstance(scene, (str, os.PathLike)):
        scene = Scene.load(scene)
    return scene.to_dict(), str(scene.base_dir)


def _pointer(doc, path):
    parts = [p for p in path.split("/") if p != ""]
    if not parts:
        raise ValueError(f"parameter {path!r}: an empty JSON pointer")
    node = doc
    for p in parts[:-1]:
        node = node[int(p)] if isinstance(node, list) else node[p]
    return node, (int(parts[-1]) if isinstance(node, list) else parts[-1])


def _plain(value):
    """A JSON value: NumPy scalars and arrays (np.linspace grids) as Python's."""
    return value.tolist() if hasattr(value, "tolist") else value


def variants(parameters, samples=None, seed=0):
    """The variants of `parameters` ({json pointer: [values]} for a grid, or
    {json pointer: (low, high)} with `samples` for uniform random samples),
    each a dict {pointer: value}, in a fixed order."""
    names = sorted(parameters)
    if samples is None:
        for values in itertools.product(*(parameters[n] for n in names)):
            yield {n: _plain(v) for n, v in zip(names, values)}
        return
    rng = random.Random(seed)
    for _ in range(samples):
        yield {n: rng.uniform(*map(float, parameters[n])) for n in names}


def apply(scene_dict, variant):
    """A copy of `scene_dict` with each value of `variant` at its pointer."""
    doc = json.loads(json.dumps(scene_dict))
    for path, value in variant.items():
        try:
            node, key = _pointer(doc, path)
            if isinstance(node, list) and not 0 <= key < len(node):
                raise IndexError(key)
        except (KeyError, IndexError, ValueError, TypeError) as e:
            raise ValueError(f"parameter {path!r} names no key of the scene ({e})") from None
        node[key] = _plain(value)
    return doc


def _flatten(prefix, value, out):
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else k, v, out)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _flatten(f"{prefix}.{i}", v, out)
    else:
        out[prefix] = value


def row_of(summary, forces_bytes):
    """The table row of a run: its summary's numbers and strings by dotted key
    (machine and wall-clock keys left out) and the SHA-256 of its force
    trace."""
    row = {}
    _flatten("", {k: v for k, v in summary.items() if k not in _UNSTABLE}, row)
    row["forces_sha256"] = hashlib.sha256(forces_bytes).hexdigest()
    return row


def run_variant(scene_dict, base_dir, variant, duration):
    """Runs one variant in a temporary folder and returns (summary, the bytes
    of forces.csv, its log, error): the run's log is what the simulation
    wrote to standard error meanwhile (its state changes, warnings); a
    variant that cannot run (dmplatform.Error, ValueError) comes back with
    summary and forces None and its error, so its log is kept too. On the
    worker that runs it (single-threaded workers: the redirection of file
    descriptor 2 catches the C++ side's output)."""
    from . import Error, Scene, run

    with tempfile.TemporaryFile() as log:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(log.fileno(), 2)
        try:
            doc = apply(scene_dict, variant)
            doc.setdefault("outputs", {})
            doc["outputs"].update({"forces": True, "summary": True, "frames": False, "plot": False,
                                   "recording": False})
            doc.get("engines", {}).pop("render", None)
            scene = Scene.from_dict(doc, base_dir, "sweep variant")
            with tempfile.TemporaryDirectory(prefix="dm_sweep_") as tmp:
                result = run(scene, duration, tmp)
                forces = (pathlib.Path(tmp) / "forces.csv").read_bytes()
            summary, error = result.summary, ""
        except (Error, ValueError) as e:
            summary, forces, error = None, None, _error_text(e)
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        log.seek(0)
        text = log.read().decode("utf-8", errors="replace")
    return summary, forces, text, error


def _error_text(e):
    """One line: a table cell."""
    lines = [line.strip() for line in str(e).splitlines() if line.strip()]
    return f"{type(e).__name__}: " + "; ".join(lines)


def _write_atomic(path, data):
    tmp = path.with_name(path.name + ".part")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def _done(folder, variant):
    try:
        return json.loads((folder / "variant.json").read_text()) == variant and (folder / "row.json").exists()
    except (OSError, ValueError):
        return False


def _write_table(out_dir, rows):
    columns = []
    for r in rows:
        for k in r:
            if k not in columns:
                columns.append(k)
    path = out_dir / "results.csv"
    tmp = path.with_name("results.csv.part")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        for r in rows:
            w.writerow(r)
    os.replace(tmp, path)


def sweep(scene, parameters, out_dir, duration, client=None, samples=None, seed=0, progress=None):
    """Runs every variant of `scene` (a Scene or a scene file) and returns the
    table: one dict per variant, in variant order, with `variant` (its
    number), the parameters' values, `error` (empty unless it failed) and its
    results (row_of). `client`: a dask.distributed.Client, "serial" (one
    after the other in this process), or None (a LocalCluster of one
    single-threaded worker process per core, closed at the end).
    `progress(done, total)` is called as variants finish."""
    out_dir = pathlib.Path(out_dir)
    (out_dir / "variants").mkdir(parents=True, exist_ok=True)
    scene_dict, base_dir = _scene_dict(scene)
    todo = list(variants(parameters, samples, seed))
    rows = [None] * len(todo)

    def record(i, summary=None, forces=None, error="", log=None):
        folder = out_dir / "variants" / f"{i:05d}"
        folder.mkdir(exist_ok=True)
        if log is not None:
            _write_atomic(folder / "log.txt", log.encode())
        row = {"variant": i, **todo[i], "error": error}
        if summary is not None:
            _write_atomic(folder / "summary.json", (json.dumps(summary, indent=2) + "\n").encode())
            _write_atomic(folder / "forces.csv", forces)
            row.update(row_of(summary, forces))
        _write_atomic(folder / "variant.json", json.dumps(todo[i]).encode())
        _write_atomic(folder / "row.json", json.dumps(row).encode())  # last: the variant is done
        rows[i] = row

    pending = []
    for i, v in enumerate(todo):
        folder = out_dir / "variants" / f"{i:05d}"
        if _done(folder, v):
            rows[i] = json.loads((folder / "row.json").read_text())
        else:
            pending.append(i)
    finished = len(todo) - len(pending)
    if progress:
        progress(finished, len(todo))

    own_cluster = None
    if pending and client is None:
        from distributed import Client, LocalCluster

        own_cluster = LocalCluster(n_workers=os.cpu_count() or 1, threads_per_worker=1, processes=True,
                                   dashboard_address=":0")
        client = Client(own_cluster)
    try:
        if client == "serial":
            for i in pending:
                try:
                    summary, forces, log, error = run_variant(scene_dict, base_dir, todo[i], duration)
                    record(i, summary, forces, error, log)
                except Exception as e:  # noqa: BLE001 — a failed variant is a row, the sweep goes on
                    record(i, error=_error_text(e))
                finished += 1
                if progress:
                    progress(finished, len(todo))
        elif pending:
            from distributed import as_completed

            futures = {client.submit(run_variant, scene_dict, base_dir, todo[i], duration, pure=False,
                                     retries=1, key=f"dm-sweep-{i:05d}-{time.time_ns()}"): i
                       for i in pending}
            for fut in as_completed(futures):
                i = futures[fut]
                try:
                    summary, forces, log, error = fut.result()
                    record(i, summary, forces, error, log)
                except Exception as e:  # noqa: BLE001
                    record(i, error=_error_text(e))
                finished += 1
                if progress:
                    progress(finished, len(todo))
    finally:
        if own_cluster is not None:
            client.close()
            own_cluster.close()
    _write_table(out_dir, rows)
    return rows


def _main(argv):
    import argparse

    p = argparse.ArgumentParser(prog="python3 -m dmplatform.sweeps", description="Runs a sweep file (docs/sweeps.md).")
    p.add_argument("sweep", help="SWEEP.json: {scene, duration, parameters, out, [samples, seed]}")
    p.add_argument("--scheduler", help="a Dask scheduler's address (tcp://HOST:8786); default: a LocalCluster")
    p.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: one per core)")
    p.add_argument("--serial", action="store_true", help="run the variants one after the other in this process")
    a = p.parse_args(argv)
    path = pathlib.Path(a.sweep)
    try:
        spec = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        p.error(f"{path}: {e}")
    if not isinstance(spec, dict):
        p.error(f"{path}: expected a JSON object")
    known = {"scene", "duration", "parameters", "out", "samples", "seed"}
    unknown = sorted(set(spec) - known)
    if unknown:
        p.error(f"{path}: unknown key(s) {unknown}; known: {sorted(known)}")
    for key in ("scene", "duration", "parameters", "out"):
        if key not in spec:
            p.error(f"{path}: missing key {key!r}")
    scene = (path.parent / spec["scene"]).resolve()
    out = (path.parent / spec["out"]).resolve()
    client = "serial" if a.serial else None
    cluster = None
    if a.scheduler:
        from distributed import Client

        client = Client(a.scheduler)
    elif a.workers and not a.serial:
        from distributed import Client, LocalCluster

        cluster = LocalCluster(n_workers=a.workers, threads_per_worker=1, processes=True, dashboard_address=":0")
        client = Client(cluster)

    def progress(done, total):
        print(f"\rsweep: {done}/{total} variants", end="", file=sys.stderr, flush=True)

    try:
        rows = sweep(scene, spec["parameters"], out, spec["duration"], client=client, samples=spec.get("samples"),
                     seed=spec.get("seed", 0), progress=progress)
    finally:
        if cluster is not None:
            client.close()
            cluster.close()
    print(file=sys.stderr)
    failed = [r for r in rows if r.get("error")]
    print(f"{len(rows)} variants, {len(failed)} failed; table in {out / 'results.csv'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
