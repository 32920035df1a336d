# Rigid-body physics from Python against mechanics: free fall follows the
# integrator's discrete solution exactly, a box sliding on the ground with
# friction mu stops after v0^2 / (2 mu g), a resting sphere's contact holds
# its weight, a bounce keeps the restitution's share of the speed, a
# head-on collision in zero gravity keeps the momentum; misuse is refused.
import numpy as np
import pytest

import dmplatform as dm

G = 9.81


def test_free_fall_is_the_symplectic_euler_solution():
    w = dm.PhysicsWorld()
    w.add_sphere("ball", 0.01, mass=0.2, position=(0, 0, 1.0))
    h, n = 1e-3, 500
    w.step(h, steps=n)
    s = w.state("ball")
    assert s["velocity"][2] == pytest.approx(-G * h * n, rel=1e-12)
    assert s["position"][2] == pytest.approx(1.0 - G * h * h * n * (n + 1) / 2, rel=1e-12)
    assert w.time == pytest.approx(h * n)


def test_a_sliding_box_stops_where_coulomb_friction_says():
    w = dm.PhysicsWorld()
    w.add_plane("ground", friction=0.4)
    w.add_box("box", (0.05, 0.05, 0.02), mass=1.0, position=(0, 0, 0.02), velocity=(1.0, 0, 0), friction=0.4)
    # The pair's coefficient: the two materials' (both 0.4).
    w.step(1e-3, steps=1000)
    s = w.state("box")
    assert np.linalg.norm(s["velocity"]) < 1e-3  # stopped after v0 / (mu g) = 0.255 s
    assert s["position"][0] == pytest.approx(1.0 / (2 * 0.4 * G), rel=0.02)
    assert s["position"][2] == pytest.approx(0.02, abs=1e-3)


def test_a_resting_sphere_is_held_by_its_weight():
    w = dm.PhysicsWorld()
    w.add_plane("ground")
    w.add_sphere("ball", 0.02, mass=0.5, position=(0, 0, 0.021))
    w.step(1e-3, steps=1000)
    s = w.state("ball")
    assert s["position"][2] == pytest.approx(0.02, abs=5e-4)
    assert np.linalg.norm(s["velocity"]) < 1e-3
    held = np.zeros(3)
    for c in w.contacts():
        if c["b"] == "ball":
            held += c["force_on_b"]
        elif c["a"] == "ball":
            held -= c["force_on_b"]
    assert held == pytest.approx([0, 0, 0.5 * G], rel=1e-3, abs=1e-6)


def test_a_bounce_keeps_the_restitutions_share_of_the_speed():
    w = dm.PhysicsWorld()
    w.add_plane("ground", restitution=0.5)
    w.add_sphere("ball", 0.01, mass=0.1, position=(0, 0, 0.01 + 0.2), restitution=0.5)
    fastest_down, fastest_up, vz = 0.0, 0.0, []
    for _ in range(400):
        w.step(1e-3)
        v = w.state("ball")["velocity"][2]
        vz.append(v)
    vz = np.array(vz)
    first_up = np.argmax(vz > 0)
    fastest_down = -vz[first_up - 1]
    fastest_up = vz[first_up]
    assert fastest_down == pytest.approx(np.sqrt(2 * G * 0.2), rel=0.02)
    assert fastest_up / fastest_down == pytest.approx(0.5, abs=0.03)


def test_a_head_on_collision_keeps_the_momentum():
    w = dm.PhysicsWorld(gravity=(0, 0, 0))
    w.add_sphere("a", 0.01, mass=1.0, position=(-0.05, 0, 0), velocity=(1.0, 0, 0), restitution=1.0)
    w.add_sphere("b", 0.01, mass=3.0, position=(0.05, 0, 0), restitution=1.0)
    p0 = w.linear_momentum.copy()
    e0 = w.kinetic_energy
    w.step(1e-3, steps=200)
    assert w.linear_momentum == pytest.approx(p0, abs=1e-12)
    va, vb = w.state("a")["velocity"][0], w.state("b")["velocity"][0]
    # Elastic: va = (m1 - m2)/(m1 + m2) v = -0.5, vb = 2 m1/(m1 + m2) v = 0.5.
    assert va == pytest.approx(-0.5, abs=0.02) and vb == pytest.approx(0.5, abs=0.02)
    assert w.kinetic_energy == pytest.approx(e0, rel=0.05)


def test_misuse_is_refused_naming_it():
    w = dm.PhysicsWorld()
    w.add_sphere("ball", 0.01)
    with pytest.raises(dm.Error) as e:
        w.add_sphere("ball", 0.02)
    assert "exists" in str(e.value)
    with pytest.raises(dm.Error):
        w.add_sphere("neg", -0.01)
    w.step(1e-3)
    with pytest.raises(dm.Error) as e:
        w.add_box("late", (0.01, 0.01, 0.01))
    assert "before the first step" in str(e.value)
    with pytest.raises(dm.Error) as e:
        w.state("nobody")
    assert "nobody" in str(e.value)
