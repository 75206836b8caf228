"""Removing assets (meshes, height fields, textures, materials, skins) with every reference to
them, from the elements and from every default class: MuJoCo refuses a model whose reference
names a missing asset, and a default class hands its references to every element in it (a Kinova
Jaco's common.xml gives every site `material="reference_site"` that way)."""

from __future__ import annotations

from pathlib import Path

import mujoco

from gen.lib import mjcf_defaults

ASSET_KINDS = ("mesh", "hfield", "texture", "material", "skin")

# Every attribute that names an asset: (the spec's element list, its default class's member, the
# attribute, the kind of asset it names). Skins have no default class.
REFERENCES = (
    ("geoms", "geom", "meshname", "mesh"), ("geoms", "geom", "hfieldname", "hfield"),
    ("geoms", "geom", "material", "material"),
    ("sites", "site", "meshname", "mesh"), ("sites", "site", "material", "material"),
    ("tendons", "tendon", "material", "material"), ("flexes", "flex", "material", "material"),
    ("skins", None, "material", "material"), ("meshes", "mesh", "material", "material"),
    ("materials", "material", "textures", "texture"), ("lights", "light", "texture", "texture"),
)
_LISTS = {"mesh": "meshes", "hfield": "hfields", "texture": "textures", "material": "materials", "skin": "skins"}


def default_classes(spec: mujoco.MjSpec, path: Path) -> list[mujoco.MjsDefault]:
    """Every default class of the model: `main` and each <default class=...> of the file and its
    includes, nested or not, used by an element or only by other classes (childclass included)."""
    return mjcf_defaults.default_classes(spec, mjcf_defaults.class_names_in_file(path))


def remove_assets(spec: mujoco.MjSpec, kinds: set[str], classes: list[mujoco.MjsDefault],
                  only: set[str] | None = None) -> int:
    """Deletes every asset of the given kinds (or, given `only`, those of them so named) with
    everything that refers to one: the geoms drawn from a deleted mesh or height field are deleted
    (and the contact pairs and sensors naming them), a mesh site becomes a sphere, and every other
    reference (a material's textures, a light's texture, the material of a geom, site, tendon,
    flex, skin or mesh) is cleared, on the elements and on every default class in `classes`. The
    number of geoms deleted."""
    assert kinds <= set(ASSET_KINDS), kinds
    doomed = {kind: {a.name for a in getattr(spec, _LISTS[kind]) if only is None or a.name in only}
              for kind in kinds}
    gone: set[str] = set()
    n = 0
    for g in list(spec.geoms):
        if g.meshname in doomed.get("mesh", ()) or g.hfieldname in doomed.get("hfield", ()):
            if g.name:
                gone.add(g.name)
            spec.delete(g)
            n += 1
    if gone:
        _delete_naming(spec, gone)
    for s in spec.sites:
        if s.meshname and s.meshname in doomed.get("mesh", ()):
            s.meshname = ""
            s.type = mujoco.mjtGeom.mjGEOM_SPHERE
    for d in classes:
        if d.site.meshname in doomed.get("mesh", ()) or (d.site.type == mujoco.mjtGeom.mjGEOM_MESH and
                                                         "mesh" in kinds and only is None):
            d.site.meshname = ""
            d.site.type = mujoco.mjtGeom.mjGEOM_SPHERE
    for elist, member, attr, kind in REFERENCES:
        if kind not in kinds:
            continue
        targets = list(getattr(spec, elist))
        if member is not None:
            targets += [getattr(d, member) for d in classes]
        for e in targets:
            _clear(e, attr, doomed[kind])
    for kind in kinds:
        for a in list(getattr(spec, _LISTS[kind])):
            if a.name in doomed[kind]:
                spec.delete(a)
    return n


def _clear(e: object, attr: str, names: set[str]) -> None:
    """The reference cleared when it names one of `names` (a list of them: those entries)."""
    value = getattr(e, attr)
    if isinstance(value, str):
        if value and value in names:
            setattr(e, attr, "")
    elif any(v in names for v in value):
        setattr(e, attr, ["" if v in names else v for v in value])


def _delete_naming(spec: mujoco.MjSpec, geoms: set[str]) -> None:
    """The contact pairs and sensors that name a deleted geom go with it."""
    for p in list(spec.pairs):
        if p.geomname1 in geoms or p.geomname2 in geoms:
            spec.delete(p)
    for s in list(spec.sensors):
        if s.objtype == mujoco.mjtObj.mjOBJ_GEOM and s.objname in geoms or \
                s.reftype == mujoco.mjtObj.mjOBJ_GEOM and s.refname in geoms:
            spec.delete(s)


def strip_meshes(spec: mujoco.MjSpec, classes: list[mujoco.MjsDefault], only: set[str] | None = None) -> int:
    """Drops the mesh geoms and mesh assets, and textures, height fields and skins (their files may be
    missing too), with every reference to them; given `only`, just the assets so named (those whose
    files are missing: a body whose mass comes from a mesh that is there keeps it). The number of
    geoms dropped."""
    return remove_assets(spec, {"mesh", "hfield", "texture", "skin"}, classes, only)
