# Geometry and images from Python against geometry: a sphere (isosurface of
# its distance field) voxelized keeps its volume within the voxels' error
# and its signed distance is r - |x| where exact; simplified to a fifth it
# stays within the report's Hausdorff bound, which hausdorff() confirms; an
# image's array shares its pixels and round-trips through PNG bit for bit.
import numpy as np
import pytest

import dmplatform as dm

R = 0.02


@pytest.fixture(scope="module")
def sphere():
    h = 0.0005
    n = int(2.4 * R / h)
    z, y, x = np.mgrid[0:n, 0:n, 0:n]
    c = (n - 1) / 2 * h
    affine = np.diag([h, h, h, 1.0])
    affine[:3, 3] = -c
    p = np.stack([x, y, z], -1) * h - c
    return dm.isosurface(dm.Volume((R - np.linalg.norm(p, axis=-1)).astype(np.float32), affine), 0.0)


def test_voxelizing_a_sphere_keeps_its_volume_and_distance(sphere):
    h = 0.001
    occ = dm.voxelize(sphere, h)
    assert occ.array.dtype == np.uint8
    volume = occ.array.sum() * h ** 3
    assert volume == pytest.approx(4 / 3 * np.pi * R ** 3, rel=0.03)
    sdf = dm.voxelize(sphere, h, signed_distance=True)
    centres = np.stack(np.meshgrid(*[np.arange(s) for s in sdf.array.shape[::-1]], indexing="ij"), -1)
    world = centres.reshape(-1, 3) @ sdf.affine[:3, :3].T + sdf.affine[:3, 3]
    d = sdf.array.transpose(2, 1, 0).reshape(-1)
    assert np.allclose(d, np.linalg.norm(world, axis=1) - R, atol=0.0005)


def test_simplifying_stays_within_its_reported_distance(sphere):
    small, report = dm.simplify(sphere, ratio=0.2)
    assert report["triangles_after"] <= 0.21 * report["triangles_before"]
    assert len(small.triangles) == report["triangles_after"]
    measured = dm.hausdorff(small, sphere)
    assert measured == pytest.approx(report["max_distance"], rel=0.25)
    assert measured < 0.002  # a 20 mm sphere with a fifth of its triangles
    bounded, r2 = dm.simplify(sphere, ratio=0.01, max_error=1e-4)
    assert r2["max_distance"] <= 1e-4 * 1.0001 and r2["triangles_after"] > 0.01 * r2["triangles_before"]


def test_an_image_shares_its_pixels_and_round_trips_through_png(tmp_path):
    pixels = (np.arange(24 * 32 * 3) % 251).astype(np.uint8).reshape(24, 32, 3)
    im = dm.Image(pixels)
    assert (im.width, im.height, im.channels) == (32, 24, 3)
    view = im.array
    view[0, 0, 0] = 7
    assert im.array[0, 0, 0] == 7  # the same memory
    pixels[0, 0, 0] = 7
    dm.write_png(im, tmp_path / "x.png")
    assert np.array_equal(dm.read_png(tmp_path / "x.png").array, pixels)
    deep = dm.Image((np.arange(100) * 600).astype(np.uint16).reshape(10, 10))
    dm.write_png(deep, tmp_path / "d.png")
    assert np.array_equal(dm.read_png(tmp_path / "d.png").array[:, :, 0], deep.array[:, :, 0])
    with pytest.raises(dm.Error):
        dm.Image(np.zeros((4, 4), dtype=np.int64))
