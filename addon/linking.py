"""Cycles' light and shadow linking (Blender 4.0 and later): which objects a light lights (its
`light_linking.receiver_collection`) and which cast its shadows (`blocker_collection`).

Blender's manual (Render › Lights › Light Linking) gives the rule for either collection: with
only included objects, the light affects (is blocked by) those alone; with only excluded ones,
every object but those; with both, the included minus the excluded. No collection, or an empty
one: every object. Each entry of the collection (an object, or a child collection standing for
every object in it) carries its state, `CollectionLightLinking.link_state`.

What the export follows: a light that lights every previewed object or none of them (the
irradiance is computed per scene, not per object), and which props cast each light's shadows
(`blockers`, `translucent.Scene.link_shadows`). The rest is stated, not hidden: `export.add_lights`
puts a line in `ExportInfo.linking` for each part left unfollowed."""

from __future__ import annotations

import bpy


def _states(collection: bpy.types.Collection) -> tuple[set[str], set[str]]:
    """The object names the linking collection includes and excludes: its own objects by their
    entry's state, a child collection's objects (all levels) by the child's entry."""
    included, excluded = set(), set()
    # Each entry lies beside its object or child collection, in the same order (the entries
    # do not name them).
    for obj, entry in zip(collection.objects, collection.collection_objects):
        (excluded if entry.light_linking.link_state == "EXCLUDE" else included).add(obj.name)
    for child, entry in zip(collection.children, collection.collection_children):
        names = {o.name for o in child.all_objects}
        (excluded if entry.light_linking.link_state == "EXCLUDE" else included).update(names)
    return included, excluded


def _member(collection: bpy.types.Collection | None, name: str) -> bool:
    """Whether the object `name` is in the set a linking collection defines (every object where
    there is no collection or it has no entries)."""
    if collection is None:
        return True
    included, excluded = _states(collection)
    if name in excluded:
        return False
    return name in included if included else True


def receives(light: bpy.types.Object, name: str) -> bool:
    """Whether Cycles lets `light` light the object `name` (its receiver collection)."""
    linking = getattr(light, "light_linking", None)
    return _member(getattr(linking, "receiver_collection", None), name)


def blocks(light: bpy.types.Object, name: str) -> bool:
    """Whether Cycles lets the object `name` cast `light`'s shadows (its blocker collection)."""
    linking = getattr(light, "light_linking", None)
    return _member(getattr(linking, "blocker_collection", None), name)


def key(light: bpy.types.Object) -> tuple:
    """What the linking of `light` depends on, to compare between updates: each collection's
    included and excluded names."""
    linking = getattr(light, "light_linking", None)
    out = []
    for attr in ("receiver_collection", "blocker_collection"):
        c = getattr(linking, attr, None)
        out.append(None if c is None else tuple(sorted(x) for x in _states(c)))
    return tuple(out)


def follow(light: bpy.types.Object, previewed: list[str], occluders: list[str]) -> tuple[bool, list[str]]:
    """Whether to export `light` (a light, or an emissive rectangle) for the previewed objects
    (names), and the lines saying what of its linking is not followed, `occluders` the other
    objects exported (names; the light's own object aside). A light that lights none of the
    previewed objects is left out (its bounce off the other objects with it); one that lights
    some of them lights all; a receiver or blocker collection that leaves out another exported
    object is named."""
    occluders = [n for n in occluders if n != light.name]
    lit = [n for n in previewed if receives(light, n)]
    if not lit:
        return False, [f"{light.name} lights none of the previewed objects (light linking): left out, "
                       "its bounce off the other objects with it"]
    lines = []
    if len(lit) < len(previewed):
        unlit = ", ".join(n for n in previewed if n not in lit)
        lines.append(f"{light.name} does not light {unlit} in Cycles (light linking): lit here, not followed per "
                     "object")
    dark = sorted(n for n in occluders if not receives(light, n))
    if dark:
        lines.append(f"{light.name} does not light {', '.join(dark)} in Cycles (light linking): their bounce of it "
                     "still counted here")
    linked = getattr(getattr(light, "light_linking", None), "blocker_collection", None) is not None
    free = sorted(n for n in occluders if not blocks(light, n))
    if linked and free:
        lines.append(f"{light.name}'s shadows are not cast by {', '.join(free)} (shadow linking; not followed by the "
                     "splatting)")
    own = sorted(n for n in previewed if not blocks(light, n))
    if own:
        lines.append(f"{light.name}'s shadows are not cast by {', '.join(own)} in Cycles (shadow linking): a "
                     "previewed object always casts them here, not followed")
    return True, lines


def blockers(light: bpy.types.Object, occluders: dict[str, str]) -> list[str] | None:
    """The exported occluders (labels, `occluders` mapping each to its object's name) that cast
    `light`'s shadows under its blocker collection; None where it has none (every one does)."""
    linking = getattr(light, "light_linking", None)
    if getattr(linking, "blocker_collection", None) is None:
        return None
    return sorted(label for label, name in occluders.items() if blocks(light, name))
