"""The black hole object of Add > Black Hole: its horizon and photon sphere shown at true size.

The hole is an empty (never rendered) drawn as a sphere of radius r_s, the event horizon, with a child
empty drawn as a sphere of radius 1.5 r_s, the photon sphere, where light can orbit the hole. Both
follow ``scene.grlens.r_s`` (set or animated) and the hole's scale: :func:`sync` sets their display
sizes, from the r_s update, the frame handler and edits of the hole. Which objects are grlens' own
is recorded in custom properties (``grlens_hole`` on the hole, ``grlens_photon_sphere`` on its
child), so the file keeps it. Units: Blender units (r_s in scene length units).
"""
from __future__ import annotations

import math

import bpy

PHOTON_SPHERE = 1.5
"""Radius of the photon sphere in units of r_s (circular light orbits of a Schwarzschild hole)."""

HOLE_KEY = "grlens_hole"
PHOTON_KEY = "grlens_photon_sphere"


def is_hole_marker(obj) -> bool:
    """Whether ``obj`` is a hole made by Add > Black Hole (or its photon-sphere child)."""
    return obj is not None and (obj.get(HOLE_KEY) is not None or obj.get(PHOTON_KEY) is not None)


def _world_scale(obj) -> float:
    """Mean length of the axes of ``obj``'s world matrix (1 for an unscaled object; 0 if degenerate)."""
    m = obj.matrix_world
    return sum(math.sqrt(sum(m[r][c] ** 2 for r in range(3))) for c in range(3)) / 3.0


def photon_sphere_of(hole):
    """The photon-sphere child that Add > Black Hole made for ``hole``, or None."""
    for child in hole.children:
        if child.get(PHOTON_KEY) is not None:
            return child
    return None


def _set_size(obj, size: float) -> None:
    if math.isfinite(size) and size > 0 and abs(obj.empty_display_size - size) > 1e-6 * size:
        obj.empty_display_size = size  # (written only when it changes: no needless depsgraph updates)


def sync(scene) -> None:
    """Give the hole of ``scene`` made by Add > Black Hole the display sizes of its horizon (r_s) and
    photon sphere (1.5 r_s) for the scene's current r_s, in world units whatever the hole's scale.
    Other objects used as the hole, a non-positive r_s or a degenerate scale: nothing is changed."""
    g = getattr(scene, "grlens", None)
    hole = g.black_hole if g is not None else None
    if hole is None or hole.get(HOLE_KEY) is None or hole.type != "EMPTY":
        return
    r_s = g.r_s
    if not (math.isfinite(r_s) and r_s > 0):
        return
    s = _world_scale(hole)
    if not s > 0:
        return
    _set_size(hole, r_s / s)
    ps = photon_sphere_of(hole)
    if ps is not None and ps.type == "EMPTY":
        # (the child inherits the hole's scale; its own is normally 1)
        _set_size(ps, PHOTON_SPHERE * r_s / max(_world_scale(ps), 1e-30))


def add(scene, collection, location=(0.0, 0.0, 0.0), name: str = "Black Hole"):
    """Create a hole marker at ``location`` in ``collection`` and make it the black hole of
    ``scene``: an empty drawn as its horizon, with a child empty drawn as its photon sphere
    (neither renders, the child cannot be selected by clicking). Returns (hole, the former black
    hole object or None)."""
    hole = bpy.data.objects.new(name, None)
    hole.empty_display_type = "SPHERE"
    hole.location = location
    hole.hide_render = True
    hole[HOLE_KEY] = 1
    collection.objects.link(hole)
    ps = bpy.data.objects.new(f"{hole.name} Photon Sphere", None)
    ps.empty_display_type = "SPHERE"
    ps.parent = hole
    ps.hide_render = True
    ps.hide_select = True
    ps[PHOTON_KEY] = 1
    collection.objects.link(ps)
    g = scene.grlens
    former = g.black_hole
    g.black_hole = hole
    sync(scene)
    return hole, (former if former is not hole else None)


def replaced_note(former) -> str:
    """The note of Add > Black Hole when the scene had a black hole already."""
    return (f"the new black hole replaces '{former.name}' as the scene's black hole ('{former.name}' is kept; "
            "delete it if it is no longer needed)")
