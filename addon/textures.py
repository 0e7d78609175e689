"""A Base Color or a Subsurface Weight driven by a link (an image texture through any UV map, a
colour attribute, a procedural, a mix of them): Blender evaluates it, per vertex, by a Cycles
emission bake on temporary copies (issue 30, point 2); the add-on re-implements no node.

The copies: the material (its Base Color's link routed into an Emission shader, the only
output), each object's evaluated mesh (UV maps and colour attributes kept, every face on that
material, placed where the object is so Object and Generated coordinates agree) and a scene of
their own. They are removed again whatever happens; the user's objects, meshes, materials,
images and scene are only read."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from translucent import cycles

from . import bake, export
from .principled import MEANS, principled_inputs, principled_node

# The Principled inputs read per vertex where a link drives them (PRT).
FOLLOWED = ("Base Color", "Subsurface Weight")
# Those read where a link drives them and previewed at their mean over the vertices (PRT): the
# transport's samples and knots are spaced for one radius, and the walk table is one Roughness's
# (`principled.MEANS`).
AVERAGED = ("Subsurface Radius", "Subsurface Scale", "Roughness")


def linked(mat: bpy.types.Material, socket: str) -> bool:
    """Whether a link drives the material's Principled input `socket`."""
    node = principled_node(mat)
    return node is not None and socket in node.inputs and node.inputs[socket].is_linked


def linked_base_color(mat: bpy.types.Material) -> bool:
    """Whether a link drives the material's Principled Base Color."""
    return linked(mat, "Base Color")


def linked_any(mat: bpy.types.Material) -> bool:
    """Whether a link drives any input read per vertex (`FOLLOWED`) or as its mean
    (`AVERAGED`)."""
    return any(linked(mat, s) for s in FOLLOWED + AVERAGED)


def _upstream(mat: bpy.types.Material) -> list:
    """The nodes the followed inputs' links read from, directly or through other nodes (groups'
    insides are in their own trees: a group node counts by its inputs and its tree's name)."""
    node = principled_node(mat)
    if node is None:
        return []
    return bake.upstream([node.inputs[s].links[0].from_node for s in FOLLOWED + AVERAGED if linked(mat, s)])


def tree_key(mat: bpy.types.Material) -> str:
    """What the baked colours depend on, as a digest: the nodes upstream of the followed inputs
    (`_upstream`), by `bake.nodes_key`. Equal keys, the same bake; a slider of the Principled
    node itself leaves it as it is."""
    return bake.nodes_key(_upstream(mat))


def _emission_copy(mat: bpy.types.Material, socket: str = "Base Color") -> bpy.types.Material:
    """A copy of `mat` whose only output is an Emission of strength 1 fed by what drives its
    input `socket`: the bake's emission pass is then that input itself (linear; a value in every
    channel)."""
    copy = mat.copy()
    tree = copy.node_tree
    node = principled_node(copy)
    source = node.inputs[socket].links[0].from_socket
    for n in [n for n in tree.nodes if n.type == "OUTPUT_MATERIAL"]:
        tree.nodes.remove(n)
    emit = tree.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    out.target = "ALL"
    if node.inputs[socket].type == "VALUE":
        # A value input: through a value socket of its own (x + 0), so a colour feeding it is
        # converted as Blender converts it for the Principled input.
        value = tree.nodes.new("ShaderNodeMath")
        value.operation = "ADD"
        value.inputs[1].default_value = 0.0
        tree.links.new(source, value.inputs[0])
        source = value.outputs[0]
    tree.links.new(source, emit.inputs["Color"])
    tree.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return copy


def bake_base_color(mat: bpy.types.Material, objects: list[bpy.types.Object], depsgraph=None,
                    socket: str = "Base Color") -> tuple[dict, float]:
    """The Base Color (or the input `socket`) of `mat` per evaluated vertex of each of `objects`
    ({name: (N, 3) float32 linear RGB; a value input in every channel}) as Cycles evaluates it,
    and the bake's seconds. Raises ValueError when the input is not linked or the bake fails (the
    message says why)."""
    if not linked(mat, socket):
        raise ValueError(f"the {socket} of {mat.name!r} is not driven by a link")
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    with bake.baking():  # the copies too: their updates are the bake's own
        return _bake_copies(mat, objects, depsgraph, socket)


