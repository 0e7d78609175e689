"""Cycles' light and shadow linking (Blender 4.0 and later): which objects a light lights (its
`light_linking.receiver_collection`) and which cast its shadows (`blocker_collection`).

Blender's manual (Render › Lights › Light Linking) gives the rule for either collection: with
only included objects, the light affects (is blocked by) those alone; with only excluded ones,
every object but those; with both, the included minus the excluded. No collection, or an empty
one: every object. Each entry of the collection (an object, or a child collection standing for
every object in it) carries its state, `CollectionLightLinking.link_state`.

What the export follows (`link`): which props and which previewed objects each light lights (a
prop left out sends none of it back; a previewed object left out still receives it from the props
it lights: `translucent.Scene.link_light`), and which of them cast its shadows (`link_shadows`).
A light lighting nothing exported is left out, and `export.add_lights` puts a line in
`ExportInfo.linking` saying so. Every method follows the rest (the splatting's light views too)."""

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
    (names), `occluders` the other objects exported (names; the light's own object aside), and
    the lines saying what its linking left out: a light that lights none of the exported objects
    is left out."""
    occluders = [n for n in occluders if n != light.name]
    if not any(receives(light, n) for n in previewed + occluders):
        return False, [f"{light.name} lights none of the exported objects (light linking): left out"]
    return True, []


def _objects(previewed: list[str], member) -> bool | list[int]:
    """The previewed objects (their places, as the exported mesh's objects) for which `member`
    holds: True for all of them, False for none, else their places."""
    places = [k for k, name in enumerate(previewed) if member(name)]
    return True if len(places) == len(previewed) else bool(places) and places


def link(scene, lights: range, light: bpy.types.Object, previewed: list[str], occluders: dict[str, str]) -> None:
    """Light and shadow linking of `light` onto the core scene's `lights` (the places of the
    lights it was exported as): the props it lights and those casting its shadows (`occluders`
    maps each exported occluder's label to its object's name), and the previewed objects it
    lights and those casting its shadows (`previewed`, by their places in the exported mesh)."""
    linking = getattr(light, "light_linking", None)
    for collection, member, apply in (("receiver_collection", receives, scene.link_light),
                                      ("blocker_collection", blocks, scene.link_shadows)):
        if getattr(linking, collection, None) is None:
            continue
        names = sorted(label for label, name in occluders.items() if member(light, name))
        mesh = _objects(previewed, lambda n, member=member: member(light, n))
        for k in lights:
            apply(k, names, mesh=mesh)
