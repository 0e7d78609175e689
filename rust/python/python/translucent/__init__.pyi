from ._native import (
    Cancelled as Cancelled,
    Material as Material,
    Prt as Prt,
    Scene as Scene,
    __version__ as __version__,
    reference_radiosity as reference_radiosity,
    relative_error as relative_error,
)