def _bake_copies(mat, objects, depsgraph, socket: str) -> tuple[dict, float]:
    """`bake_base_color`'s copies made, baked and removed again."""
    t0 = time.perf_counter()
    made_meshes, copy = [], None
    try:
        copy = _emission_copy(mat, socket)
        for obj in objects:
            mesh = export.evaluated_copy(obj, depsgraph)
            made_meshes.append(mesh)
            mesh.materials.clear()
            mesh.materials.append(copy)
            if len(mesh.polygons):
                mesh.polygons.foreach_set("material_index", np.zeros(len(mesh.polygons), dtype=np.int32))
        try:
            baked = bake.emission([(mesh, obj.matrix_world, []) for obj, mesh in zip(objects, made_meshes)])
        except ValueError as e:
            raise ValueError(f"{e} (reading the {socket})") from e
        return {obj.name: colours for obj, colours in zip(objects, baked)}, time.perf_counter() - t0
    finally:
        for mesh in made_meshes:
            bpy.data.meshes.remove(mesh)
        if copy is not None:
            bpy.data.materials.remove(copy)


def per_exported_vertex(baked: dict, info) -> np.ndarray:
    """The baked colours in the exported scene's vertex order (`export.ExportInfo.objects`: each
    object's range, the vertices of the previewed faces where only some are)."""
    parts = []
    for r in info.objects:
        colours = baked[r.name]
        parts.append(colours if r.vertices is None else colours[r.vertices])
    return np.concatenate(parts).astype(np.float32)


def input_source(mat: bpy.types.Material, socket: str = "Base Color") -> str:
    """The node that drives the Principled input `socket`, as the panel names it ("Image
    Texture")."""
    node = principled_node(mat)
    return node.inputs[socket].links[0].from_node.bl_label if linked(mat, socket) else ""


def for_export(mat: bpy.types.Material, info, depsgraph=None, socket: str = "Base Color") -> tuple[np.ndarray, str]:
    """The Base Color (or `socket`) per exported vertex (`per_exported_vertex`) baked for the
    objects of `info`, and the panel's line about it. Raises ValueError when an object's
    evaluated mesh no longer has the vertex count it was exported with (re-baking would
    misplace colours)."""
    objects = [bpy.data.objects.get(r.name) for r in info.objects]
    if any(o is None for o in objects):
        raise ValueError("an object of the preview is gone")
    baked, seconds = bake_base_color(mat, objects, depsgraph, socket)
    for r in info.objects:
        if r.evaluated_count and len(baked[r.name]) != r.evaluated_count:
            raise ValueError(f"{r.name} has {len(baked[r.name])} vertices now, {r.evaluated_count} at the precompute")
    colours = per_exported_vertex(baked, info)
    return colours, (f"{socket} from {input_source(mat, socket)}: read by Cycles at {len(colours):,} vertices "
                     f"in {1000 * seconds:.0f} ms")


def weights_for_export(mat: bpy.types.Material, info) -> tuple[np.ndarray, str]:
    """The Subsurface Weight per exported vertex (`for_export`: its link converted to a value as
    Blender converts it for the Principled input, saturated to [0, 1] as Cycles does), (N,)
    float32, and the panel's line about it."""
    grey, line = for_export(mat, info, socket="Subsurface Weight")
    return np.clip(grey[:, 0], 0.0, 1.0).astype(np.float32), line


@dataclass
class Reading:
    """What `read` found: the Base Color per exported vertex and the Subsurface Weight (each
    None where it is not read), the node tree's key it was read for, the panel's line, the
    materials a precompute chooses its transport for (empty where the Base Color is uniform),
    and the other materials' albedo per vertex beside a uniform material (`others_in`; None
    where there are none or they sit in `colours`' rows)."""

    colours: np.ndarray | None = None
    key: str = ""
    message: str = ""
    materials: list = field(default_factory=list)
    weights: np.ndarray | None = None
    others: np.ndarray | None = None

    def kwargs(self) -> dict:
        """The per-vertex arguments of `Prt.radiance` (`base_color`, `subsurface_weight`,
        `others`)."""
        out = {}
        if self.colours is not None:
            out["base_color"] = self.colours
        if self.weights is not None:
            out["subsurface_weight"] = self.weights
        if self.others is not None:
            out["others"] = self.others
        return out


