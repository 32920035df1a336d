# dmtool probe's 6-DOF renderers from Python (dmplatform.vps, sphere_tree,
# burr), against geometry and dmtool: a ball tool pressed straight down onto
# a sphere of known radius is pushed back up its normal, with no torque (the
# push is through the centre), harder the deeper it goes and never harder than
# its stiffness times the depth (a coupling in series with a stiffer contact);
# a burr drilling down into the sphere removes bone, at most the volume its
# ball swept inside the sphere; each replays a path to the bytes `dmtool
# probe` writes for the same model and path; misuse raises dm.Error naming
# the argument.
import json
import pathlib
import subprocess

import numpy as np
import pytest

import dmplatform as dm

H = 0.0005  # m, voxel of the sphere's distance field
R = 0.012   # m, the sphere
RT = 0.002  # m, the ball tool and burr


@pytest.fixture(scope="module")
def ball_solid(sphere_field):
    """The sphere as a solid: values above 0 inside (a threshold's, an isosurface's inside)."""
    return sphere_field(R, H, 12)


@pytest.fixture(scope="module")
def ball_sdf(ball_solid):
    """The same sphere's signed distance, negative inside."""
    return dm.Volume(-ball_solid.array, ball_solid.affine)


def press(renderer, depth, steps=400):
    """The ball's centre lowered onto the sphere's top to `depth` past touching, then held."""
    top = R + RT
    renderer.reset([0, 0, top + 0.003])
    for z in np.linspace(top + 0.003, top - depth, steps):
        r = renderer.tick([0, 0, z])
    for _ in range(200):
        r = renderer.tick([0, 0, top - depth])
    return r


# Each renderer with the band its push-back F/k may lie in around the depth
# d, from its geometry: vps feels its coupling in series with a stiffer
# contact (0.2 d < F/k <= d); the sphere tree's proxy rests on the model's
# surface, for a mesh the marching-cubes polygon within its sagitta H²/8R
# (2.6 µm) of the sphere (|F/k - d| <= 5 µm), and for a volume the same:
# its tree's patches are fitted to the field's isosurface (before they
# were, the ball felt the voxels' spheres, up to half a voxel's diagonal
# past the surface, and at the default 6 levels a third of the push
# sideways off their staircase). The push is along the normal within 2 %.
@pytest.mark.parametrize("make,low,high,side", [
    (lambda sdf, solid: dm.vps(sdf, stiffness=500.0, tool_radius=RT), lambda d: 0.2 * d, lambda d: d, 0.02),
    (lambda sdf, solid: dm.vps(solid, stiffness=500.0, tool_radius=RT, threshold=0.0),
     lambda d: 0.2 * d, lambda d: d, 0.02),
    (lambda sdf, solid: dm.sphere_tree(dm.isosurface(solid, 0.0), stiffness=500.0, tool_radius=RT),
     lambda d: d - 5e-6, lambda d: d + 5e-6, 0.02),
    (lambda sdf, solid: dm.sphere_tree(solid, stiffness=500.0, tool_radius=RT, threshold=0.0),
     lambda d: d - 5e-6, lambda d: d + 5e-6, 0.02),
], ids=["vps_sdf", "vps_occupancy", "sphere_tree_mesh", "sphere_tree_volume"])
def test_a_ball_pressed_on_a_sphere_is_pushed_back_up_its_normal(ball_sdf, ball_solid, make, low, high, side):
    k = 500.0
    forces = []
    for depth in (0.0005, 0.001, 0.0015):
        r = press(make(ball_sdf, ball_solid), depth)
        f = r.force
        assert r.contacts > 0
        assert low(depth) < f[2] / k <= high(depth)        # pushed back up the normal, as far as the geometry says
        assert np.hypot(f[0], f[1]) < side * f[2]          # along the normal
        assert np.linalg.norm(r.torque) < side * f[2] * RT  # through the centre: no twist
        forces.append(f[2])
    assert forces[0] < forces[1] < forces[2]


