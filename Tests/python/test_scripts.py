# Scripted scenes: the bundled box_tether.json's Python tether (a spring to
# the box's start, set every physics step) runs the same in the caller's
# interpreter (dmplatform.run) and in the one the dmplatform program embeds,
# bit for bit; at rest the hand's force balances the tether's and the
# table's friction (Newton); the script's first contact is the first tick
# of forces.csv with a force on the hand; args change what it does; a
# Python error stops the run naming the script's file and line; a script
# opens a fluid inlet, which then delivers its rate.
import json
import shutil
import subprocess

import numpy as np
import pytest

import dmplatform as dm


def tether(source_dir, tmp_path, stiffness=20.0):
    scene = dm.Scene.load(source_dir / "examples/scenes/box_tether.json")
    d = scene.to_dict()
    del d["engines"]["render"]  # the mechanics, not the pictures
    d["outputs"].update({"frames": False, "plot": False})
    d["scripts"][0]["args"]["stiffness_N_m"] = stiffness
    shutil.copy(source_dir / "examples/scenes/box_tether.py", tmp_path / "box_tether.py")
    (tmp_path / "scene.json").write_text(json.dumps(d))
    return d


def box(summary):
    return [b for b in summary["physics"]["bodies"] if b["name"] == "box"][0]


def test_a_python_script_runs_the_same_from_python_and_from_dmplatform(source_dir, dmplatform_exe, tmp_path):
    d = tether(source_dir, tmp_path)
    result = dm.run(dm.Scene.from_dict(d, tmp_path, "box_tether.json"), 6.0, tmp_path / "py")
    s = result.summary
    m = s["scripts"]["tether"]["metrics"]
    assert s["scripts"]["tether"]["ticks"] == 6000  # the physics rate
    # Newton at rest: the hand pushes the box (minus the force on the hand)
    # against the tether and the table's friction.
    hand_on_box = -np.array(s["haptics"]["final_force_N"])
    tether_force = np.array(m["tether_force_N"])
    table = np.array(box(s)["contact_force_N"])
    assert np.linalg.norm(box(s)["velocity_m_s"]) < 1e-4
    assert abs(hand_on_box[0] + tether_force[0] + table[0]) < 1e-3 * abs(hand_on_box[0])
    assert tether_force[0] == pytest.approx(-20.0 * m["box_travel_m"], rel=1e-3)
    # The first contact is the first tick with a force on the hand.
    forces = dm.read_forces(result.out_dir / "forces.csv")
    f = np.sqrt(forces["fx"] ** 2 + forces["fy"] ** 2 + forces["fz"] ** 2)
    assert m["first_contact_s"] == pytest.approx(forces["t"][np.argmax(f > 0)], abs=1.5e-3)
    assert m["max_hand_force_N"] == pytest.approx(s["haptics"]["max_force_N"], rel=1e-9)
    # The same scene through the program's embedded interpreter.
    subprocess.run([dmplatform_exe, "run", str(tmp_path / "scene.json"), "--duration", "6",
                    "--out", str(tmp_path / "cli")], check=True, capture_output=True)
    cli = json.loads((tmp_path / "cli/summary.json").read_text())
    assert cli["scripts"] == s["scripts"]
    assert cli["physics"]["bodies"] == s["physics"]["bodies"]
    assert (tmp_path / "cli/forces.csv").read_bytes() == (tmp_path / "py/forces.csv").read_bytes()


def test_a_stiffer_tether_holds_the_box_closer(source_dir, tmp_path):
    travel = []
    for k in (10.0, 40.0):
        d = tether(source_dir, tmp_path, k)
        s = dm.run(dm.Scene.from_dict(d, tmp_path), 6.0, tmp_path / f"k{k}").summary
        travel.append(s["scripts"]["tether"]["metrics"]["box_travel_m"])
    assert travel[1] < travel[0]


