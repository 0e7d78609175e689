"""Type stubs of the native module. Units: scene units for lengths, 1/scene unit for
coefficients, Blender/Cycles light units (W, W/m^2, radiance)."""

import math
from typing import Any, Callable, Literal, Sequence, overload

import numpy as np
import numpy.typing as npt

__version__: str

RGB = float | Sequence[float]
Vec3 = Sequence[float]
RGBTuple = tuple[float, float, float]
ArrayN3 = npt.ArrayLike
Progress = Callable[[float], bool | None]

class Cancelled(RuntimeError):
    """Raised when a progress callback returned False."""

LIMITS: dict[str, int | float]
# Cycles' clamps of the walk's inputs: "anisotropy", "ior", "albedo" -> (low, high).
CYCLES_CLAMPS: dict[str, tuple[float, float]]
"""The stated limits on request sizes by name (docs/api.md, "Limits"); a request over one
raises ValueError naming it."""

Profile = Literal["cycles", "dipole", "multipole"]
Backend = Literal["auto", "gpu", "cpu"]

class Material:
    """A homogeneous translucent material: the medium (coefficients in 1/scene unit, g, eta)
    and the Principled BSDF layers Cycles puts around its subsurface lobe."""

    def __init__(self, sigma_a: RGB, sigma_s: RGB, g: float = 0.0, eta: float = 1.3) -> None: ...
    @staticmethod
    def from_principled(
        base_color: RGB,
        radius: RGB,
        scale: float,
        anisotropy: float = 0.0,
        ior: float = 1.5,
        roughness: float = 0.5,
        subsurface_weight: float = 1.0,
        metallic: float = 0.0,
        transmission: float = 0.0,
        specular_ior_level: float = 0.5,
    ) -> Material:
        """What Cycles 5.0 renders for a Principled BSDF (subsurface method "Random Walk"):
        sigma = Chiang's remap of the Base Color over d = radius x scale / (4 pi), g clamped to
        [0, 0.9], and the layers. Inputs Blender would refuse raise ValueError."""
    def with_layers(
        self,
        roughness: float | None = None,
        subsurface_weight: float | None = None,
        metallic: float | None = None,
        transmission: float | None = None,
        base_color: RGB | None = None,
    ) -> Material: ...
    def with_stack(
        self,
        thickness: float = math.inf,
        top: Material | None = None,
        top_thickness: float | None = None,
    ) -> Material:
        """The same medium as a slab `thickness` deep (scene units; inf: a half-space) under an
        optional layer with `top`'s sigma_a and sigma_s (this material's g and eta)
        `top_thickness` deep. Only profile "multipole" reads it (Donner and Jensen 2005); a top
        layer thinner than its source depth 1/sigma_t' in any channel is refused when the
        profile is built. ValueError naming the argument for a thickness <= 0 or NaN."""
    @property
    def thickness(self) -> float: ...
    @property
    def top_layer(self) -> tuple[RGBTuple, RGBTuple, float] | None:
        """(sigma_a, sigma_s, thickness) of the layer over the medium, or None."""
    @staticmethod
    def preset(name: str, mm_per_unit: float = 1000.0) -> Material:
        """Jensen 2001's measured material `name`; `mm_per_unit` mm per scene unit (1000 = metres)."""
    @staticmethod
    def preset_names() -> list[str]: ...
    @property
    def sigma_a(self) -> tuple[float, float, float]: ...
    @property
    def sigma_s(self) -> tuple[float, float, float]: ...
    @property
    def g(self) -> float: ...
    @property
    def eta(self) -> float: ...
    @property
    def roughness(self) -> float: ...
    @property
    def subsurface_weight(self) -> float: ...
    @property
    def metallic(self) -> float: ...
    @property
    def transmission(self) -> float: ...
    @property
    def base_color(self) -> tuple[float, float, float]: ...
    @property
    def total_diffuse_reflectance(self) -> tuple[float, float, float]:
        """The dipole's R_d,total per channel (Jensen 2001)."""
    def slab_reflectance(
        self, profile: Profile = "cycles", cos_view: float = 1.0
    ) -> tuple[float, float, float]:
        """A thick slab's radiance under a white world of radiance 1, seen at `cos_view`: what
        the specular layer leaves, W(cos_view), times the view factor V(cos_view) (Cycles' walk
        enters along the view refracted into the medium; 1 along the normal and for the
        dipole) times the lobes' totals."""

