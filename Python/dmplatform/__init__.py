"""DMPlatform for Python: the surgical simulation SDK's data model as NumPy
arrays, its readers and writers, isosurfaces, collision queries, rigid-body
physics, the god-object renderer and device-path replays (dmtool probe), and
scene files run in lockstep or real time with Python scripts inside them
(docs/python.md).

    import dmplatform as dm
    ct = dm.read_volume("/usr/share/mricron/templates/ch2.nii.gz")
    skin = dm.isosurface(ct, 40)
    scene = dm.Scene.load("examples/scenes/head_probe.json")
    result = dm.run(scene, 1.0, "out")
    forces = dm.read_forces(result.out_dir / "forces.csv")
"""
import numpy as _np

from ._core import (Error, Fluid, FluidInlet, FluidRegion, FluidSuction, HapticRenderer, HapticResponse, Image, Mesh, MeshTree, PhysicsWorld,
                    RunResult, Scene, Simulation, Volume, burr, god_object, hausdorff, isosurface, probe, read_mesh,
                    read_png, read_volume, run, sample_boundary, simplify, sphere_tree, voxelize, vps, write_mesh,
                    write_png, write_volume)

from .fit import fit
from .sweeps import sweep

__all__ = ["Error", "Fluid", "FluidInlet", "FluidRegion", "FluidSuction", "HapticRenderer", "HapticResponse", "Image", "Mesh", "MeshTree", "PhysicsWorld",
           "RunResult", "Scene", "Simulation", "Volume", "burr", "fit", "god_object", "hausdorff", "isosurface", "probe",
           "read_forces", "read_mesh", "read_png", "read_volume", "run", "sample_boundary", "simplify", "sphere_tree",
           "sweep", "voxelize", "vps", "write_mesh", "write_png", "write_volume"]


def read_forces(path):
    """A run's forces.csv as a NumPy structured array, one row per haptic
    tick: t (s), fx, fy, fz (N, on the hand, world), tx, ty, tz (N·m), px,
    py, pz (m) and qw, qx, qy, qz (the proxy's pose), contacts,
    penetration (m)."""
    return _np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="ascii")
