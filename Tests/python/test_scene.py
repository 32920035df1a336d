# Scenes from Python: a bundled scene loads, round-trips through a dict,
# refuses a wrong key with its JSON path, and runs in lockstep to the same
# force trace, byte for byte, as `dmplatform run` gives for the same scene.
import json
import subprocess

import numpy as np
import pytest

import dmplatform as dm


def box_push(source_dir):
    scene = dm.Scene.load(source_dir / "examples/scenes/box_push.json")
    d = scene.to_dict()
    del d["engines"]["render"]  # the mechanics, not the pictures
    d["outputs"].update({"frames": False, "plot": False, "recording": False})
    return d, scene.base_dir


def test_a_scene_round_trips_through_a_dict(source_dir):
    scene = dm.Scene.load(source_dir / "examples/scenes/osteotomy.json")
    assert scene.name == "osteotomy"
    again = dm.Scene.from_dict(scene.to_dict(), scene.base_dir)
    assert again == scene
    assert again.to_dict()["engines"]["haptics"]["renderer"] == "bone-placement"


def test_a_wrong_key_is_refused_with_its_json_path(source_dir):
    d, base = box_push(source_dir)
    d["objects"][1]["masss"] = 0.2
    with pytest.raises(dm.Error) as e:
        dm.Scene.from_dict(d, base, "pushed.json")
    assert e.value.where == "pushed.json: /objects/1/masss"
    assert "mass" in str(e.value)  # the suggestion


def test_a_run_from_python_gives_the_trace_dmplatform_run_gives(source_dir, dmplatform_exe, tmp_path):
    d, base = box_push(source_dir)
    scene = dm.Scene.from_dict(d, base, "box_push.json")
    result = dm.run(scene, 2.0, tmp_path / "py")
    assert not result.interrupted
    assert result.simulated_seconds == pytest.approx(2.0)
    assert result.summary["haptics"]["ticks"] == 2000
    body = [b for b in result.summary["physics"]["bodies"] if b["name"] == "box"][0]
    assert body["displacement_m"] > 0.005  # the tool met and pushed the box
    forces = dm.read_forces(result.out_dir / "forces.csv")
    assert forces.shape == (2000,)
    assert forces["t"][0] == 0.0 and forces["fx"].min() < -0.1  # the box pushes the hand back
    # The same scene through the command line.
    (tmp_path / "scene.json").write_text(json.dumps(d))
    subprocess.run([dmplatform_exe, "run", str(tmp_path / "scene.json"), "--lockstep", "--duration", "2",
                    "--out", str(tmp_path / "cli")], check=True, capture_output=True)
    assert (tmp_path / "cli/forces.csv").read_bytes() == (tmp_path / "py/forces.csv").read_bytes()
    assert json.loads((tmp_path / "py/summary.json").read_text())["haptics"] == result.summary["haptics"]


def test_run_refuses_an_unknown_mode(source_dir, tmp_path):
    d, base = box_push(source_dir)
    with pytest.raises(dm.Error) as e:
        dm.run(dm.Scene.from_dict(d, base), 0.1, tmp_path, mode="fast")
    assert e.value.where == "mode"


def test_a_run_stepped_from_python_writes_what_one_run_writes(source_dir, tmp_path):
    d, base = box_push(source_dir)
    scene = dm.Scene.from_dict(d, base, "box_push.json")
    sim = dm.Simulation(scene, tmp_path / "stepped", duration_hint=2.0)
    seen = []
    while sim.time < 2.0 - 1e-9:
        sim.advance(0.25)
        state = sim.state()
        box = [b for b in state["physics"]["bodies"] if b["name"] == "box"][0]
        seen.append((state["time_s"], box["position_m"][0], state["haptics"]["force_N"][0]))
    result = sim.finish()
    assert [t for t, _, _ in seen] == pytest.approx([0.25 * k for k in range(1, 9)])
    assert seen[-1][1] > seen[0][1] + 0.005  # the box moved between the steps the hand pushed it
    assert seen[-1][2] < -0.1                # the box pushes the hand back
    assert result.summary["duration_s"] == pytest.approx(2.0)
    whole = dm.run(scene, 2.0, tmp_path / "whole")
    assert (tmp_path / "stepped/forces.csv").read_bytes() == (tmp_path / "whole/forces.csv").read_bytes()
    assert result.summary["physics"] == whole.summary["physics"]
    with pytest.raises(dm.Error):
        sim.advance(0.1)
    with pytest.raises(dm.Error):
        sim.finish()