def has_others(info) -> bool:
    """Whether some exported vertex scatters as another material (`export.ObjectRange.others`)."""
    return any(r.others is not None for r in info.objects)


def read_others(info) -> None:
    """Reads the other materials' albedo again into `info` (`export.others_now`): a colour
    changed in another material, or another material put in its slot, is seen at the next edit
    without a precompute (the transport takes a Base Color per vertex)."""
    for r in info.objects:
        obj = bpy.data.objects.get(r.name)
        if r.others is not None and r.other_slots is not None and obj is not None:
            r.others = export.others_now(obj, r.other_slots)


def others_key(info) -> str:
    """The other materials' albedo as `read_others` would read it now, as a string."""
    parts = []
    for r in info.objects:
        obj = bpy.data.objects.get(r.name)
        if r.other_slots is None or obj is None:
            continue
        for k, mat in export.other_materials(obj, r.other_slots).items():
            parts.append(f"{r.name}[{k}] {getattr(mat, 'name', None)} {cycles.diffuse_albedo(mat)}")
    return ", ".join(parts)


def others_in(info) -> np.ndarray | None:
    """Per exported vertex, the albedo of the other material it scatters as (`export.ObjectRange
    .others`), NaN rows for the previewed vertices; None when every exported vertex is
    previewed."""
    if not has_others(info):
        return None
    return np.concatenate([r.others if r.others is not None else np.full((r.count, 3), np.nan, np.float32)
                           for r in info.objects]).astype(np.float32)


