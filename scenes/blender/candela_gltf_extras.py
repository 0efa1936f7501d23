# SPDX-License-Identifier: Apache-2.0
"""Candela glTF extras: a Blender 3.4 add-on that extends Blender's own glTF exporter
(io_scene_gltf2 3.4.x) so that an exported scene carries what Cycles renders and glTF cannot
say (issue 14). It writes, as `extras` (the keys Candela's loader reads, README "Scene support"):

  * point and spot lights: "candela_light": {"radius": r}      (the light's Radius, shadow_soft_size)
  * sun lights:            "candela_light": {"angle": deg}     (the sun's angular diameter, degrees)
  * area lights, which the exporter drops (it keeps their node but no light):
        "candela_area_light": {"shape": "rect"|"disk", "size": [x, y], "color": [r, g, b], "power": W}
    on the light's node. Square and Rectangle are "rect", Disk and Ellipse are "disk" (an ellipse
    keeps both diameters in "size": Candela's disk is the ellipse of those diameters). "size" is Blender's Size / Size X, Size Y in the light's local axes; the node keeps
    the object's transform (Blender 3.4's exporter folds a -90 degree X rotation into light nodes
    so that the glTF node's local axes are Blender's local light axes: local -Z is the emission
    direction, one-sided, and local X/Y span the light). "power" is Blender's Power in watts
    (times the strength of an unlinked Emission node in the light's node tree); "color" is the
    light's Color (times that node's colour). Cycles 3.4 gives such a light the radiance
    power / (4 area) * color (measured: README "Blender add-on").
  * materials: a Principled BSDF with Specular 0 (Metallic 0, Transmission 0, unlinked) gets
    KHR_materials_specular "specularFactor": 0. Cycles 3.4 derives that lobe's Fresnel IOR from
    Specular (2 / (1 - sqrt(0.08 specular)) - 1 = 1 at 0): it reflects nothing, not even at grazing
    angles, while the exporter's specularColorFactor 0 keeps glTF's Schlick edge (checked: a black
    Specular 0 sphere under a white world renders 0 in Cycles, its rim included).
  * the world, on the scene: "candela_environment": {"uri": FILE, "rotation": deg, "strength": s}:
      - Background <- Environment Texture (equirectangular) [<- Mapping <- Texture Coordinate]:
        the image is copied next to the .gltf (a packed image is written out), "rotation" is the
        Mapping node's Z rotation in degrees (the sign Candela's --env-rotation uses; a Mapping
        of type Texture is the inverse, so its angle is negated), "strength" the Background's;
      - a constant Background colour (or a world without nodes): a small constant EXR
        `<gltf name>_world.exr` of that colour is written next to the .gltf;
      - a black world (strength 0 or colour 0): nothing (Candela's background is black).
    Anything else in the world (textures Candela cannot reproduce, Mapping X/Y rotation, location,
    non-uniform scale) is reported as a warning and left out.

Light units: Blender's exporter writes punctual lights in its "Standard" lighting mode as
W / (4 pi) * 683 cd (point, spot) and W/m^2 * 683 lux (sun), which Candela's default
`--light-units blender` reads back exactly (intensity / 683 = Cycles' W/sr and W/m^2). In the
"Unitless" (COMPAT) mode Candela must be run with `--light-units raw`; the "Raw" mode writes
point powers as if they were intensities (4 pi off), which no Candela setting undoes: the add-on
warns in both cases. Area light powers are written in watts whatever the mode.

Install: Edit > Preferences > Add-ons > Install..., pick this file, enable "Import-Export:
Candela glTF extras"; then File > Export > glTF 2.0 as usual. Headless:
    blender -b scene.blend --python-expr "import addon_utils; addon_utils.enable('candela_gltf_extras', default_set=True); \
        import bpy; bpy.ops.export_scene.gltf(filepath='out.gltf', export_format='GLTF_SEPARATE')"
(with this file in Blender's add-on path, e.g. ~/.config/blender/3.4/scripts/addons/, or its folder
on sys.path / in BLENDER_USER_SCRIPTS/addons).
"""

import math
import os
import shutil

import bpy