class Scene:
    """A triangle mesh with its lights and world."""

    def __init__(
        self,
        positions: ArrayN3,
        triangles: npt.ArrayLike,
        normals: ArrayN3 | None = None,
        objects: npt.ArrayLike | None = None,
    ) -> None:
        """`positions` (N, 3) in scene units, held in single precision; `triangles` (M, 3) vertex
        indices of an integer dtype. ValueError for NaN/Inf or out-of-range values (beyond f32, or
        whose squared lengths or cross products overflow it), bad indices, empty meshes or zero
        total area; TypeError for triangles that are not integers. `objects` (N,) integers: the
        object each vertex belongs to; PRT's transport and its walks gather no light from another
        object (Cycles' walk stays in its own). ValueError names a triangle joining two objects."""
    def add_sun(self, direction: Vec3, irradiance: float, color: RGB | None = None) -> None:
        """`direction`: the way the light travels; `irradiance`: Blender's Strength [W/m^2]."""
    def add_point_light(self, position: Vec3, power: float, color: RGB | None = None) -> None:
        """`power`: Blender's Power [W]; intensity power/(4 pi) [W/sr]."""
    def add_spot_light(
        self,
        position: Vec3,
        direction: Vec3,
        power: float,
        spot_size: float,
        blend: float = 0.15,
        color: RGB | None = None,
    ) -> None:
        """`spot_size`: full cone angle [rad]; `blend` in [0, 1] as in Blender."""
    def add_area_light(
        self,
        position: Vec3,
        direction: Vec3,
        axis_u: Vec3,
        size_u: float,
        size_v: float,
        power: float,
        color: RGB | None = None,
    ) -> None:
        """One-sided rectangle of `power` [W], emitting along `direction`."""
    def add_mesh_light(
        self,
        positions: npt.ArrayLike,
        triangles: npt.ArrayLike,
        strength: float,
        color: RGB | None = None,
        corner_colors: npt.ArrayLike | None = None,
        visible_shadow: bool = True,
    ) -> None:
        """A mesh emitting radiance `strength` x `color` [W/(unit^2 sr)] from both sides of its
        triangles (Blender's Emission shader on any shape): positions (N, 3), triangles (M, 3).
        `corner_colors` (M, 3, 3): a textured or mixed emission, each triangle's corners' RGB
        factors of that radiance, blended across it (sampled by power, so black parts cost no
        rays). `visible_shadow=False`: hidden from shadow rays (Object > Visibility > Ray
        Visibility > Shadow off), its near side no longer hides its far side. ValueError names
        a position that is not finite, an index out of range, a mesh with no area, a negative
        strength or factor, or corner colours of another shape."""
    def set_world(
        self, color: RGB | None = None, strength: float = 1.0, image: npt.ArrayLike | None = None
    ) -> None:
        """Uniform radiance `color` x `strength`, or an (H, W, 3) equirectangular radiance image."""
    def add_occluder(
        self, positions: npt.ArrayLike, triangles: npt.ArrayLike, name: str = "occluder", albedo: RGB | None = None
    ) -> None:
        """Another object that casts shadows on the mesh and does not scatter (a floor, a wall,
        a prop): world-space (N, 3) positions and (M, 3) triangles, either winding. Shadow rays
        stop at it; the walks and the object's own light never enter it. `albedo` (a float or
        RGB in [0, 1]) above 0 sends light back by one diffuse bounce. ValueError names what is
        wrong (NaN, an index out of range, an empty object)."""
    def without_lights(self) -> Scene:
        """A copy of this scene's mesh and occluders (other objects, their albedo) with no
        light, world or linking, for adding the lights again while the rest stays as it was."""
    def link_shadows(self, light: int, blockers: Sequence[str], mesh: bool | Sequence[int] = True) -> None:
        """Shadow linking (Cycles' blocker collection) for light `light`, its place among the
        lights added (0 the first): only the occluders named in `blockers` cast its shadows, and
        of the mesh the objects `mesh` names (True: all, False: none, or their indices as in
        `objects`; 0 for a mesh of one); the other lights keep every object. Followed by the
        irradiance of PRT (single scattering too), the hierarchy and the references; not by the
        splatting. ValueError names an unknown light, occluder or object; TypeError a `mesh`
        that is none of those."""
    def link_light(self, light: int, receivers: Sequence[str], mesh: bool | Sequence[int] = True) -> None:
        """Light linking (Cycles' receiver collection) for light `light`, its place among the
        lights added: it lights only the occluders named in `receivers` (only they send it back
        as the bounce) and of the mesh the objects `mesh` names (as `link_shadows`); a mesh
        object left out still receives it from the occluders it lights, as in Cycles. Followed
        where `link_shadows` is. ValueError names an unknown light, occluder or object."""
    @property
    def occluders(self) -> dict[str, object]:
        """What the shadow rays keep of the occluders under the current lights and world:
        objects, triangles, triangles_kept, objects_skipped (names), degenerate."""
    def irradiance(
        self,
        eta: float = 1.0,
        world_samples: int = 64,
        area_samples: int = 16,
        seed: int = 0,
        progress: Progress | None = None,
    ) -> npt.NDArray[np.float32]:
        """(N, 3) irradiance entering the surface at each vertex (Xu 2007 eq. 3). `progress` as
        for every long call: False cancels (`Cancelled`)."""
    @property
    def vertex_count(self) -> int: ...
    @property
    def triangle_count(self) -> int: ...
    @property
    def area(self) -> float: ...
    @property
    def light_count(self) -> int: ...
    @property
    def lighting_version(self) -> int:
        """Grows with every light or world change (what `Prt.stale_reason` compares)."""
    @property
    def vertex_coverage(self) -> npt.NDArray[np.float32]:
        """(N,) share of a small disc around each vertex that the surface covers: 1 inside, the
        angle share on an open boundary (1/2 on a straight edge), 0 for unused vertices."""
    @property
    def positions(self) -> npt.NDArray[np.float32]:
        """(N, 3) vertex positions [unit]: a pose's `update(positions=...)` takes these."""
    @property
    def normals(self) -> npt.NDArray[np.float32]:
        """(N, 3) unit vertex normals (given, or area-weighted)."""
    @property
    def vertex_areas(self) -> npt.NDArray[np.float32]:
        """(N, 1) area per vertex, the weights of error metrics."""
    @property
    def mesh_report(self) -> dict[str, float]:
        """What validation found that is not fatal: degenerate_triangles, isolated_vertices,
        zero_normals, normals_against_winding, open_edges, non_manifold_edges,
        inconsistent_edges, reversed_pairs, closed_components, inward_components,
        closed_volume, area."""

