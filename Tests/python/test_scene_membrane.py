# A scene's membrane from Python (docs/scene-format.md, "Membranes"): a drum
# written as a dict sags until its rim carries its weight, a sheet dropped on
# a static sphere rests on it with the sphere carrying its weight, and a
# membrane the tool would touch is refused with its JSON path.
import pytest

import dmplatform as dm

G = 9.80665


def drum():
    return {
        "format": "dmplatform-scene", "version": 2, "name": "drum",
        "resources": {"sheet": {"type": "shape", "shape": "plane", "half_extents": [0.05, 0.05],
                                "subdivisions": 3}},
        "objects": [{"name": "drum", "mesh": "sheet", "pose": {"position": [0, 0, 0.1]},
                     "membrane": {"mass": 0.01, "stiffness": 20, "damping": 0.02, "drag": 5,
                                  "pinned": "boundary"}}],
        "engines": {"physics": {"rate_hz": 500}},
        "outputs": {"summary": True},
    }


def test_a_drum_sags_until_its_rim_carries_its_weight(tmp_path):
    summary = dm.run(dm.Scene.from_dict(drum(), tmp_path), 3.0, tmp_path / "out").summary
    m = summary["physics"]["membranes"][0]
    assert m["name"] == "drum" and m["particles"] == 81 and m["pinned"] == 32
    assert m["pinned_load_N"][2] == pytest.approx(-0.01 * G, rel=0.01)
    assert m["center_of_mass_m"][2] < 0.1


def test_a_sheet_dropped_on_a_static_sphere_rests_on_it(tmp_path):
    d = drum()
    d["resources"]["ball"] = {"type": "shape", "shape": "sphere", "radius": 0.03, "subdivisions": 4}
    d["objects"].append({"name": "organ", "mesh": "ball"})
    d["objects"][0]["pose"]["position"] = [0, 0, 0.04]
    d["objects"][0]["membrane"].update({"pinned": None, "friction": 1.0, "thickness": 0.0005, "drag": 4})
    del d["objects"][0]["membrane"]["pinned"]
    m = dm.run(dm.Scene.from_dict(d, tmp_path), 2.0, tmp_path / "out").summary["physics"]["membranes"][0]
    assert m["obstacles"][0]["name"] == "organ"
    assert m["obstacles"][0]["force_N"][2] == pytest.approx(-0.01 * G, rel=0.01)
    assert m["center_of_mass_m"][2] < 0.03


def test_a_membrane_the_tool_would_touch_is_refused_with_its_path(tmp_path):
    d = drum()
    d["resources"]["ball"] = {"type": "shape", "shape": "sphere", "radius": 0.002}
    d["objects"].append({"name": "tip", "mesh": "ball", "pose": {"position": [0, 0, 0.2]}})
    d["devices"] = [{"name": "hand", "driver": "sim-haptic"}]
    d["engines"]["haptics"] = {"device": "hand", "objects": ["drum"], "proxy_object": "tip"}
    d["materials"] = {"skin": {"haptic": {"stiffness": 300}}}
    d["objects"][0].update({"haptic": True, "material": "skin"})
    with pytest.raises(dm.Error) as e:
        dm.Scene.from_dict(d, tmp_path, "drum.json")
    assert e.value.where == "drum.json: /engines/haptics/objects"
    assert "cannot be touched" in str(e.value)
