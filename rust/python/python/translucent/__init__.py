"""Translucent: real-time subsurface-scattering preview with stated error and speed.

Jensen's dipole BSSRDF on triangle meshes; PRT material editing after Xu et al. 2007.
Lengths are in scene units, coefficients in 1/scene unit, light units follow Blender/Cycles
(sun Strength = W/m^2, point/spot/area Power = W, world colour = radiance).
"""

from ._native import (
    Cancelled,
    Material,
    Prt,
    Scene,
    __version__,
    reference_radiosity,
    relative_error,
)

__all__ = [
    "Cancelled",
    "Material",
    "Prt",
    "Scene",
    "__version__",
    "reference_radiosity",
    "relative_error",
]
