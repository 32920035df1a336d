# The pytest suite of the dmplatform package (Tests/python), run by ctest
# with PYTHONPATH at build/Python and DM_SOURCE_DIR / DM_DMPLATFORM set.
import os
import pathlib

import pytest


@pytest.fixture(scope="session")
def source_dir():
    return pathlib.Path(os.environ.get("DM_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))


@pytest.fixture(scope="session")
def dmplatform_exe():
    exe = os.environ.get("DM_DMPLATFORM")
    if not exe:
        pytest.skip("DM_DMPLATFORM is not set (ctest sets it)")
    return exe


@pytest.fixture(scope="session")
def sphere_field():
    """make(R, H, pad) -> the field R - |p| (> 0 inside a sphere of radius R about the origin) on a grid of
    spacing H with `pad` voxels to spare, as a dm.Volume (float32); its negative is the signed distance."""
    import numpy as np

    import dmplatform as dm

    def make(radius, spacing, pad):
        n = int(2 * radius / spacing) + pad
        z, y, x = np.mgrid[0:n, 0:n, 0:n]
        c = (n - 1) / 2 * spacing
        affine = np.diag([spacing, spacing, spacing, 1.0])
        affine[:3, 3] = -c
        p = np.stack([x, y, z], -1) * spacing - c
        return dm.Volume((radius - np.linalg.norm(p, axis=-1)).astype(np.float32), affine)

    return make