class Prt:
    """Precomputed transport (Xu 2007) of a scene; evaluates a material in milliseconds."""

    def __init__(
        self,
        scene: Scene,
        materials: Material | Sequence[Material],
        coefficients: int = 32,
        degree: Literal[1, 2] = 1,
        samples: int | None = None,
        tolerance: float = 1e-5,
        far_field: float = 0.25,
        world_samples: int = 64,
        area_samples: int = 16,
        progress: Progress | None = None,
        backend: Literal["auto", "gpu", "cpu"] = "auto",
        fit_tolerance: float | None = None,
        profile: Profile = "cycles",
        interreflection: bool | None = None,
        interreflection_rays: int = 144,
        walks: int | None = None,
        walk_vertices: int = 1000,
        walk_rays: int | None = None,
        walk_media: int | None = None,
        single_scattering: bool | None = None,
        single_coefficients: int = 16,
        single_steps: int = 32,
        first_preview: bool = False,
        seed: int = 0,
    ) -> None:
        """`seed`: the walks' and the irradiance's random streams (the object's own light and the
        samples' places are fixed). Two seeds give two independent previews of one scene; their
        difference shows the noise the error estimate states. ValueError below 0.

        `first_preview`: a picture to show while the full precompute runs: the half-space
        profile and the object's own light on 16 rays a vertex (as `interreflection` says; no
        walks, no single scattering unless asked) on at most 150,000 samples
        (`report["first_preview"]`); about 0.8 s for the 10 cm bunny (6.5 % from the full
        preview there) where the full precompute takes 15-20 s. Asking for walks with it
        raises ValueError.
        `profile`: "cycles" (Cycles' random walk with the Principled layers: what a Cycles
        render shows) or "dipole" (Jensen's dipole, the papers' model).
        `interreflection`: add the object's own light falling back on it (three bounces, ray
        cast with `interreflection_rays` per vertex); None: on for "cycles" (Cycles shows it),
        off for "dipole".
        `walks`: Cycles' walk traced through the mesh itself for the geometry a half-space
        profile cannot see (thin and curved parts); None: on for "cycles" with as many walks as
        `walk_rays` rays allow (default 30 M, at least 600 and at most 8000 per vertex: about
        32 walks each at as many vertices as that buys, up to all, then half the walks evenly
        and half where they spread most; 12-15 s on 2 cores for the 10 cm bunny), off
        for "dipole"; with several `materials`, those whose diffusion lengths lie more than
        1.5x beyond the first's are walked too, the rays shared (`report["walks"]["media"]`:
        a textured Base Color's brightest and darkest; `walk_media`: at most that many of
        `materials`, from the first, are walked, the rest only set the basis); N: exactly N walks per walked vertex and channel; 0: off. Each walk
        carries a control variate (its twin in the tangent half-space), so few walks suffice. Flat
        neighbourhoods are not walked (`report["walks"]["skipped_flat"]`); where the term
        changes faster than the walked vertices' spacing, and at vertices sunk inside another
        part of the mesh, a second pass walks 3x closer with up to half the rays again
        (`report["walks"]["refined_vertices"]`).
        `backend`: where edits run; "auto" takes a hardware GPU if there is one, else the CPU;
        "gpu" takes any wgpu adapter (Mesa's lavapipe too) and raises RuntimeError if none.
        `fit_tolerance`: choose the basis size as the smallest (up to `coefficients`) whose
        estimated relative error on `materials` is at most this, instead of fixing it.
        `single_scattering`: Xu 2007's single-scattering term L^(1) (eqs. 12-15; the dipole
        only: Cycles' walk already holds every order, True with "cycles" raises ValueError);
        None: on when the materials' single-scattering share (a thick slab under a sun, seen
        along the normal: L^(1) / (L^(1) + L_d), worst channel) is at least 1 %
        (report["single_scattering_share"], ["single_scattering_reason"]). Its transport:
        `single_coefficients` basis functions of E = exp(-sigma_t r), `single_steps`
        deterministic steps along the path below each vertex (Xu: 16 and 32)."""
    def set_backend(self, backend: Literal["auto", "gpu", "cpu"], half: bool = False) -> str:
        """Moves edits to another device; returns which one (or why the CPU was kept).
        `half` stores the GPU transport as f16 (half the memory; see transport_f16_error)."""
    @property
    def transport_f16_error(self) -> float | None: ...
    @property
    def backend(self) -> Literal["gpu", "cpu"]: ...
    @property
    def backend_message(self) -> str: ...
    def radiosity(
        self,
        material: Material,
        interreflection: bool = True,
        walks: bool = True,
        base_color: npt.ArrayLike | None = None,
        subsurface_weight: npt.ArrayLike | None = None,
        others: npt.ArrayLike | None = None,
    ) -> npt.NDArray[np.float32]:
        """(N, 3) radiosity B per vertex: the profile summed over the lit surface (with the
        object's own light where it was precomputed, unless `interreflection` is False, and
        the walks' geometry term where they ran, unless `walks` is False: then the half-space
        profile alone, what `reference_radiosity` integrates).
        `base_color`: (N, 3) Principled Base Color per vertex (linear RGB, saturated to [0, 1]
        as Cycles does) for a `Material.from_principled` material: each vertex scatters as its
        own Base Color's medium; the estimate adds the table's interpolation error.
        `subsurface_weight`: (N,) Principled Subsurface Weight per vertex in [0, 1] (Cycles'
        profile only; the material's own Base Color where `base_color` is not given): w of the
        subsurface lobe and 1 - w of the diffuse lobe beside it, as Cycles splits them.
        `others`: (N, 3), for a uniform `Material.from_principled` material whose object has faces
        of other materials: their vertices' Base Color, NaN rows for the previewed vertices. The
        others scatter as their own colour into the object's own light and come back NaN (not
        previewed; `last_eval["skipped"]` counts them); the previewed vertices cost a uniform
        edit. Not with `base_color` or `subsurface_weight` (put the others' colours in
        `base_color`'s rows then)."""
    def radiance(
        self,
        material: Material,
        eye: Vec3 | None = None,
        phase: Literal["hg", "eddington"] = "hg",
        base_color: npt.ArrayLike | None = None,
        subsurface_weight: npt.ArrayLike | None = None,
        others: npt.ArrayLike | None = None,
    ) -> npt.NDArray[np.float32]:
        """(N, 3) radiance toward the point `eye`, W(w_o) V(w_o) B / pi (W: F_t for the dipole, what
        the specular layer leaves for Cycles; V: Cycles' view factor, see `Material.slab_reflectance`,
        1 for the dipole); without an eye, along each vertex normal (a bake).
        With single scattering (report["single_scattering"]) plus L^(1) toward the eye, with
        the Henyey-Greenstein ("hg") or Eddington (Xu eq. 11) phase function.
        `base_color`, `subsurface_weight` and `others` as `radiosity` (multiple scattering alone
        then; `last_eval["skipped"]` says so)."""
    def single_radiance(
        self,
        material: Material,
        eye: Vec3 | None = None,
        phase: Literal["hg", "eddington"] = "hg",
    ) -> npt.NDArray[np.float32]:
        """(N, 3) single scattering L^(1) alone toward `eye` (Xu 2007 eq. 14); ValueError when
        the precompute left it out."""
    @property
    def last_eval(self) -> dict[str, Any] | None:
        """The keys every method shares: method ("prt"), quantity ("radiosity" or "radiance"),
        error_estimate (per channel, relative), seconds, skipped (a list of {"what", "why"}); then
        PRT's own: fit_seconds, dot_seconds, backend, fit_error, irradiance_noise (the part of
        error_estimate the irradiance's sampling brings, per channel: the bounce off the rest of
        the scene, area and mesh lights' points, the traced world's rays), refresh_advised; GPU
        timings when the GPU ran it; single_error_estimate and single_seconds when single
        scattering was evaluated."""
    @property
    def refresh_advised(self) -> bool | None:
        """True when the last evaluation's estimated error says the material left the range the
        basis was chosen for (above 1 % and 3x the representatives' own), or when the scene's
        lights or world changed since the precompute (`stale_reason`): `update(lights=scene)`."""
    @property
    def stale_reason(self) -> str | None:
        """None while the precompute's (or the last update's) lighting is the scene's; else a
        sentence saying the scene's lights or world changed since."""
    def update(
        self,
        lights: Scene | None = None,
        positions: npt.ArrayLike | None = None,
        normals: npt.ArrayLike | None = None,
        first_preview: bool | None = None,
        progress: Progress | None = None,
    ) -> dict[str, Any]:
        """New lights and world for the same mesh (`lights`: a Scene of this mesh), or a pose of
        it: `positions` (N, 3) and optionally `normals` (the same vertices and triangles; under
        `lights`' lights when given, else the held ones), or a `lights` Scene whose mesh is a
        pose of this one. Recomputes only what depends on the light (irradiance, transport
        rows, the walks' term read at the same exits with no walk traced, the object's own
        light gathered over its kept rays); a pose recomputes the samples, irradiance and
        transport on the posed mesh and carries the walks and the own light to it
        (`report["carried_pose"]`: a new precompute refines them), on a first preview's
        samples (`first_preview` None or True: about a second) or the precompute's (False;
        `first_preview` is refused for a light-only update). The old transport answers
        edits until the new one replaces it, and a cancel keeps it. When every light's (and
        the world's) emission only changed by one factor per channel, a rescale: no ray, and
        `rescaled` gives the factor (else None). When one light's (or the world's) emission
        alone changed, the transport is the old one plus that source's own layer scaled
        (`from_layer` True): relit under that source alone once, at the first such change
        (`seconds_layer`), and kept; a later change casts no ray. Returns seconds (and per stage), rays,
        own_light_rays, walks_traced, rescaled, from_layer, seconds_layer, layer_bytes (what
        the kept layers hold), posed.
        ValueError names a bad argument (normals
        without positions, another vertex count or topology)."""
    def prepare_layers(self, lights: Scene, progress: Progress | None = None) -> dict[str, Any]:
        """Each light's (and the world's) own layer made now, so that the first change of one
        source's power or colour alone is as quick as every later one (`update`'s
        `from_layer` with `seconds_layer` 0: no ray; 0.08 s instead of 2 s on the 10 cm
        bunny). The add-on calls it on a worker thread after a precompute. `lights`: the Scene
        this Prt was last lit with (ValueError naming `lights` otherwise). A lone source needs
        none (its change rescales everything); black sources, lights that reach neither the
        mesh nor anything that sends light back, and those beyond the 8 kept get none. Releases the GIL; `progress` as for the constructor (False cancels:
        `Cancelled`). Returns built, kept (made before), skipped ([(source, why)]), rays,
        seconds, layer_bytes."""
    @property
    def report(self) -> dict[str, float | int | bool | list[float]]:
        """What the precompute did and left out: samples, support_radius [unit], knots,
        coefficients, basis_size_by_tolerance, representative_error, stored_channels, rays,
        lights_used, lights_skipped_black, lights_unreached, lights_bounce_only (lights reaching
        only the rest of the scene, gathered by its bounce), world_skipped, skipped_beyond_support,
        skipped_dark, skipped_other_object, single_scattering (bool), single_scattering_share,
        single_scattering_tolerance, single_scattering_reason, single (None, or coefficients,
        steps, knots, step_length, groups, spread_groups, legendre_order, transport_bytes,
        quantization_error, on_gpu, rays, bounded_paths, seconds), walks and walks_indirect
        (None, or walked_vertices, skipped_flat, walks_per_vertex, refined_vertices,
        refined_walks_per_vertex, sharp_vertices, sharp_walks_per_vertex (open edges and apexes,
        walked one by one), walks, rays, spacing, kernel_radius, noise, share, media (media
        walked: 1, or more beside the first), seconds:
        the walks through the mesh for the direct light and for the object's own light),
        shadow_edge_triangles and shadow_edge_points (where the walks read the light on a finer
        grid), carried_pose (the walks and own light carried from another pose by `update`,
        not walked on this one), world_unshadowed (a first preview's world by its nine
        spherical-harmonic coefficients, no shadows), seconds per step."""
    @property
    def eta(self) -> float:
        """The IOR of the irradiance's Fresnel factor (1 for the Cycles profile)."""
    @property
    def profile(self) -> Profile: ...
    @property
    def vertex_count(self) -> int: ...

