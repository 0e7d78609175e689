from ._native import (
    Cancelled as Cancelled,
    Material as Material,
    Prt as Prt,
    Scene as Scene,
    __version__ as __version__,
    layer_weight as layer_weight,
    prepare_profile as prepare_profile,
    profile_ready as profile_ready,
    reference_radiosity as reference_radiosity,
    relative_error as relative_error,
    set_table_cache as set_table_cache,
    table_cache as table_cache,
)
