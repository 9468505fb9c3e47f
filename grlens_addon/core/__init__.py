"""The add-on's numeric core: plain numpy, no bpy (tested without Blender).

One module per step of the method (seed 000): ``mapping`` (vertices to their lensed images),
``subdivision`` (adaptive, crack-free tessellation by the screen-space curvature rho), ``culling``
(Einstein-ring degeneracy, outside the LUT, inside the horizon, outside the frustum),
``illumination`` (point light along both connecting geodesics).
"""
