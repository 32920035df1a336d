# The ODE backend of a scene's physics world from Python (docs/scene-format.md,
# "Physics backends"): a box launched along a table on ODE stops after the
# Coulomb distance and the summary says which backend ran; ODE settings with
# the built-in solver, and sleeping bodies on ODE, are refused with their
# JSON paths.
import pytest

import dmplatform as dm

G = 9.80665


def sliding_box(physics):
    return {
        "format": "dmplatform-scene", "version": 2, "name": "slide",
        "resources": {"table": {"type": "shape", "shape": "plane", "half_extents": [1, 1]},
                      "box": {"type": "shape", "shape": "box", "half_extents": [0.02, 0.03, 0.01]}},
        "objects": [{"name": "table", "mesh": "table", "contact": {"friction": 0.3}},
                    {"name": "box", "mesh": "box", "dynamic": True, "mass": 0.1, "velocity": [0.5, 0, 0],
                     "contact": {"friction": 0.3}, "pose": {"position": [0, 0, 0.01]}}],
        "engines": {"physics": physics},
        "outputs": {"summary": True},
    }


def test_a_box_on_ode_slides_the_coulomb_distance(tmp_path):
    scene = dm.Scene.from_dict(sliding_box({"backend": "ode", "ode": {"iterations": 30}}), tmp_path)
    summary = dm.run(scene, 0.5, tmp_path / "out").summary
    assert summary["physics"]["backend"] == "ode"
    box = next(b for b in summary["physics"]["bodies"] if b["name"] == "box")
    assert box["position_m"][0] == pytest.approx(0.5**2 / (2 * 0.3 * G), rel=0.02)
    assert box["contact_force_N"][2] == pytest.approx(0.1 * G, rel=0.01)


@pytest.mark.parametrize("physics, path, words", [
    ({"ode": {"iterations": 30}}, "/engines/physics/ode", "built-in solver"),
    ({"backend": "ode", "sleep": True}, "/engines/physics/sleep", "no sleeping"),
    ({"backend": "bullet"}, "/engines/physics/backend", "bullet"),
])
def test_ode_settings_out_of_place_are_refused_with_their_paths(tmp_path, physics, path, words):
    with pytest.raises(dm.Error) as e:
        dm.Scene.from_dict(sliding_box(physics), tmp_path, "slide.json")
    assert e.value.where == "slide.json: " + path
    assert words in str(e.value)
