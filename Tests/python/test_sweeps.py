# Sweeps: 64 lockstep variants of the box push (the box's mass × the
# friction) on a 2-worker Dask LocalCluster give exactly the table (and
# force traces) of the same variants run one after the other here; with a
# worker killed mid-sweep every result still arrives; a sweep restarted on
# its folder reruns only what is missing; a variant that cannot run is a
# row with its error while the others go on.
import json
import os
import signal
import threading

import pytest

import dmplatform as dm
from dmplatform import sweeps

distributed = pytest.importorskip("distributed")

GRID = {"/objects/1/mass": [0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45],
        "/objects/1/contact/friction": [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]}
DURATION = 0.6  # s: the hand meets the box after about 0.4 s


@pytest.fixture(scope="module")
def scene(source_dir):
    return dm.Scene.load(source_dir / "examples/scenes/box_push.json")


@pytest.fixture(scope="module")
def serial(scene, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    return sweeps.sweep(scene, GRID, out, DURATION, client="serial"), out


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as c, distributed.Client(c) as client:
        yield c, client


def test_the_grid_has_every_combination_in_order():
    v = list(sweeps.variants(GRID))
    assert len(v) == 64
    assert v[0] == {"/objects/1/contact/friction": 0.1, "/objects/1/mass": 0.1}
    assert v[9] == {"/objects/1/contact/friction": 0.2, "/objects/1/mass": 0.15}
    samples = list(sweeps.variants({"/objects/1/mass": (0.1, 0.5)}, samples=5, seed=3))
    assert samples == list(sweeps.variants({"/objects/1/mass": (0.1, 0.5)}, samples=5, seed=3))
    assert all(0.1 <= s["/objects/1/mass"] <= 0.5 for s in samples)


def test_a_distributed_sweep_equals_the_serial_one(serial, scene, cluster, tmp_path):
    rows, out = serial
    assert len(rows) == 64 and not any(r["error"] for r in rows)
    # The variants differ: heavier, stickier boxes move less.
    moved = {(r["/objects/1/mass"], r["/objects/1/contact/friction"]): r["physics.bodies.0.displacement_m"]
             for r in rows}
    assert moved[(0.1, 0.1)] > moved[(0.45, 0.8)]
    _, client = cluster
    distributed_rows = sweeps.sweep(scene, GRID, tmp_path, DURATION, client=client)
    assert distributed_rows == rows
    for i in (0, 31, 63):
        a = (out / "variants" / f"{i:05d}" / "forces.csv").read_bytes()
        b = (tmp_path / "variants" / f"{i:05d}" / "forces.csv").read_bytes()
        assert a == b
    assert (tmp_path / "results.csv").read_text() == (out / "results.csv").read_text()
    # Each variant's log, captured where it ran (a worker's standard error).
    log = (tmp_path / "variants" / "00005" / "log.txt").read_text()
    assert "simulation: running -> stopping (done)" in log


def test_a_worker_killed_mid_sweep_loses_nothing(serial, scene, tmp_path):
    rows, _ = serial
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as c, distributed.Client(c) as client:
        pids = list(client.run(os.getpid).values())
        killed = threading.Event()

        def progress(done, total):
            if done >= 8 and not killed.is_set():
                killed.set()
                os.kill(pids[0], signal.SIGKILL)

        got = sweeps.sweep(scene, GRID, tmp_path, DURATION, client=client, progress=progress)
    assert killed.is_set()
    assert got == rows


def test_a_restarted_sweep_runs_only_what_is_missing(serial, scene, tmp_path):
    rows, out = serial
    part = {"/objects/1/mass": GRID["/objects/1/mass"][:2], "/objects/1/contact/friction": GRID["/objects/1/contact/friction"]}
    first = sweeps.sweep(scene, part, tmp_path, DURATION, client="serial")
    for i in (3, 7, 12):
        (tmp_path / "variants" / f"{i:05d}" / "row.json").unlink()  # as if killed before it finished
    ran = []
    again = sweeps.sweep(scene, part, tmp_path, DURATION, client="serial",
                         progress=lambda done, total: ran.append(done))
    assert ran[0] == 13 and ran[-1] == 16  # 13 kept, 3 rerun
    assert again == first


def test_a_variant_that_cannot_run_is_a_row_with_its_error(scene, tmp_path):
    rows = sweeps.sweep(scene, {"/objects/1/mass": [0.2, -1.0]}, tmp_path, 0.1, client="serial")
    assert rows[0]["error"] == "" and rows[0]["haptics.ticks"] == 100
    assert "/objects/1/mass" in rows[1]["error"]
    assert "simulation: running -> stopping (done)" in (tmp_path / "variants/00000/log.txt").read_text()
    assert (tmp_path / "variants/00001/log.txt").exists()  # the failed one keeps its (short) log too
    with pytest.raises(ValueError):
        sweeps.apply(scene.to_dict(), {"/objects/9/mass": 1.0})
    # NumPy grids work as lists do.
    import numpy as np
    assert list(sweeps.variants({"/objects/1/mass": np.array([0.1, 0.15, 0.2])})) == list(
        sweeps.variants({"/objects/1/mass": [0.1, 0.15, 0.2]}))


def test_the_command_line_runs_a_sweep_file(source_dir, tmp_path):
    spec = {"scene": str(source_dir / "examples/scenes/box_push.json"), "duration": 0.2,
            "parameters": {"/objects/1/mass": [0.1, 0.2]}, "out": str(tmp_path / "out")}
    (tmp_path / "sweep.json").write_text(json.dumps(spec))
    assert sweeps._main([str(tmp_path / "sweep.json"), "--serial"]) == 0
    assert (tmp_path / "out" / "results.csv").read_text().count("\n") == 3


def test_dmplatform_sweep_runs_the_package(source_dir, dmplatform_exe, tmp_path):
    import subprocess

    spec = {"scene": str(source_dir / "examples/scenes/box_push.json"), "duration": 0.2,
            "parameters": {"/objects/1/mass": [0.1, 0.2, -1.0]}, "out": str(tmp_path / "out")}
    (tmp_path / "sweep.json").write_text(json.dumps(spec))
    p = subprocess.run([dmplatform_exe, "sweep", str(tmp_path / "sweep.json"), "--serial"], capture_output=True,
                       text=True)
    assert p.returncode == 1, p.stderr  # one variant cannot run
    assert "3 variants, 1 failed" in p.stdout
    rows = (tmp_path / "out" / "results.csv").read_text().splitlines()
    assert len(rows) == 4
