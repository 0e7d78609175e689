from dataclasses import dataclass

MIN_ALPHA: float
MAX_ALPHA: float
G_RANGE: tuple[float, float]
IOR_RANGE: tuple[float, float]

def single_scattering_albedo(albedo: float, g: float) -> float: ...
@dataclass
class Principled:
    base_color: tuple[float, float, float]
    radius: tuple[float, float, float]
    scale: float
    anisotropy: float
    ior: float
    exact: bool = ...

def from_principled(
    base_color: float | tuple[float, float, float],
    radius: float | tuple[float, float, float],
    scale: float,
    anisotropy: float,
    ior: float,
) -> tuple[tuple[float, float, float], tuple[float, float, float], float, float]: ...
def to_principled(
    sigma_a: float | tuple[float, float, float],
    sigma_s: float | tuple[float, float, float],
    g: float = 0.0,
    eta: float = 1.3,
) -> Principled: ...
def apply_to_principled(node: object, p: Principled) -> None: ...
def read_principled(node: object) -> Principled: ...
def make_volume_material(name: str, sigma_a: object, sigma_s: object, g: float, eta: float) -> object: ...