class Splat:
    """Image-space splatting (Shah et al. 2009) over a copy of `scene`, nothing precomputed:
    every evaluation splats each sun, point or spot light's view (ray casts on the CPU), peels
    the whole surface for the world, area lights and point lights inside the mesh's bounding
    sphere (Shah's §Environment Lighting: three axis views, every layer) and for the light the
    rest of the scene sends back (every source's bounce), and gathers the
    splats within r_max (eq. 4) at the vertices of their own object. `eps` is eqs. 4-5's
    threshold in (0, 1); `max_grid` the largest light-view side in [1, 4096] (eq. 5's grid is
    cut to it, the cut reported); `peel_grid` each peeled view's side in [1, 4096] (at most
    `max_grid`).
    ValueError naming eps, max_grid, peel_grid or profile."""

    def __init__(
        self,
        scene: Scene,
        profile: Profile = "cycles",
        eps: float = 0.01,
        max_grid: int = 1024,
        walks: bool = False,
        walk_rays: int | None = None,
        backend: Backend = "auto",
        reuse: bool = False,
        peel_grid: int = 1024,
        estimate_receivers: int = 16,
    ) -> None:
        """`walks` (Cycles' profile only): the walks' geometry term and the object's own light,
        walked at the first evaluation (`walk_rays` in all, default as PRT's) and carried to a
        new light or pose. `backend`: where `render` draws its splats (see `set_backend`).
        `reuse`: each evaluation keeps the earlier ones' splat sources that still see the light
        (Shah 2009's sampling coherence; see the `reuse` property). ValueError naming eps,
        max_grid, peel_grid, estimate_receivers, profile, walks, walk_rays or backend.
        `estimate_receivers`: each evaluation's `error_estimate` is its B at that many vertices
        against the ground truth there (about 0.1-0.2 s a vertex on the 10 cm bunny)."""
    @property
    def reuse(self) -> bool:
        """Whether each evaluation keeps the earlier ones' splat sources (lit anew, moved with a
        pose) and adds the light view's new samples only where none covers them: a slow light
        sweep or turn changes B smoothly. Setting it False forgets them."""
    @reuse.setter
    def reuse(self, on: bool) -> None: ...
    def set_backend(self, backend: Backend, half: bool = False) -> str:
        """Where `render` draws its splats (pass 3): "auto" (a hardware GPU that blends float-32
        targets, else the CPU), "gpu" (any Vulkan adapter, Mesa's lavapipe included;
        RuntimeError when none) or "cpu". `half=True` uses half-float targets (up to 16 % off,
        docs/splat.md). Per-vertex radiosity is gathered on the CPU either way. Returns what was
        chosen, in words."""
    @property
    def backend(self) -> Literal["gpu", "cpu"]:
        """"gpu" where renders draw on a GPU, else "cpu"."""
    def radiosity(
        self,
        material: Material,
        progress: Progress | None = None,
        base_color: npt.ArrayLike | None = None,
        media: int = 2,
        subsurface_weight: npt.ArrayLike | None = None,
    ) -> npt.NDArray[np.float32]:
        """(N, 3) radiosity B per vertex; Cancelled when `progress` returns False. `base_color`:
        (N, 3) Principled Base Color per vertex for a `Material.from_principled` material, as
        `Hierarchy.radiosity`: `media` media (1-16) splatted and blended around each vertex's
        colour; the estimate is read against each estimate receiver's own medium. `render`
        takes them too. `subsurface_weight`: (N,) Subsurface Weight per vertex in [0, 1]
        (Cycles' profile), as `Hierarchy.radiosity`: the media splatted at weight 1 and each
        vertex's lobes split by its weight."""
    def radiance(
        self,
        material: Material,
        eye: Vec3 | None = None,
        progress: Progress | None = None,
        base_color: npt.ArrayLike | None = None,
        media: int = 2,
        subsurface_weight: npt.ArrayLike | None = None,
    ) -> npt.NDArray[np.float32]:
        """(N, 3) radiance toward `eye` (scene units) or along each normal (None); `base_color`,
        `media` and `subsurface_weight` as `radiosity`."""
    def render(
        self,
        material: Material,
        eye: Vec3,
        target: Vec3,
        up: Vec3 | None = None,
        fov: float = 0.6911503837897546,
        size: tuple[int, int] | None = None,
        progress: Progress | None = None,
        base_color: npt.ArrayLike | None = None,
        media: int = 2,
        subsurface_weight: npt.ArrayLike | None = None,
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int32]]:
        """The camera's image: a pinhole at `eye` looking at `target` (scene units), `up` the
        image's up (default +Z), `fov` [rad] across the larger side of `size` = (width, height)
        (default (800, 600); fov's default is Blender's 50 mm lens on its 36 mm sensor). Returns
        the (H, W, 3) radiance toward the eye, row 0 the top (0 off the previewed objects and
        where the rest of the scene stands in front), and an (H, W) mask: the object seen plus
        1, 0 for none. `base_color`, `media` and `subsurface_weight` as `radiosity`: each pixel
        blends the media's radiance with its triangle's corners' weights interpolated at the
        hit (a corner's diffuse lobe through its exit weight toward the eye). ValueError naming eye, target, up, fov, size, base_color or media; Cancelled when
        `progress` returns False."""
    def update(
        self,
        positions: npt.ArrayLike | None = None,
        lights: Scene | None = None,
        normals: npt.ArrayLike | None = None,
    ) -> None:
        """A pose (same vertices and triangles) and/or a Scene whose lights, world and
        occluders replace these; the next evaluation splats the new scene."""
    @property
    def profile(self) -> Profile: ...
    @property
    def eps(self) -> float: ...
    @property
    def max_grid(self) -> int: ...
    @property
    def peel_grid(self) -> int: ...
    @property
    def estimate_receivers(self) -> int:
        """The vertices each evaluation reads the ground truth at for its `error_estimate`
        (`reference_radiosity` at 1 % tolerance; 0: none, and `skipped` says so)."""
    @property
    def walks(self) -> bool: ...
    def retrace_walks(self) -> None:
        """The next evaluation walks the walks' term and the object's own light anew, on the
        current shape and light, for the material it evaluates: a pose (`update(positions=...)`)
        carries them (`report["terms"]["carried_pose"]`) until then. Nothing without walks."""
    @property
    def report(self) -> dict[str, object] | None:
        """The last evaluation's r_max, overlap, splats, "terms" (the walks' and own light's
        report as the Hierarchy's: "walks", "walks_indirect", "own_light_rays",
        "own_light_share", "carried_pose", "seconds"; None without walks), stage seconds (a render's camera view
        too, with the pixels that see the mesh), per-light grid and ray counts and "reuse" (with
        reuse on: "kept", "dropped", "stretched", "covered", "added", "fresh"; else None), and "gpu" (a
        render drawn on a GPU: "adapter", "software", "target", the "groups" and "splats" drawn,
        "culled", "seconds_upload", "seconds_draw", "seconds_readback"; None on the CPU), and
        "peel" (where the world, an area light, a point light inside the bounding sphere or
        the rest of the scene's bounce lights the mesh: "lights" [{"light", "why"}], "world",
        "bounce", "grid", "grid_capped", "rays",
        "crossings", "layers", "cut", "samples", "unlit", "irradiance_rays", "seconds"; else
        None), and "estimate" (the error estimate's "receivers", "level", "seconds"; None with
        `estimate_receivers` 0); None before the first."""
    @property
    def last_eval(self) -> dict[str, object] | None:
        """The keys every method shares ("method" "splat", "quantity", "error_estimate": the
        relative RMS per channel of the half-space B at `estimate_receivers` vertices against
        the ground truth there, None with none, "seconds", "skipped") and "refresh_advised"
        (False)."""