def beside_others(base_color: np.ndarray, others: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Base Color per exported vertex where the faces of other materials scatter too: the
    previewed vertices' `base_color` ((N, 3), or one colour), the others' own albedo (`others_in`),
    and the mask of the previewed vertices."""
    previewed = np.isnan(others[:, 0])
    colours = np.where(previewed[:, None], np.asarray(base_color, np.float32), others).astype(np.float32)
    return colours, previewed


def _shown(v) -> str:
    """A value or an RGB triple for the panel, four significant digits."""
    return f"{float(v):.4g}" if np.ndim(v) == 0 else "(" + ", ".join(f"{float(x):.4g}" for x in v) + ")"


def read_means(mat: bpy.types.Material, info) -> list[str]:
    """Each linked Subsurface Radius, Scale and Roughness (`AVERAGED`) read by Cycles at the exported
    vertices and kept as their mean in `principled.MEANS` (the preview's one medium), and the
    panel's lines saying over what range it varies. Raises ValueError as `for_export`."""
    means, lines = {}, []
    for socket in AVERAGED:
        if not linked(mat, socket):
            continue
        values, _ = for_export(mat, info, socket=socket)
        if principled_node(mat).inputs[socket].type == "VALUE":
            values = values[:, 0]
        # Summed in float64 (a float32 sum drifts: 964 x 0.004 gave 0.0040000007), held as a
        # socket holds it (float32): the mean typed into the socket is the same medium.
        mean = values.mean(axis=0, dtype=np.float64).astype(np.float32)
        means[socket] = float(mean) if np.ndim(mean) == 0 else tuple(float(x) for x in mean)
        lo, hi = values.min(axis=0), values.max(axis=0)
        lines.append(f"{socket} from {input_source(mat, socket)}: {_shown(lo)} to {_shown(hi)} at {len(values):,} "
                     f"vertices, previewed at their mean {_shown(mean)}: one medium, not per vertex yet")
    MEANS[mat.name] = means  # replaced whole once read: no moment without one
    return lines


def reading_key(mat: bpy.types.Material, info, method: str) -> str:
    """What `read` depends on, as a string ("" where it reads nothing): the node tree's key
    where a link drives a followed input, and the Base Color where the faces of other materials
    scatter beside the previewed ones (PRT; the node tree alone for the hierarchy and the
    splatting; a Principled material only)."""
    if method not in ("prt", "hierarchy", "splat") or mat.translucent.source != "PRINCIPLED":
        return ""
    key = tree_key(mat) if linked_any(mat) else ""
    if method == "prt" and has_others(info):
        inputs = principled_inputs(mat)
        key += (f"; other materials beside Base Color {None if inputs is None else inputs.base_color}: "
                f"{others_key(info)}")
    return key


def read(mat: bpy.types.Material, info, method: str) -> Reading:
    """The Base Color and the Subsurface Weight of `mat` per vertex of the exported scene `info`,
    for a transport built by `method`: read by Cycles (`for_export`) where a link drives them
    and PRT previews them (the weight with Cycles' profile, the one whose lobes it splits), and
    a linked Radius, Scale and Roughness read to their mean (`read_means`); the hierarchy and
    the splatting (per vertex) read the Base Color, the weight and the means, and the line
    says so.
    Where the faces of other materials were exported to scatter
    (`export.export_scene(others_scatter=True)`), their vertices take their own albedo and the
    previewed ones the Base Color. Nothing otherwise."""
    if method == "prt":
        read_others(info)
    others = others_in(info) if method == "prt" else None
    if not any(linked(mat, k) for k in AVERAGED):
        MEANS.pop(mat.name, None)
    if mat.translucent.source != "PRINCIPLED" or not (linked_any(mat) or others is not None):
        return Reading()
    sockets = [s for s in FOLLOWED + AVERAGED if linked(mat, s)]
    names = " and ".join(sockets)
    # The hierarchy and the splatting blend media around each vertex's Base Color: no
    # representatives.
    blended = method in ("hierarchy", "splat")
    out = Reading(key=reading_key(mat, info, method))
    lines = []
    try:
        lines += read_means(mat, info)
        previewed = None
        if linked(mat, "Base Color"):
            out.colours, line = for_export(mat, info)
            lines.append(line)
        if others is not None:
            base = out.colours if out.colours is not None else principled_inputs(mat).base_color
            out.colours, previewed = beside_others(base, others)
            lines.append(f"{int((~previewed).sum()):,} vertices of other materials scatter as their own colour, "
                         "not previewed (Cycles' walk may leave through their faces)")
        if out.colours is not None and not blended:
            out.materials = representatives(principled_inputs(mat), out.colours, previewed)
        if linked(mat, "Subsurface Weight"):
            if mat.translucent.profile_name() != "cycles":
                lines.append("Subsurface Weight: per vertex with Cycles' profile only, the socket's value shown")
            else:
                out.weights, line = weights_for_export(mat, info)
                lines.append(line)
    except ValueError as e:
        return Reading(message=f"{names} not read per vertex ({e}): the socket's value shown")
    if others is not None and out.weights is None and not linked(mat, "Base Color"):
        # A uniform material beside other materials' faces: the previewed vertices cost a
        # uniform edit, the others' albedo passed apart (`Prt.radiance(others=...)`).
        out.colours, out.others = None, others
    out.message = "; ".join(lines)
    return out


# The first three `representatives`: the previewed vertices' media, which the walks may be traced
# for (`Prt(walk_media=...)`); any after them only cover other materials' faces.
SHOWN_MEDIA = 3


def walked(materials: list) -> dict:
    """`Prt`'s argument that keeps the walks to the previewed vertices' media when
    `representatives` added other materials' faces' after them."""
    return {"walk_media": SHOWN_MEDIA} if len(materials) > SHOWN_MEDIA else {}


def representatives(inputs, colours: np.ndarray, previewed: np.ndarray | None = None) -> list:
    """The materials the transport's basis and samples are chosen for when the Base Color
    varies: the inputs at the previewed vertices' mean Base Color (whose walks are traced;
    `previewed` a mask, None: all), and at their per-channel brightest and darkest (walked too
    where their diffusion lengths lie far from the mean's); then, where other materials' faces
    are kept, at every vertex's brightest and darkest, so the support and knots cover every
    medium between (`translucent.Prt` reports the table's interpolation and range in its
    estimate)."""
    import dataclasses

    c = np.clip(colours, 0.0, 1.0)
    shown = c if previewed is None or not previewed.any() else c[previewed]
    picks = [shown.mean(axis=0), shown.max(axis=0), shown.min(axis=0)]
    if len(shown) < len(c):
        picks += [c.max(axis=0), c.min(axis=0)]
    return [dataclasses.replace(inputs, base_color=tuple(float(x) for x in p)).material() for p in picks]


def images_of(mat: bpy.types.Material) -> set[str]:
    """Names of the images the material's node tree reads (their edits re-read the colours)."""
    tree = getattr(mat, "node_tree", None)
    if tree is None:
        return set()
    return {n.image.name for n in tree.nodes if getattr(n, "image", None) is not None}
