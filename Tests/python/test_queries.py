# Collision queries and haptic rendering from Python, against geometry and
# dmtool: a sphere (the isosurface of its distance field) answers closest
# points, signed distances, rays, the distance between two spheres and their
# contacts as the sphere's geometry says; a thin open plate answers unsigned
# distances and is hit from both sides; the god-object pressed into the
# sphere pushes back k times the depth along the normal; and dmplatform.probe
# writes the bytes `dmtool probe` writes for the same mesh and path.
import pathlib
import subprocess

import numpy as np
import pytest

import dmplatform as dm

H = 0.0005   # m, voxel of the sphere's distance field
R = 0.015    # m
TOL = 0.25 * H  # marching cubes of a smooth field: within a fraction of a voxel


@pytest.fixture(scope="module")
def sphere(sphere_field):
    return dm.isosurface(sphere_field(R, H, 8), 0.0)  # the field is > 0 inside


def plate():
    # A 4 cm square in z = 0, two triangles, open (felt from both sides).
    return dm.Mesh(np.array([[-0.02, -0.02, 0], [0.02, -0.02, 0], [0.02, 0.02, 0], [-0.02, 0.02, 0]]),
                   np.array([[0, 1, 2], [0, 2, 3]]))


def translation(x, y, z):
    t = np.eye(4)
    t[:3, 3] = [x, y, z]
    return t


def test_closest_points_are_the_spheres_signed_distance(sphere):
    tree = dm.MeshTree(sphere)
    assert tree.is_closed
    rng = np.random.default_rng(7)
    d = rng.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    radii = rng.uniform(0.2 * R, 3 * R, size=200)
    q = tree.closest_points(d * radii[:, None])
    assert np.allclose(q["distance"], radii - R, atol=TOL)             # negative inside
    assert np.allclose(np.linalg.norm(q["point"], axis=1), R, atol=TOL)  # on the sphere
    assert np.all(np.einsum("ij,ij->i", q["normal"], d) > 0.99)          # outward, radial
    assert np.all(q["triangle"] >= 0)
    far = tree.closest_points(np.array([[0, 0, 1.0]]), max_distance=0.1)
    assert far["distance"][0] == np.inf and far["triangle"][0] == -1


def test_rays_hit_the_sphere_where_its_geometry_says(sphere):
    tree = dm.MeshTree(sphere)
    pose = translation(0.1, 0, 0)
    offsets = np.linspace(-0.9 * R, 0.9 * R, 9)
    origins = np.stack([np.full(9, 0.1), offsets, np.full(9, 0.05)], 1)
    hit = tree.raycast(origins, np.array([[0, 0, -1.0]]), pose=pose)
    assert np.allclose(hit["t"], 0.05 - np.sqrt(R * R - offsets ** 2), atol=4 * TOL)
    miss = tree.raycast(np.array([[0.1, 2 * R, 0.05]]), np.array([[0, 0, -1.0]]), pose=pose)
    assert miss["t"][0] == np.inf and miss["triangle"][0] == -1 and np.isnan(miss["point"][0, 0])
    short = tree.raycast(origins[:1], np.array([[0, 0, -1.0]]), pose=pose, t_max=0.01)
    assert short["t"][0] == np.inf


def test_two_spheres_are_their_centre_distance_less_two_radii_apart(sphere):
    tree = dm.MeshTree(sphere)
    for gap in (0.01, 0.002):
        d = tree.distance(tree, other_pose=translation(2 * R + gap, 0, 0))
        assert d["distance"] == pytest.approx(gap, abs=2 * TOL)
        assert d["point"][0] == pytest.approx(R, abs=TOL)
        assert d["other_point"][0] == pytest.approx(R + gap, abs=TOL)
        assert not tree.intersects(tree, other_pose=translation(2 * R + gap, 0, 0))
    overlap = translation(2 * R - 0.004, 0, 0)
    assert tree.intersects(tree, other_pose=overlap)
    assert tree.distance(tree, other_pose=overlap)["distance"] == 0.0
    c = tree.contacts(tree, other_pose=overlap)
    assert len(c["depth"]) > 0
    # The intersection is the circle x = R - 2 mm, of radius sqrt(R² - (R - 2 mm)²).
    assert np.allclose(c["position"][:, 0], R - 0.002, atol=0.5 * H)
    ring = np.hypot(c["position"][:, 1], c["position"][:, 2])
    assert np.allclose(ring, np.sqrt(R ** 2 - (R - 0.002) ** 2), atol=0.5 * H)