class Hierarchy:
    """Hierarchical boundary elements (Mertens 2003): a face-cluster hierarchy over a copy of
    the scene, links refined by the solid-angle oracle, for deforming meshes and moving lights.
    Nothing is precomputed that a deformation invalidates."""

    def __init__(
        self,
        scene: Scene,
        material: Material,
        profile: Profile = "cycles",
        eps: tuple[float, float] = (0.005, 0.5),
        mode: Literal["on_the_fly", "incremental", "render"] = "on_the_fly",
        world_samples: int = 64,
        area_samples: int = 16,
        estimate_receivers: int = 32,
        world_shadows: bool = False,
        walks: bool = False,
        walk_rays: int | None = None,
        receivers: Literal["vertices", "faces"] = "vertices",
        progress: Progress | None = None,
        walks_from: Prt | None = None,
    ) -> None:
        """Builds the hierarchy and evaluates `material` once. `receivers`: "vertices" gathers
        B at every vertex, each refined from the root (within 2 % of the ground truth on coarse
        and held-out meshes); "faces" at the face centroids, averaged to the vertices (Mertens
        §3.2: on-the-fly 258-301 against 377 ms at 130k triangles, 2.4-6 % off where faces are
        as wide as the diffusion length). Either way the light is sampled at four points of each face. `walks` (Cycles' profile only):
        the walks' geometry term and the object's own light as PRT has them (the shared
        `walks` and `own_light` kernels), walked at this first evaluation for `material`
        (`walk_rays` in all, default as PRT's) and carried to a new light or pose without a
        walk traced (`retrace_walks` walks the pose); off, the half-space profile alone.
        `walks_from`: a `Prt` (Cycles' profile, walks on) precomputed on this same mesh and
        shape, whose walks' term and own light are carried here instead of walked (walks on;
        the records shared, not copied): the hierarchy is up in well under a second where its
        own walks take as long as the precompute's, so a light dragged over a PRT preview is
        followed at the hierarchy's pace (`update(lights=...)`); ValueError when that Prt has
        no walks or another shape. The light the rest of the scene sends back (occluders with an
        albedo) is cast at the vertices, `world_samples` rays each, and each face takes its
        corners' averaged over their rings; its noise and that average's bias are in the error
        estimate. `world_shadows`: False lights
        by the world's nine spherical-harmonic coefficients, unshadowed (Mertens 2003 §5.3,
        no rays); True traces `world_samples` shadowed rays per point. `eps` = (ε₁, ε₂) [sr]: the
        receiver's and the emitter's solid-angle thresholds of the refinement oracle.
        `mode`: "on_the_fly" (everything from scratch each evaluation, no links kept),
        "render" (links kept; a light change gathers again over them), "incremental" (links
        kept and re-checked after a material or geometry change). Releases the GIL."""
    def radiosity(
        self,
        material: Material,
        base_color: npt.ArrayLike | None = None,
        media: int = 2,
        progress: Progress | None = None,
        subsurface_weight: npt.ArrayLike | None = None,
    ) -> npt.NDArray[np.float32]:
        """B per vertex, (N, 3): what `reference_radiosity` integrates. `base_color`: (N, 3)
        Principled Base Color per vertex (linear RGB, saturated to [0, 1] as Cycles does) for a
        `Material.from_principled` material, whose own Base Color is then unused: each vertex
        scatters as its own Base Color's medium, as Cycles' walk takes the medium where it
        starts. The hierarchy sums `media` media (1-16; Base Colors at the vertices'
        area-weighted quantiles, per channel) and blends the two around each vertex's colour,
        each scaled by the vertex's own slab total: exact under a light uniform over the
        profile's reach and at a vertex of a medium's colour. `last_eval["error_estimate"]`
        adds what the blend misses, measured at the estimate's receivers against each one's own
        medium, and the totals' table error. Costs `media` evaluations. `subsurface_weight`:
        (N,) Principled Subsurface Weight per vertex in [0, 1] (Cycles' profile only), with or
        without `base_color`: the media summed at weight 1 and each vertex taking w of its blend
        and (1 - w) of the diffuse lobe, (1 - Metallic)(1 - Transmission) times its Base Color
        times its irradiance plus the own light (the object's own light sent by the vertices'
        mean of both lobes). `progress(fraction)` as
        for every long call: False cancels (`Cancelled`), the links of an unfinished refinement
        dropped, the hierarchy as it was."""
    def radiance(
        self,
        material: Material,
        eye: Vec3 | None = None,
        base_color: npt.ArrayLike | None = None,
        media: int = 2,
        progress: Progress | None = None,
        subsurface_weight: npt.ArrayLike | None = None,
    ) -> npt.NDArray[np.float32]:
        """L = W(w_o) B / pi toward `eye`, or along each normal without one. `base_color`,
        `media`, `progress` and `subsurface_weight` as `radiosity` (W and Cycles' view factor
        then the first medium's)."""
    def update(
        self,
        positions: npt.ArrayLike | None = None,
        lights: Scene | None = None,
        normals: npt.ArrayLike | None = None,
    ) -> None:
        """The mesh deformed (same vertex count and triangles) and/or the lights, world and
        occluders are now those of the Scene `lights` (other occluders: every light's rays
        cast again). Evaluated at the next `radiosity`/`radiance`."""
    def retrace_walks(self) -> None:
        """With walks on: the next evaluation walks them anew on the mesh as it is now (the
        refinement after a pose); a no-op with walks off."""
    mode: Literal["on_the_fly", "incremental", "render"]
    @property
    def profile(self) -> Profile: ...
    @property
    def eps(self) -> tuple[float, float]: ...
    @property
    def vertex_count(self) -> int: ...
    @property
    def last_eval(self) -> dict[str, Any] | None:
        """The last evaluation, with the keys every method shares: method ("hierarchy"), quantity,
        error_estimate (per channel; None when estimate_receivers is 0: no estimate computed),
        seconds, skipped (a list of {"what", "why"}); and refresh_advised (always False)."""
    @property
    def report(self) -> dict[str, object]:
        """The last evaluation: links, far_links, near_links, links_per_face, split_faces, edge_faces
        (split faces resolved finer along a shadow's edge), clusters, faces,
        depth, oracle_tests, relinked, rays, seconds per phase (build, refit, irradiance, pull,
        links, push, estimate) and in all, error_estimate per channel (the sampled irradiance's
        noise, irradiance_noise, and the walks' added), terms (None with walks off; else walks, walks_indirect, own_light_rays,
        own_light_share, carried_pose, seconds)."""

