# The particle fluid from Python: a small column in its container settles
# with a pressure (averaged over 1 s) that grows as rho0 g with depth (5 %,
# on a coarse 2 cm lattice) and its density error under the solver's bound; suction by a mask
# removes exactly the masked particles and their mass; misuse is refused.
import numpy as np
import pytest

import dmplatform as dm


def test_a_column_settles_to_hydrostatic_pressure():
    f = dm.Fluid(spacing=0.02, viscosity=1e-3)
    f.add_box_boundary((0, 0, 0), (0.2, 0.2, 0.6))
    assert f.add_block((0, 0, 0), (0.2, 0.2, 0.3)) == 1500
    for _ in range(200):
        f.step(0.01)
    p = np.zeros(len(f))
    for _ in range(100):  # pressure averaged over 1 s at rest
        f.step(0.01)
        p += f.pressures / 100
        assert f.last_step["density_error"] <= 1e-3
    x = f.positions
    inner = (x[:, 0] > 0.05) & (x[:, 0] < 0.15) & (x[:, 1] > 0.05) & (x[:, 1] < 0.15) & (x[:, 2] > 0.05) & (x[:, 2] < 0.22)
    slope = np.polyfit(x[inner, 2], p[inner], 1)[0]
    assert -slope == pytest.approx(1000 * 9.81, rel=0.05)
    assert f.time == pytest.approx(3.0)


def test_suction_removes_the_masked_particles_and_their_mass():
    f = dm.Fluid(spacing=0.02)
    f.add_box_boundary((0, 0, 0), (0.2, 0.2, 0.6))
    f.add_block((0, 0, 0), (0.2, 0.2, 0.2))
    m0, n0 = f.mass, len(f)
    tip = np.array([0.1, 0.1, 0.2])
    mask = np.linalg.norm(f.positions - tip, axis=1) < 0.05
    assert f.remove(mask) == mask.sum() > 0
    assert len(f) == n0 - mask.sum()
    assert f.mass == pytest.approx(m0 - mask.sum() * f.particle_mass)
    f.add_particles(np.array([[0.1, 0.1, 0.4], [0.12, 0.1, 0.4]]), velocity=(0, 0, -1))
    assert len(f) == n0 - mask.sum() + 2
    f.step(0.01)
    with pytest.raises(dm.Error):
        f.remove(np.ones(3, dtype=bool))
    with pytest.raises(dm.Error):
        dm.Fluid(spacing=-1.0)
    with pytest.raises(dm.Error):
        f.step(0.0)