bl_info = {
    "name": "Candela glTF extras",
    "author": "Candela authors",
    "version": (1, 0, 0),
    "blender": (3, 4, 0),
    "location": "File > Export > glTF 2.0 (adds extras; no options)",
    "description": "Exports light radius, sun angle, area lights and the world HDRI (rotation, strength) "
                   "as Candela glTF extras",
    "category": "Import-Export",
}

_PREFIX = "Candela glTF extras: "


def _warn(msg):
    print(_PREFIX + "WARNING: " + msg)


def _emission_node(light):
    """The unlinked-input Emission node feeding the light's active output, or None."""
    if not light.use_nodes or not light.node_tree:
        return None
    for node in light.node_tree.nodes:
        if isinstance(node, bpy.types.ShaderNodeOutputLight) and node.is_active_output:
            surface = node.inputs.get("Surface")
            if surface and surface.is_linked:
                src = surface.links[0].from_node
                if isinstance(src, bpy.types.ShaderNodeEmission):
                    return src
                _warn("light '%s': its node tree is not a plain Emission node; its nodes are ignored" % light.name)
    return None


def _light_color_power(light):
    color = [float(c) for c in light.color]
    power = float(light.energy)
    emission = _emission_node(light)
    if emission is not None:
        col, strength = emission.inputs["Color"], emission.inputs["Strength"]
        if col.is_linked or strength.is_linked:
            _warn("light '%s': a linked Emission colour/strength is ignored" % light.name)
        else:
            color = [c * float(e) for c, e in zip(color, col.default_value[:3])]
            power *= float(strength.default_value)
    return color, power


def _area_light(light):
    shape = light.shape
    if shape == "SQUARE":
        kind, size = "rect", [light.size, light.size]
    elif shape == "RECTANGLE":
        kind, size = "rect", [light.size, light.size_y]
    elif shape == "DISK":
        kind, size = "disk", [light.size, light.size]
    else:  # ELLIPSE
        kind, size = "disk", [light.size, light.size_y]  # Candela's disk is an ellipse of these diameters
    spread = getattr(light, "spread", math.pi)
    if abs(spread - math.pi) > 1e-6:
        _warn("area light '%s': spread %.1f degrees is not exported (Candela's area lights emit over "
              "the whole hemisphere)" % (light.name, math.degrees(spread)))
    color, power = _light_color_power(light)
    return {"shape": kind, "size": [float(size[0]), float(size[1])], "color": color, "power": power}


def _set_extra(target, key, value):
    if not isinstance(target.extras, dict):
        target.extras = {}
    target.extras[key] = value


# ---------------------------------------------------------------- world

def _socket_source(socket):
    return socket.links[0].from_node if socket.is_linked else None


def _copy_image(image, directory, export_settings):
    """Copies (or writes, if packed) the image next to the glTF; returns its name there."""
    name = bpy.path.basename(image.filepath_raw or image.filepath) or (image.name + ".exr")
    dest = os.path.join(directory, name)
    if image.packed_file is not None:
        with open(dest, "wb") as f:
            f.write(image.packed_file.data)
    else:
        src = os.path.abspath(bpy.path.abspath(image.filepath, library=image.library))
        if not os.path.isfile(src):
            _warn("world image '%s' (%s) is missing: no environment exported" % (image.name, src))
            return None
        if os.path.abspath(dest) != src:
            shutil.copyfile(src, dest)
    return name


def _write_constant_exr(color, path):
    """A 4x2 float EXR of one colour: Candela's environment is an image."""
    img = bpy.data.images.new("candela_world_constant", 4, 2, alpha=True, float_buffer=True)
    # Non-Color: Blender 3.4 writes a float image of colour space "Linear" through its display
    # transform (0.03 became 0.19); Non-Color writes the scene-linear values as they are
    img.colorspace_settings.name = "Non-Color"
    try:
        img.pixels[:] = [color[0], color[1], color[2], 1.0] * 8
        img.filepath_raw = path
        img.file_format = "OPEN_EXR"
        img.save()
    finally:
        bpy.data.images.remove(img)