@overload
def reference_radiosity(
    scene: Scene,
    material: Material,
    rel_tol: float = 1e-3,
    receivers: Sequence[int] | None = None,
    max_level: int = 4,
    world_samples: int = 64,
    area_samples: int = 16,
    progress: Progress | None = None,
    details: Literal[False] = False,
    profile: Profile = "cycles",
    max_nodes: int = 4_000_000,
) -> npt.NDArray[np.float32]: ...
@overload
def reference_radiosity(
    scene: Scene,
    material: Material,
    rel_tol: float = 1e-3,
    receivers: Sequence[int] | None = None,
    max_level: int = 4,
    world_samples: int = 64,
    area_samples: int = 16,
    progress: Progress | None = None,
    *,
    details: Literal[True],
    profile: Profile = "cycles",
    max_nodes: int = 4_000_000,
) -> tuple[npt.NDArray[np.float32], dict[str, object]]: ...
@overload
def reference_radiance(
    scene: Scene,
    material: Material,
    profile: Literal["cycles"] = "cycles",
    walks: int = 256,
    receivers: Sequence[int] | None = None,
    seed: int = 0,
    world_samples: int = 64,
    area_samples: int = 16,
    progress: Progress | None = None,
    details: Literal[False] = False,
    at: Literal["bake", "vertex"] = "bake",
    tunnel: bool = True,
) -> npt.NDArray[np.float32]:
    """Cycles' answer without Blender: radiance along each receiver's normal (as a vertex bake
    records it) from Cycles 5.0's random walk traced inside the mesh, `walks` per vertex and
    channel, direct light; each walk with its tangent half-space twin as a control variate
    (the standard error is that of the corrected mean). `at="bake"` enters where Blender's
    vertex bake samples (each corner's point 1e-4 * max(1, largest |coordinate|) towards the
    corner triangle's centroid, the walks spread evenly over them), `at="vertex"` at the
    vertex. `tunnel=False` leaves out what Cycles files as indirect light although no other
    surface reflects it: a walk leaving through a surface inside another part of the mesh (an
    eyeball sunk into a head) goes on past that part after the exit's bounce. Compare with a
    direct-light bake with `tunnel=False`. Releases the GIL."""
