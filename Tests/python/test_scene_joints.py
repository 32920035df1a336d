# Joints of a scene's physics world from Python (docs/scene-format.md, the
# physics engine's "joints"): a pendulum written as a dict swings as the
# physical pendulum it is, the summary dict reports its joint, and a joint
# on an object that is not a rigid body of the world is refused with its
# JSON path.
import math

import pytest

import dmplatform as dm

G = 9.80665


def pendulum(theta0, length=0.5, radius=0.01):
    return {
        "format": "dmplatform-scene", "version": 2, "name": "pendulum",
        "resources": {"ball": {"type": "shape", "shape": "sphere", "radius": radius}},
        "objects": [{"name": "bob", "mesh": "ball", "dynamic": True, "mass": 0.01,
                     "pose": {"position": [length * math.sin(theta0), 0, 1 - length * math.cos(theta0)]}}],
        "engines": {"physics": {"rate_hz": 1000, "joints": [
            {"name": "pivot", "type": "hinge", "a": "bob", "anchor": [0, 0, 1], "axis": [0, 1, 0]}]}},
        "outputs": {"summary": True},
    }


def test_a_hinged_ball_swings_as_its_physical_pendulum(tmp_path):
    theta0, length, radius = 0.1, 0.5, 0.01
    omega = math.sqrt(G * length / (length**2 + 0.4 * radius**2))
    t = round(0.75 * math.pi / omega * 1000) / 1000  # 3/8 of a period, in whole 1 ms steps
    summary = dm.run(dm.Scene.from_dict(pendulum(theta0), tmp_path), t, tmp_path / "out").summary
    bob = next(b for b in summary["physics"]["bodies"] if b["name"] == "bob")
    x, _, z = bob["position_m"]
    theta = math.atan2(x, 1 - z)
    expected = theta0 * math.cos(omega * t)
    assert theta == pytest.approx(expected, rel=0.01)
    pivot = next(j for j in summary["physics"]["joints"] if j["name"] == "pivot")
    assert pivot["anchor_gap_m"] < 1e-4


def test_a_joint_on_an_object_outside_the_world_is_refused_with_its_path(tmp_path):
    d = pendulum(0.1)
    d["objects"].append({"name": "ghost", "mesh": "ball", "collide": False, "pose": {"position": [1, 0, 1]}})
    d["engines"]["physics"]["joints"][0]["b"] = "ghost"
    with pytest.raises(dm.Error) as e:
        dm.Scene.from_dict(d, tmp_path, "pendulum.json")
    assert e.value.where == "pendulum.json: /engines/physics/joints/0/b"
    assert "does not collide" in str(e.value)
