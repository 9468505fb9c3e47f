"""lutgen: connecting null geodesics in the Schwarzschild spacetime and their lookup tables.

Pure numpy/scipy (no bpy). Units: lengths in r_s, c = 1 (times in r_s/c), angles in radians.
"""
from .solver import Connection, check_observer_radius, connect, connect_grid, shadow_half_angle

__all__ = ["Connection", "connect", "connect_grid", "shadow_half_angle", "check_observer_radius"]
__version__ = "0.1.0"
