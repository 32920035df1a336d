# The data model in Python: a volume's voxels are a NumPy view of the C++
# object's memory (both ways), a real MRI reads with its affine, and the
# isosurface of a sampled ball has the ball's area and encloses its volume
# within the marching-cubes discretisation error; a mesh round-trips a file.
import math
import os

import numpy as np
import pytest

import dmplatform as dm


def ball(n=48, spacing=0.001, radius=0.015):
    c = (n - 1) / 2.0
    k, j, i = np.mgrid[0:n, 0:n, 0:n]
    d = np.sqrt((i - c) ** 2 + (j - c) ** 2 + (k - c) ** 2) * spacing
    affine = np.diag([spacing, spacing, spacing, 1.0])
    return dm.Volume((radius - d).astype(np.float32), affine)


def test_volume_array_shares_memory_with_the_cpp_volume():
    v = dm.Volume(np.zeros((4, 5, 6), np.int16))
    assert v.dims == (6, 5, 4)
    a = v.array
    assert a.shape == (4, 5, 6) and a.dtype == np.int16
    a[1, 2, 3] = 7  # [z, y, x]
    assert v.value(3, 2, 1) == 7.0
    b = v.array
    assert np.shares_memory(a, b)
    del v  # the arrays keep the volume alive
    assert b[1, 2, 3] == 7


def test_volume_affine_places_voxels_in_the_world():
    affine = np.array([[0.5e-3, 0, 0, 0.01], [0, 0.5e-3, 0, -0.02], [0, 0, 2e-3, 0.03], [0, 0, 0, 1]])
    v = dm.Volume(np.zeros((3, 3, 3), np.uint8), affine)
    assert np.allclose(v.affine, affine)
    assert v.spacing == pytest.approx((0.5e-3, 0.5e-3, 2e-3))
    w = v.index_to_world(np.array([[2.0, 1.0, 1.0]]))
    assert np.allclose(w, [[0.011, -0.0195, 0.032]])


def test_a_bad_array_or_file_raises_an_error_naming_it():
    with pytest.raises(dm.Error) as e:
        dm.Volume(np.zeros((4, 4), np.uint8))
    assert e.value.where == "array"
    with pytest.raises(dm.Error) as e:
        dm.Volume(np.zeros((2, 2, 2), np.complex64))
    assert e.value.code == "unsupported"
    with pytest.raises(dm.Error) as e:
        dm.read_volume("/nonexistent/ct.nii.gz")
    assert e.value.code == "not found" and "/nonexistent/ct.nii.gz" in e.value.where
    with pytest.raises(dm.Error):
        dm.Mesh(np.zeros((3, 3)), np.array([[0, 1, 3]]))


def test_the_colin27_mri_reads_with_its_affine():
    path = "/usr/share/mricron/templates/ch2.nii.gz"
    if not os.path.exists(path):
        pytest.skip("mricron-data is not installed")
    v = dm.read_volume(path)
    assert v.dims == (181, 217, 181)
    assert v.spacing == pytest.approx((0.001, 0.001, 0.001))
    assert v.array.shape == (181, 217, 181)
    assert v.array.max() > 0


def test_isosurface_of_a_ball_has_its_area_and_volume(tmp_path):
    r = 0.015
    mesh = dm.isosurface(ball(radius=r), 0.0)
    p, t = mesh.positions, mesh.triangles.astype(np.int64)
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0  # closed, CCW from outside
    assert area == pytest.approx(4 * math.pi * r * r, rel=0.02)
    assert volume == pytest.approx(4 / 3 * math.pi * r**3, rel=0.02)
    # Every vertex lies on the sphere to within a fraction of a voxel.
    assert np.abs(np.linalg.norm(p - 0.0235, axis=1) - r).max() < 0.3e-3
    out = tmp_path / "ball.stl"
    dm.write_mesh(mesh, out)
    back = dm.read_mesh(out)
    assert back.triangles.shape == mesh.triangles.shape
    assert np.allclose(np.sort(back.positions, axis=0), np.sort(mesh.positions, axis=0), atol=1e-6)
