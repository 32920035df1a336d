"""The tether of box_tether.json: a spring from the box to where it started.

Runs at the physics rate (the scene's "engine": "physics"): each tick it
reads the box's position and holds the spring's force on it until the next
tick; events say when the tool touched the box and let go. The metrics land
in summary.json under scripts/tether/metrics.
"""

k = 0.0
home = None
touching = False


def start(sim):
    global k, home
    k = float(sim.args["stiffness_N_m"])
    home = sim.body("box")["center_of_mass"]
    sim.metric("contacts", 0)
    sim.metric("max_hand_force_N", 0.0)


def event(sim, ev):
    global touching
    if ev["type"] == "contact_began" and ev["object"] == "box":
        touching = True
        sim.metric("contacts", sim.metrics["contacts"] + 1)
        if "first_contact_s" not in sim.metrics:
            sim.metric("first_contact_s", ev["time"])
    elif ev["type"] == "contact_ended":
        touching = False
        sim.metric("last_release_s", ev["time"])


def tick(sim):
    c = sim.body("box")["center_of_mass"]
    pull = [-k * (c[i] - home[i]) for i in range(3)]
    pull[2] = 0.0  # along the table only
    sim.set_force("box", pull)
    if touching:
        f = sim.tool["force"]
        norm = (f[0] ** 2 + f[1] ** 2 + f[2] ** 2) ** 0.5
        if norm > sim.metrics["max_hand_force_N"]:
            sim.metric("max_hand_force_N", norm)
    sim.metric("tether_force_N", pull)


def finish(sim):
    c = sim.body("box")["center_of_mass"]
    return {"box_travel_m": ((c[0] - home[0]) ** 2 + (c[1] - home[1]) ** 2) ** 0.5}