def _mapping_rotation(tex, world_name):
    """Z rotation in degrees of the Mapping node feeding the Environment Texture (0 if none)."""
    mapping = _socket_source(tex.inputs["Vector"])
    if mapping is None:
        return 0.0
    if not isinstance(mapping, bpy.types.ShaderNodeMapping):
        _warn("world '%s': the Environment Texture's vector comes from a %s node, not a Mapping node; "
              "exported without rotation" % (world_name, mapping.bl_idname))
        return 0.0
    coords = _socket_source(mapping.inputs["Vector"])
    if coords is not None and not (isinstance(coords, bpy.types.ShaderNodeTexCoord)
                                   and mapping.inputs["Vector"].links[0].from_socket.name in ("Generated", "Object")):
        _warn("world '%s': the Mapping node's input is not Texture Coordinate > Generated" % world_name)
    for name in ("Location", "Rotation", "Scale"):
        if name in mapping.inputs and mapping.inputs[name].is_linked:
            _warn("world '%s': a linked Mapping %s is ignored" % (world_name, name))
    rot = mapping.inputs["Rotation"].default_value if "Rotation" in mapping.inputs else (0, 0, 0)
    if abs(rot[0]) > 1e-6 or abs(rot[1]) > 1e-6:
        _warn("world '%s': Mapping X/Y rotation is not exported (only the Z rotation)" % world_name)
    if mapping.vector_type in ("POINT", "TEXTURE") and "Location" in mapping.inputs \
            and any(abs(v) > 1e-6 for v in mapping.inputs["Location"].default_value):
        _warn("world '%s': Mapping location is not exported" % world_name)
    if "Scale" in mapping.inputs:
        s = mapping.inputs["Scale"].default_value
        if min(s) <= 0 or max(s) - min(s) > 1e-6:
            _warn("world '%s': non-uniform or negative Mapping scale is not exported" % world_name)
    deg = math.degrees(rot[2])
    # Type Texture applies the inverse transform: the environment turns the other way.
    return -deg if mapping.vector_type == "TEXTURE" else deg


def _world_environment(world, export_settings):
    """The candela_environment dict for the world, or None."""
    directory = export_settings["gltf_filedirectory"]
    if not world.use_nodes or not world.node_tree:
        color = list(world.color)
        if max(color) <= 0:
            return None
        name = os.path.splitext(os.path.basename(export_settings["gltf_filepath"]))[0] + "_world.exr"
        _write_constant_exr(color, os.path.join(directory, name))
        return {"uri": name, "strength": 1.0, "rotation": 0.0}
    out = next((n for n in world.node_tree.nodes
                if isinstance(n, bpy.types.ShaderNodeOutputWorld) and n.is_active_output), None)
    if out is None or not out.inputs["Surface"].is_linked:
        return None
    bg = _socket_source(out.inputs["Surface"])
    if not isinstance(bg, bpy.types.ShaderNodeBackground):
        _warn("world '%s': its output is a %s, not a Background: not exported" % (world.name, bg.bl_idname))
        return None
    if bg.inputs["Strength"].is_linked:
        _warn("world '%s': a linked Background strength is not exported (1 is written)" % world.name)
        strength = 1.0
    else:
        strength = float(bg.inputs["Strength"].default_value)
    if strength <= 0:
        return None
    src = _socket_source(bg.inputs["Color"])
    if src is None:
        color = list(bg.inputs["Color"].default_value[:3])
        if max(color) <= 0:
            return None
        name = os.path.splitext(os.path.basename(export_settings["gltf_filepath"]))[0] + "_world.exr"
        _write_constant_exr(color, os.path.join(directory, name))
        return {"uri": name, "strength": strength, "rotation": 0.0}
    if not isinstance(src, bpy.types.ShaderNodeTexEnvironment) or src.image is None:
        _warn("world '%s': the Background colour comes from a %s node: only an Environment Texture with an "
              "image (or a constant colour) is exported" % (world.name, src.bl_idname))
        return None
    if src.projection != "EQUIRECTANGULAR":
        _warn("world '%s': %s projection is not exported (Candela reads equirectangular maps)"
              % (world.name, src.projection))
        return None
    uri = _copy_image(src.image, directory, export_settings)
    if uri is None:
        return None
    return {"uri": uri, "strength": strength, "rotation": _mapping_rotation(src, world.name)}