@overload
def reference_radiance(
    scene: Scene,
    material: Material,
    profile: Literal["cycles"] = "cycles",
    walks: int = 256,
    receivers: Sequence[int] | None = None,
    seed: int = 0,
    world_samples: int = 64,
    area_samples: int = 16,
    progress: Progress | None = None,
    *,
    details: Literal[True],
    at: Literal["bake", "vertex"] = "bake",
    tunnel: bool = True,
) -> tuple[npt.NDArray[np.float32], dict[str, object]]: ...
@overload
def reference_single_scattering(
    scene: Scene,
    material: Material,
    eye: Vec3 | None = None,
    receivers: Sequence[int] | None = None,
    phase: Literal["hg", "eddington"] = "hg",
    steps: int = 512,
    world_samples: int = 64,
    area_samples: int = 16,
    details: Literal[False] = False,
    progress: Progress | None = None,
) -> npt.NDArray[np.float32]:
    """Ground-truth single scattering L^(1) toward `eye` (None: along each normal), (K, 3):
    Xu 2007 eq. 5 by brute force with the exact attenuation exp(-sigma_t (s'_i + s)) and phase
    function, `steps` cells per channel along the path below each receiver (relative
    quadrature error below 1e-4 at 512 on a plane); the same path model and light sampling as
    `Prt(single_scattering=True)`, no basis. Releases the GIL."""
