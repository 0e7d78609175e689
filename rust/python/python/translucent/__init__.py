"""Translucent: real-time subsurface-scattering preview with stated error and speed.

Lengths are in scene units, coefficients in 1/scene unit, light units follow Blender/Cycles.
"""

from ._native import Cancelled, Material, __version__

__all__ = ["Cancelled", "Material", "__version__"]
