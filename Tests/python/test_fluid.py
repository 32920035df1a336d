# The particle fluid from Python: a small column in its container settles
# with a pressure (averaged over 1 s) that grows as rho0 g with depth (5 %,
# on a coarse 2 cm lattice) and its density error under the solver's bound; suction by a mask
# removes exactly the masked particles and their mass; a pump delivers its
# rate and inlets, suction and the region keep the mass account; a vessel
# slows by the linear law; misuse is refused.
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


def test_a_pump_delivers_its_rate_and_suction_and_the_region_keep_the_account():
    f = dm.Fluid(spacing=0.01, gravity=(0, 0, -9.81))
    # 10 ml/s out of a point nozzle, sideways, 15 cm over the region's floor
    nozzle = dm.FluidInlet(f, center=(0, 0, 0.1), normal=(1, 0, 0), flow_rate=1e-5)
    tip = dm.FluidSuction(center=(0.05, 0, 0.08), radius=0.02, max_flow_rate=2e-6)
    region = dm.FluidRegion((-0.05, -0.05, -0.05), (0.3, 0.05, 0.2))
    for _ in range(500):  # 1 s
        nozzle.emit(f, 0.002)
        tip.apply(f, 0.002)
        region.apply(f)
        f.step(0.002)
        assert len(f) + tip.removed_particles + region.removed_particles == nozzle.emitted_particles
    vp = f.particle_mass / 1000.0
    assert nozzle.emitted_volume == pytest.approx(1e-5, abs=vp)
    assert nozzle.points_per_layer == 1 and nozzle.outlet_area == pytest.approx(1e-4)
    assert tip.removed_volume <= 2e-6 + vp
    assert region.removed_particles > 0


def test_a_vessel_slows_with_the_pressure_on_it():
    f = dm.Fluid(spacing=0.01)
    cut = dm.FluidInlet(f, center=(0, 0, 0), radius=0.015, flow_rate=1e-5, pressure=2000)
    assert cut.points_per_layer == 9
    cut.set_applied_pressure(500)
    assert cut.back_pressure(f) == pytest.approx(500)
    assert cut.flow_rate_at(500) == pytest.approx(0.75e-5)
    assert cut.flow_rate_at(2500) == 0
    with pytest.raises(dm.Error, match="normal"):
        dm.FluidInlet(f, center=(0, 0, 0), normal=(0, 0, 0), flow_rate=1e-6)
    with pytest.raises(dm.Error, match="radius"):
        dm.FluidSuction(center=(0, 0, 0), radius=0, max_flow_rate=1e-6)


def _cube(a):
    """A cube of half-side a, triangles counter-clockwise from outside."""
    p = np.array([[x, y, z] for z in (-a, a) for y in (-a, a) for x in (-a, a)], float)  # x + 2y + 4z
    t = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                  [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]], np.uint32)
    return dm.Mesh(p, t)


def test_a_cube_held_under_water_feels_archimedes_buoyancy_and_its_corners_stay_inset():
    # A 6 cm cube at 7.5 mm spacing (4 spacings per half side) held 7 cm
    # deep in a 15 cm tank: once the waves of the start died out (0.6 s) the
    # fluid holds it up with rho0 g V (0.993 measured; 0.993 at 5 mm too) and
    # pushes it nowhere sideways. The boundary samples lie a third of a
    # spacing inside every face, corners and edges included. (At 1 cm, 3
    # spacings per half side, the force swings between 0.945 and 1.03 of
    # rho0 g V as the inset moves the faces' samples by 0.06 spacings against
    # the fluid's lattice planes: a resolution effect, not the inset's.)
    a, d = 0.03, 0.0075
    pts = dm.sample_boundary(_cube(a), d, d / 3)
    assert np.abs(pts).max() == pytest.approx(a - d / 3, abs=1e-12)
    f = dm.Fluid(spacing=d, viscosity=1e-3)
    f.add_box_boundary((0, 0, 0), (0.12, 0.12, 0.3))
    f.add_block((0, 0, 0), (0.12, 0.12, 0.15))
    c = np.array([0.06, 0.06, 0.07])
    f.remove(np.all(np.abs(f.positions - c) < a, axis=1))
    pose = np.eye(4)
    pose[:3, 3] = c
    assert f.add_rigid_body(pts, pose) == 0
    force = np.zeros(3)
    for _ in range(500):
        f.step(0.002)
        if f.time > 0.6:
            force += f.rigid_load(0)[0] / 200
    buoyancy = 1000 * 9.81 * (2 * a) ** 3
    assert force[2] == pytest.approx(buoyancy, rel=0.05)
    assert np.linalg.norm(force[:2]) < 0.02 * buoyancy
    assert np.allclose(f.rigid_pose(0), pose)
    assert len(f.moving_boundary_positions) == len(pts)
    with pytest.raises(dm.Error, match="body 1 of 1"):
        f.rigid_load(1)
    with pytest.raises(dm.Error, match="inset"):
        dm.sample_boundary(_cube(a), d, d)


def _floor(side, cells):
    """A square floor [0, side]² at z = 0 facing up."""
    n = cells + 1
    p = np.array([[side * i / cells, side * j / cells, 0.0] for j in range(n) for i in range(n)], float)
    t = []
    for j in range(cells):
        for i in range(cells):
            a = j * n + i
            t += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
    return dm.Mesh(p, np.array(t, np.uint32))


def test_a_pool_rests_on_a_deforming_surface_with_its_weight():
    # A 12 cm square pool 8 cm deep on a floor that is a surface (tissue)
    # sampled at half a spacing: the loads on its vertices sum to the pool's
    # weight once settled. Its vertices handed back unchanged keep it so;
    # a wrong count is refused naming it.
    d, side = 0.01, 0.12
    floor = _floor(side, 12)
    f = dm.Fluid(spacing=d, viscosity=1e-4)
    f.add_box_boundary((0, 0, -0.03), (side, side, 0.3))
    lift = d - d / 3 - d / 2  # the bottom layer a spacing above the samples
    f.add_block((0, 0, lift), (side, side, 0.08 + lift))
    s = f.add_surface(floor, d / 3, spacing=d / 2)
    assert s == 0
    load = np.zeros(3)
    for k in range(400):
        f.set_surface_state(s, floor.positions)
        f.step(0.002)
        if k >= 300:
            load += f.surface_loads(s).sum(axis=0) / 100
    weight = f.mass * 9.81
    assert load[2] == pytest.approx(-weight, rel=0.03)
    assert np.linalg.norm(load[:2]) < 0.01 * weight
    assert len(f.moving_boundary_positions) > len(floor.positions)
    with pytest.raises(dm.Error, match="3 vertices and 3 velocities for its 169"):
        f.set_surface_state(s, np.zeros((3, 3)))
    with pytest.raises(dm.Error, match="surface 1 of 1"):
        f.surface_loads(1)