def test_a_thin_open_plate_is_unsigned_and_hit_from_both_sides():
    tree = dm.MeshTree(plate())
    assert not tree.is_closed
    q = tree.closest_points(np.array([[0.005, 0.0, 0.003], [0.005, 0.0, -0.003], [0.03, 0.0, 0.0]]))
    assert q["distance"] == pytest.approx([0.003, 0.003, 0.01])
    up = tree.raycast(np.array([[0, 0, -0.01]]), np.array([[0, 0, 1.0]]))
    down = tree.raycast(np.array([[0, 0, 0.01]]), np.array([[0, 0, -1.0]]))
    assert up["t"][0] == pytest.approx(0.01) and down["t"][0] == pytest.approx(0.01)


def test_the_god_object_pushes_back_k_times_the_depth_along_the_normal(sphere):
    k = 800.0
    go = dm.god_object([sphere], stiffness=k)
    assert go.name == "godobject" and go.object_count == 1
    top = dm.MeshTree(sphere).raycast(np.array([[0, 0, 0.05]]), np.array([[0, 0, -1.0]]))["point"][0]
    go.reset([0, 0, 0.03])
    for z in np.linspace(0.03, top[2] - 0.002, 200):
        r = go.tick([0, 0, z])
    assert r.contacts == 1
    assert r.force == pytest.approx([0, 0, k * 0.002], abs=1e-3 * k * 0.002)
    assert r.penetration == pytest.approx(0.002, rel=1e-3)
    assert r.proxy[2, 3] == pytest.approx(top[2], abs=1e-5)  # the proxy stays on the surface
    assert go.contact["normal"][2] > 0.999
    free = go.tick([0, 0, 0.03])
    assert free.contacts == 0 and np.all(free.force == 0) and go.contact is None
    with pytest.raises(dm.Error) as e:
        dm.god_object([sphere], stiffness=-1.0)
    assert "stiffness" in str(e.value)


def test_probe_writes_what_dmtool_probe_writes(sphere, dmplatform_exe, tmp_path):
    dmtool = pathlib.Path(dmplatform_exe).with_name("dmtool")
    dm.write_mesh(sphere, tmp_path / "sphere.ply")
    mesh = dm.read_mesh(tmp_path / "sphere.ply")  # what dmtool reads
    t = np.linspace(0.0, 1.0, 11)
    path = np.stack([t, 0.002 * np.sin(6 * t), np.zeros(11), 0.02 - 0.008 * t], 1)
    np.savetxt(tmp_path / "path.csv", path, delimiter=",", header="t,x,y,z", comments="", fmt="%.17g")
    subprocess.run([str(dmtool), "probe", str(tmp_path / "sphere.ply"), "--path", str(tmp_path / "path.csv"),
                    "--renderer", "godobject", "--stiffness", "800", "--friction", "0.3,0.2",
                    "-o", str(tmp_path / "dmtool.csv")], check=True, capture_output=True)
    go = dm.god_object([mesh], stiffness=800, static_friction=0.3, dynamic_friction=0.2)
    samples = dm.probe(go, tmp_path / "path.csv", 1000.0, out=tmp_path / "py.csv")
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "dmtool.csv").read_bytes()
    reference = dm.read_forces(tmp_path / "dmtool.csv")
    assert samples.dtype.names == reference.dtype.names
    for name in samples.dtype.names:
        assert np.array_equal(samples[name], reference[name]), name
    assert samples["contacts"].max() == 1 and samples["fz"].max() > 1.0  # it pressed in
    # The path as an array replays the same.
    again = dm.probe(dm.god_object([mesh], stiffness=800, static_friction=0.3, dynamic_friction=0.2), path)
    assert np.array_equal(again, samples)
    with pytest.raises(dm.Error) as e:
        dm.probe(go, path[::-1])  # time must increase
    assert "path" in e.value.where
