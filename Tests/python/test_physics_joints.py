# Joints and the ODE backend of dm.PhysicsWorld from Python, against
# mechanics: a ball on a hinge swings with the physical pendulum's period
# on both backends with its anchors together; a box on a vertical slider
# falls to its lower limit; a resting sphere's contact force is its weight
# on both backends; misuse is refused, naming the argument.
import math

import numpy as np
import pytest

import dmplatform as dm

G = 9.81


@pytest.mark.parametrize("backend", ["builtin", "ode"])
def test_a_hinged_ball_swings_with_the_physical_pendulums_period(backend):
    length, r, m, theta0, h = 0.5, 0.02, 1.0, 0.05, 1e-3
    w = dm.PhysicsWorld(backend=backend, ode_iterations=50 if backend == "ode" else 20)
    w.add_sphere("bob", r, mass=m, position=(length * math.sin(theta0), 0, -length * math.cos(theta0)))
    w.add_joint("pivot", "hinge", "bob", anchor=(0, 0, 0), axis=(0, 1, 0))
    crossings, prev, widest = [], math.sin(theta0), 0.0
    for _ in range(4000):
        w.step(h)
        x = w.state("bob")["position"][0]
        if prev > 0 >= x:
            crossings.append(w.time - h * x / (x - prev))
        prev = x
        widest = max(widest, w.joints()[0]["anchor_gap"])
    # Solid ball: I = m (L² + 2 r² / 5); θ0²/16 longer at this amplitude.
    expected = 2 * math.pi * math.sqrt((length**2 + 0.4 * r**2) / (G * length)) * (1 + theta0**2 / 16)
    period = (crossings[-1] - crossings[0]) / (len(crossings) - 1)
    assert period == pytest.approx(expected, rel=5e-3)
    assert widest < 1e-4
    j = w.joints()[0]
    assert (j["name"], j["type"], j["a"], j["b"]) == ("pivot", "hinge", "bob", None)
    assert w.backend == backend


@pytest.mark.parametrize("backend", ["builtin", "ode"])
def test_a_box_on_a_vertical_slider_falls_to_its_lower_limit(backend):
    w = dm.PhysicsWorld(backend=backend)
    w.add_box("carriage", (0.02, 0.02, 0.02), mass=0.2, position=(0, 0, 1.0))
    w.add_joint("rail", "slider", "carriage", anchor=(0, 0, 1.0), axis=(0, 0, 1), limits=(-0.05, 0.05))
    w.step(1e-3, steps=1000)
    rail = w.joints()[0]
    # The slider's travel is b's anchor (the world's, fixed) from a's: the
    # carriage 5 cm down is +5 cm.
    assert rail["travel"] == pytest.approx(0.05, abs=1e-3)
    assert w.state("carriage")["position"][2] == pytest.approx(0.95, abs=1e-3)
    assert rail["anchor_gap"] < 1e-4


@pytest.mark.parametrize("backend", ["builtin", "ode"])
def test_a_resting_spheres_contact_force_is_its_weight(backend):
    w = dm.PhysicsWorld(backend=backend)
    w.add_plane("ground")
    w.add_sphere("ball", 0.02, mass=0.5, position=(0, 0, 0.021))
    w.step(1e-3, steps=1000)
    forces = w.contact_forces()
    assert list(forces) == ["ball"]  # moving bodies only
    assert forces["ball"] == pytest.approx([0, 0, 0.5 * G], rel=1e-2, abs=1e-6)


def test_misuse_is_refused_naming_the_argument():
    with pytest.raises(dm.Error) as e:
        dm.PhysicsWorld(backend="oed")
    assert e.value.where == "backend" and "ode" in str(e.value)
    with pytest.raises(dm.Error) as e:
        dm.PhysicsWorld(ode_iterations=50)
    assert e.value.where == "ode_iterations"
    w = dm.PhysicsWorld()
    w.add_sphere("bob", 0.01, position=(0, 0, -0.5))
    with pytest.raises(dm.Error) as e:
        w.add_joint("p", "hing", "bob")
    assert e.value.where == "type" and "hinge" in str(e.value)
    with pytest.raises(dm.Error) as e:
        w.add_joint("p", "hinge", "bob")
    assert e.value.where == "axis"
    with pytest.raises(dm.Error) as e:
        w.add_joint("p", "ball", "bob", limits=(-1, 1))
    assert e.value.where == "limits"
    with pytest.raises(dm.Error):
        w.add_joint("p", "ball", "kidney")
    w.add_joint("p", "ball", "bob")
    with pytest.raises(dm.Error) as e:
        w.add_joint("p", "ball", "bob")
    assert e.value.where == "name"
    w.step(1e-3)
    with pytest.raises(dm.Error) as e:
        w.add_joint("q", "ball", "bob")
    assert "stepped" in str(e.value)
    o = dm.PhysicsWorld(backend="ode")
    o.add_sphere("ball", 0.01)
    o.step(1e-3)
    with pytest.raises(dm.Error) as e:
        o.contacts()
    assert "contact_forces" in str(e.value)
    assert isinstance(o.contact_forces()["ball"], np.ndarray)
