# Fitting through sweeps: the tissue press (examples/scenes/tissue_press.json,
# an FEM pad pressed through the god-object) "measured" at a Young's modulus
# of 23 kPa with 10 mN of noise is fitted back from a bracket of 5..80 kPa,
# the candidates of each round run on a 2-worker LocalCluster: the estimate
# lands within 2 % of the modulus that made the measurement, and the RMS of
# the best candidate is near the noise.
import json

import numpy as np
import pytest

import dmplatform as dm

E_TRUE = 23000.0
POINTER = "/objects/1/soft/youngs_modulus"


def press(source_dir):
    scene = dm.Scene.load(source_dir / "examples/scenes/tissue_press.json")
    d = scene.to_dict()
    del d["engines"]["render"]
    d["outputs"].update({"frames": False, "plot": False})
    return d, scene.base_dir


def test_the_fit_recovers_the_modulus_that_made_the_measurement(source_dir, tmp_path):
    d, base = press(source_dir)
    d["objects"][1]["soft"]["youngs_modulus"] = E_TRUE
    measured = dm.read_forces(dm.run(dm.Scene.from_dict(d, base), 2.0, tmp_path / "measured").out_dir / "forces.csv")
    noisy = measured["fz"] + np.random.default_rng(1).normal(0.0, 0.01, len(measured))
    d["objects"][1]["soft"]["youngs_modulus"] = 20000.0  # the scene's own value: the fit must not keep it
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        best = dm.fit(dm.Scene.from_dict(d, base), {POINTER: (5e3, 8e4)}, (measured["t"], noisy), 2.0,
                      tmp_path / "fit", client=client, candidates=5, rounds=3, log=True)
    assert best["value"][POINTER] == pytest.approx(E_TRUE, rel=0.02)
    assert best["rms"] < 0.05  # N; the noise is 0.01 N
    assert len(best["rounds"]) == 3
    lo, hi = best["rounds"][-1]["bracket"][POINTER]
    assert lo < E_TRUE < hi
    # Each round is a sweep folder; a rerun resumes from it and runs nothing.
    assert json.loads((tmp_path / "fit/round_02/fit.json").read_text())["best"]["error"] == ""
    again = dm.fit(dm.Scene.from_dict(d, base), {POINTER: (5e3, 8e4)}, (measured["t"], noisy), 2.0,
                   tmp_path / "fit", client="serial", candidates=5, rounds=3, log=True)
    assert again["value"] == best["value"]


def test_a_bad_bracket_is_refused(source_dir, tmp_path):
    d, base = press(source_dir)
    with pytest.raises(ValueError) as e:
        dm.fit(dm.Scene.from_dict(d, base), {POINTER: (8e4, 5e3)}, ([0.0], [0.0]), 1.0, tmp_path, log=True)
    assert POINTER in str(e.value)
    with pytest.raises(ValueError):
        dm.fit(dm.Scene.from_dict(d, base), {POINTER: (0.0, 5e3)}, ([0.0], [0.0]), 1.0, tmp_path, log=True)