def _principled_node(material):
    """The Principled BSDF feeding the material's active output directly, or None."""
    if material is None or not material.use_nodes or not material.node_tree:
        return None
    for node in material.node_tree.nodes:
        if isinstance(node, bpy.types.ShaderNodeOutputMaterial) and node.is_active_output:
            surface = node.inputs.get("Surface")
            if surface is not None and surface.is_linked:
                src = surface.links[0].from_node
                if isinstance(src, bpy.types.ShaderNodeBsdfPrincipled):
                    return src
    return None


# ---------------------------------------------------------------- the exporter's hooks

class glTF2ExportUserExtension:
    """Blender 3.4's io_scene_gltf2 calls hook(*args, export_settings) on every instance of this class
    found in an enabled add-on (io/exp/gltf2_io_user_extensions.py)."""

    def __init__(self):
        self._units_checked = False

    def _check_units(self, export_settings):
        if self._units_checked:
            return
        self._units_checked = True
        mode = export_settings.get("gltf_lighting_mode", "SPEC")
        if mode == "COMPAT":
            _warn("lighting mode Unitless: render with Candela's --light-units raw")
        elif mode == "RAW":
            _warn("lighting mode Raw writes point/spot powers as intensities (4 pi too bright in Candela); "
                  "export with the Standard lighting mode")

    def gather_material_hook(self, gltf2_material, blender_material, export_settings):
        """Principled Specular 0 (unlinked, Metallic 0, Transmission 0): Cycles 3.4 derives the dielectric
        Fresnel's IOR from Specular, 2 / (1 - sqrt(0.08 specular)) - 1 = 1, so there is no specular
        reflection at all, not even at grazing angles; the exporter writes specularColorFactor 0,
        which keeps glTF's Schlick edge (specularFactor 1). specularFactor 0 says what Cycles renders."""
        principled = _principled_node(blender_material)
        if principled is None:
            return
        def zero(name):
            sock = principled.inputs.get(name)
            return sock is not None and not sock.is_linked and float(sock.default_value) == 0.0
        if not (zero("Specular") and zero("Metallic") and zero("Transmission")):
            return
        from io_scene_gltf2.io.com.gltf2_io_extensions import Extension
        if not isinstance(gltf2_material.extensions, dict):
            gltf2_material.extensions = {}
        ext = gltf2_material.extensions.get("KHR_materials_specular")
        if ext is None:
            gltf2_material.extensions["KHR_materials_specular"] = Extension(
                "KHR_materials_specular", {"specularFactor": 0.0}, False)
        else:
            ext.extension["specularFactor"] = 0.0

    def gather_node_hook(self, gltf2_node, blender_object, export_settings):
        if blender_object is None or blender_object.type != "LIGHT":
            return
        light = blender_object.data
        if light.type in ("POINT", "SPOT"):
            self._check_units(export_settings)
            _set_extra(gltf2_node, "candela_light", {"radius": float(light.shadow_soft_size)})
        elif light.type == "SUN":
            self._check_units(export_settings)
            _set_extra(gltf2_node, "candela_light", {"angle": math.degrees(float(light.angle))})
        elif light.type == "AREA":
            if not export_settings.get("gltf_yup", True):
                _warn("area light '%s': exported with +Z up; Candela assumes glTF's +Y up" % light.name)
            _set_extra(gltf2_node, "candela_area_light", _area_light(light))

    def gather_scene_hook(self, gltf2_scene, blender_scene, export_settings):
        world = blender_scene.world
        if world is None:
            return
        env = _world_environment(world, export_settings)
        if env is not None:
            if not export_settings.get("gltf_yup", True):
                _warn("the world is exported for +Y up; this file is +Z up")
            _set_extra(gltf2_scene, "candela_environment", env)


def register_panel():
    """The exporter's dialog asks every extension add-on for a panel; this one has no options."""
    return lambda: None


def register():
    pass


def unregister():
    pass