def test_the_burr_removes_bone_within_what_its_ball_swept(ball_sdf):
    burr = dm.burr(ball_sdf, stiffness=800.0, tool_radius=RT, rpm=80000)
    assert burr.removed_volume == 0.0
    before = burr.bone_occupancy().array.sum() * H ** 3
    assert before == pytest.approx(4 / 3 * np.pi * R ** 3, rel=0.01)
    press(burr, 0.001, steps=2000)
    removed = burr.removed_volume
    # The ball's centre went from above to 1 mm past touching: what it swept
    # inside the sphere is at most its cylinder over that drop plus a cap.
    assert removed > 0
    assert removed <= np.pi * RT ** 2 * 0.001 + 2 / 3 * np.pi * RT ** 3
    after = burr.bone_occupancy().array.sum() * H ** 3
    assert before - after == pytest.approx(removed, rel=1e-3)
    assert dm.vps(ball_sdf).removed_volume is None and dm.vps(ball_sdf).bone_occupancy() is None


@pytest.mark.parametrize("renderer,args,make", [
    ("vps", ["--tool-radius", "0.002"], lambda v: dm.vps(v, stiffness=800, tool_radius=RT)),
    ("spheretree", ["--tool-radius", "0.002", "--threshold", "0", "--levels", "7"],
     lambda v: dm.sphere_tree(v, stiffness=800, tool_radius=RT, threshold=0.0, levels=7)),
    ("burr", ["--tool-radius", "0.002", "--rpm", "60000"],
     lambda v: dm.burr(v, stiffness=800, tool_radius=RT, rpm=60000)),
])
def test_each_replays_what_dmtool_probe_writes(ball_sdf, ball_solid, dmplatform_exe, tmp_path, renderer, args,
                                               make):
    dmtool = pathlib.Path(dmplatform_exe).with_name("dmtool")
    dm.write_volume(ball_solid if renderer == "spheretree" else ball_sdf, tmp_path / "ball.nii.gz")
    volume = dm.read_volume(tmp_path / "ball.nii.gz")  # what dmtool reads
    t = np.linspace(0.0, 0.5, 11)
    path = np.stack([t, 0.001 * np.sin(6 * t), np.zeros(11), R + RT + 0.002 - 0.004 * t / 0.5], 1)
    np.savetxt(tmp_path / "path.csv", path, delimiter=",", header="t,x,y,z", comments="", fmt="%.17g")
    done = subprocess.run([str(dmtool), "probe", str(tmp_path / "ball.nii.gz"), "--path", str(tmp_path / "path.csv"),
                           "--renderer", renderer, "--stiffness", "800", *args, "-o", str(tmp_path / "dmtool.csv"),
                           "--json"], check=True, capture_output=True, text=True)
    r = make(volume)
    samples = dm.probe(r, tmp_path / "path.csv", 1000.0, out=tmp_path / "py.csv")
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "dmtool.csv").read_bytes()
    assert samples["contacts"].max() > 0 and samples["fz"].max() > 0.1  # it pressed in
    if renderer == "burr":
        assert r.removed_volume == json.loads(done.stdout)["removedVolume"] > 0


def test_misuse_names_the_argument(ball_sdf):
    with pytest.raises(dm.Error) as e:
        dm.vps("ball.nii.gz")
    assert e.value.where == "model"
    with pytest.raises(dm.Error) as e:
        dm.vps(ball_sdf, stiffness=-1.0)
    assert "stiffness" in e.value.where
    with pytest.raises(dm.Error) as e:
        dm.sphere_tree(ball_sdf, levels=1)
    assert e.value.where == "levels"
    with pytest.raises(dm.Error) as e:
        dm.burr(ball_sdf, tool_radius=-0.001)
    assert e.value.where == "tool_radius"
    with pytest.raises(dm.Error) as e:
        dm.burr(ball_sdf, bone_range=[0, 1, 2])
    assert e.value.where == "bone_range"
    with pytest.raises(dm.Error) as e:
        dm.sphere_tree(ball_sdf, tool_level=9)
    assert e.value.where == "tool_level"
