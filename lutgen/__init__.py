"""lutgen: connecting null geodesics in the Schwarzschild spacetime and their lookup tables.

Pure numpy/scipy (no bpy). Units: lengths in r_s (Schwarzschild radius), c = 1 (times in r_s/c),
angles in radians. Observer static at (r_obs, phi = 0); xi measured from the outward radial
direction in the observer's static frame; order 1 sweeps phi, order 2 sweeps 2*pi - phi.

Public API (stable): connect, connect_grid, refine_xi, Connection, shadow_half_angle, build_lut, LUT,
load_lut, save_lut, LUTFileError, and the tables that reach infinity for any observer radius:
WideLUT, build_wide_lut, LUTFamily; one table of orbits for every observer radius, inside the photon
sphere too: RayMap, OrbitTable, orbit_table (lutgen.rays); command line ``python -m lutgen``.
"""
from .escape import EscapeTable, escape_angle, escape_limit, escape_table
from .exr_io import LUTFileError
from .lut import LUT, Lookup, build_lut
from .lutfile import load_lut, save_lut
from .rays import OrbitTable, RayMap, orbit_table
from .solver import Connection, check_observer_radius, connect, connect_grid, refine_xi, shadow_half_angle
from .wide_lut import LUTFamily, WideLUT, build_wide_lut

__all__ = ["Connection", "connect", "connect_grid", "refine_xi", "shadow_half_angle", "check_observer_radius",
           "LUT", "Lookup", "build_lut", "load_lut", "save_lut", "LUTFileError",
           "WideLUT", "build_wide_lut", "LUTFamily", "RayMap", "OrbitTable", "orbit_table"]
__version__ = "0.1.0"