def test_a_python_error_names_the_script_and_its_line(source_dir, dmplatform_exe, tmp_path):
    d = tether(source_dir, tmp_path)
    (tmp_path / "bad.py").write_text("def tick(sim):\n    if sim.time >= 0.5:\n        1 / 0\n")
    d["scripts"][0]["source"] = "bad.py"
    with pytest.raises(dm.Error) as e:
        dm.run(dm.Scene.from_dict(d, tmp_path), 1.0, tmp_path / "py")
    assert "ZeroDivisionError" in str(e.value)
    assert "script:tether" in str(e.value) and "bad.py:3" in str(e.value)
    assert json.loads((tmp_path / "py/summary.json").read_text())["scripts"]["tether"]["ticks"] == 500
    (tmp_path / "scene.json").write_text(json.dumps(d))
    r = subprocess.run([dmplatform_exe, "run", str(tmp_path / "scene.json"), "--duration", "1",
                        "--out", str(tmp_path / "cli")], capture_output=True, text=True)
    assert r.returncode == 1
    assert "ZeroDivisionError" in r.stderr and "bad.py:3" in r.stderr


def test_a_script_with_no_callbacks_or_bad_syntax_is_refused_before_the_run(source_dir, tmp_path):
    d = tether(source_dir, tmp_path)
    (tmp_path / "empty.py").write_text("x = 1\n")
    (tmp_path / "syntax.py").write_text("def tick(sim)\n    pass\n")
    for name, words in (("empty.py", "none of start, event, tick, finish"), ("syntax.py", "SyntaxError")):
        d["scripts"][0]["source"] = name
        with pytest.raises(dm.Error) as e:
            dm.run(dm.Scene.from_dict(d, tmp_path), 1.0, tmp_path / "out")
        assert words in str(e.value)
        assert name in e.value.where
        assert not (tmp_path / "out").exists()  # nothing ran


def test_script_context_errors_are_python_exceptions(source_dir, tmp_path):
    d = tether(source_dir, tmp_path)
    (tmp_path / "probe.py").write_text(
        "def start(sim):\n"
        "    try:\n"
        "        sim.body('table')\n"
        "    except KeyError as e:\n"
        "        sim.metric('no_body', str(e))\n"
        "    try:\n"
        "        sim.set_force('box', [1, 2])\n"
        "    except ValueError as e:\n"
        "        sim.metric('short', str(e))\n"
        "    try:\n"
        "        sim.metric('obj', object())\n"
        "    except ValueError as e:\n"
        "        sim.metric('not_json', 'JSON' in str(e))\n"
        "    sim.metric('bodies', sim.bodies)\n"
        "    sim.metric('args', sim.args)\n")
    d["scripts"][0]["source"] = "probe.py"
    m = dm.run(dm.Scene.from_dict(d, tmp_path), 0.01, tmp_path / "out").summary["scripts"]["tether"]["metrics"]
    assert "table" in m["no_body"]
    assert "3 numbers" in m["short"]
    assert m["not_json"] is True
    assert m["bodies"] == ["box"]
    assert m["args"] == {"stiffness_N_m": 20.0}


def test_a_python_script_opens_a_fluid_inlet(tmp_path):
    (tmp_path / "open.py").write_text(
        "def tick(sim):\n"
        "    if sim.time >= 0.5 and 'opened_s' not in sim.metrics:\n"
        "        sim.set_inlet_flow_rate('saline', 'nozzle', 2e-5)\n"
        "        sim.metric('opened_s', sim.time)\n")
    d = {"format": "dmplatform-scene", "version": 2, "name": "nozzle",
         "engines": {"physics": {"rate_hz": 500}},
         "fluids": [{"name": "saline", "spacing": 0.01, "density": 1000,
                     "region": {"min": [-0.1, -0.1, -0.1], "max": [0.3, 0.1, 0.3]},
                     "inlets": [{"name": "nozzle", "center": [0, 0, 0.2], "normal": [1, 0, 0], "flow_rate": 0}]}],
         "scripts": [{"name": "open", "source": "open.py", "engine": "physics"}],
         "outputs": {"directory": "out"}}
    s = dm.run(dm.Scene.from_dict(d, tmp_path, "nozzle.json"), 1.5, tmp_path / "out").summary
    fluid = s["physics"]["fluids"][0]
    assert s["scripts"]["open"]["metrics"]["opened_s"] == pytest.approx(0.5)
    assert fluid["inlets"][0]["volume_m3"] == pytest.approx(2e-5, abs=fluid["particle_volume_m3"])
    d["scripts"][0]["source"] = "wrong.py"
    (tmp_path / "wrong.py").write_text("def tick(sim):\n    sim.set_inlet_flow_rate('saline', 'nozle', 1e-6)\n")
    with pytest.raises(dm.Error, match='no inlet "nozle"'):
        dm.run(dm.Scene.from_dict(d, tmp_path, "nozzle.json"), 0.1, tmp_path / "wrong")
