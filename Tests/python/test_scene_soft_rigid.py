# Soft tissue and a dynamic rigid body in one scene from Python
# (docs/scene-format.md, "Soft tissue"): a ball dropped on a pad comes to
# rest carried by it — the tissue's force on the ball is its weight and the
# held bottom carries both weights — and a negative contact friction is
# refused at its JSON path.
import pytest

import dmplatform as dm

G = 9.80665


def ball_on_pad(friction=0.0):
    return {
        "format": "dmplatform-scene", "version": 2, "name": "ball_on_pad",
        "resources": {"pad": {"type": "shape", "shape": "box", "half_extents": [0.03, 0.03, 0.015]},
                      "ball": {"type": "shape", "shape": "sphere", "radius": 0.01, "subdivisions": 3}},
        "objects": [{"name": "pad", "mesh": "pad", "pose": {"position": [0, 0, 0.015]},
                     "soft": {"youngs_modulus": 2e4, "poisson_ratio": 0.3, "density": 1000,
                              "damping": {"alpha": 20, "beta": 0.01}, "voxel_size": 0.005,
                              "fixed": ["-z"], "contact_friction": friction}},
                    {"name": "ball", "mesh": "ball", "dynamic": True, "mass": 0.027,
                     "pose": {"position": [0, 0, 0.0405]}}],
        "engines": {"physics": {"rate_hz": 200}},
        "outputs": {"summary": True},
    }


def test_a_ball_dropped_on_a_pad_rests_carried_by_it(tmp_path):
    summary = dm.run(dm.Scene.from_dict(ball_on_pad(0.2), tmp_path), 1.0, tmp_path / "out").summary
    pad = summary["physics"]["soft"][0]
    (ball,) = [o for o in pad["obstacles"] if o["name"] == "ball"]
    assert ball["dynamic"]
    weight = 0.027 * G
    assert ball["force_N"][2] == pytest.approx(weight, rel=0.005)
    assert pad["held_force_N"][2] == pytest.approx(weight - pad["weight_N"][2], rel=0.01)
    body = summary["physics"]["bodies"][0]
    assert body["name"] == "ball" and body["position_m"][2] < 0.04  # sunk into the pad


def test_a_negative_contact_friction_is_refused_at_its_path(tmp_path):
    with pytest.raises(dm.Error) as e:
        dm.Scene.from_dict(ball_on_pad(-1.0), tmp_path, "pad.json")
    assert e.value.where == "pad.json: /objects/0/soft/contact_friction"
