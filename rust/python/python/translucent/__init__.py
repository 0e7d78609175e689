"""Translucent: real-time subsurface-scattering preview with stated error and speed.

Any radial profile on triangle meshes: Cycles' random walk (the default: what a Cycles render
of the Principled BSDF shows) or Jensen's dipole (the papers' model); PRT material editing after
Xu et al. 2007; hierarchical boundary elements after Mertens et al. 2003 for deforming
meshes and moving lights; image-space splatting after Shah et al. 2009 (started: on the CPU,
nothing precomputed). Lengths are in scene units, coefficients in 1/scene unit, light units follow
Blender/Cycles (sun Strength = W/m^2, point/spot/area Power = W, world colour = radiance).

The random-walk tables are kept in $TRANSLUCENT_CACHE, else $XDG_CACHE_HOME/translucent, else
~/.cache/translucent (`set_table_cache(None)` keeps them in memory only).
"""

import os
import pathlib

from ._native import (
    CYCLES_CLAMPS,
    LIMITS,
    Cancelled,
    Hierarchy,
    Material,
    Prt,
    Scene,
    Splat,
    __version__,
    layer_weight,
    prepare_profile,
    principled_for_medium,
    profile_ready,
    reference_radiance,
    reference_radiosity,
    reference_single_scattering,
    relative_error,
    set_table_cache,
    table_cache,
)


def _default_cache() -> pathlib.Path:
    if os.environ.get("TRANSLUCENT_CACHE"):
        return pathlib.Path(os.environ["TRANSLUCENT_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache"
    return pathlib.Path(base) / "translucent"


set_table_cache(str(_default_cache() / "tables"))

__all__ = [
    "LIMITS",
    "Cancelled",
    "Hierarchy",
    "Material",
    "Prt",
    "Scene",
    "Splat",
    "__version__",
    "layer_weight",
    "prepare_profile",
    "profile_ready",
    "reference_radiance",
    "reference_radiosity",
    "reference_single_scattering",
    "relative_error",
    "set_table_cache",
    "table_cache",
]