@overload
def reference_single_scattering(
    scene: Scene,
    material: Material,
    eye: Vec3 | None = None,
    receivers: Sequence[int] | None = None,
    phase: Literal["hg", "eddington"] = "hg",
    steps: int = 512,
    world_samples: int = 64,
    area_samples: int = 16,
    *,
    details: Literal[True],
    progress: Progress | None = None,
) -> tuple[npt.NDArray[np.float32], dict[str, object]]: ...
def relative_error(
    estimate: ArrayN3, truth: ArrayN3, weights: npt.ArrayLike | None = None
) -> dict[str, list[float]]:
    """Area-weighted relative RMS and max relative error per channel. ValueError for a
    non-finite value (naming the row) or weights all zero; an all-zero truth channel reads 0
    where the estimate is 0 there too, inf where it is not."""
def prepare_profile(material: Material, progress: Progress | None = None, profile: Profile = "cycles") -> float:
    """Builds what `material` needs under `profile`: the random-walk tables of "cycles" (or reads
    them from the table cache), the layered tables of a "multipole" top layer; seconds taken.
    Releases the GIL. ValueError for a stack the multipole refuses."""
def profile_ready(material: Material, profile: Profile = "cycles") -> bool:
    """Whether an edit with `material` under `profile` will find its tables in memory."""
def set_table_cache(path: str | None = None) -> str | None:
    """Folder the walk tables are kept in between sessions (None: memory only)."""
def table_cache() -> str | None: ...
def single_scattering_albedo(albedo: float, g: float) -> float:
    """Cycles' subsurface_random_walk_remap (before its clamp to [0, 0.999999]); albedo in
    [0, 1], g in [0, 0.9], ValueError naming the argument otherwise."""
def layer_weight(roughness: float, cos_view: float, ior: float) -> float:
    """1 - E_spec: what the Principled specular layer leaves to the lobes under it; roughness,
    cos_view in [0, 1], ior in [1, 5], ValueError naming the argument otherwise."""
def principled_for_medium(
    sigma_a: float | Sequence[float], sigma_s: float | Sequence[float], g: float = 0.0, eta: float = 1.3
) -> tuple[tuple[float, float, float], tuple[float, float, float], float, bool]:
    """(base_color, radius, scale, exact): the Principled inputs under which Cycles simulates the
    medium; ValueError for what Cycles cannot represent."""
