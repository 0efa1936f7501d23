"""scenes/blender/make_area.py: builds the area-lit comparison scene with Blender's Python and exports
it with Blender's glTF exporter and the Candela add-on (scenes/blender/candela_gltf_extras.py) to
scenes/blender_area/area.gltf. Blender 3.4, on your machine only (never in CI):

    blender -b --factory-startup -noaudio -P scenes/blender/make_area.py -- [--out DIR]
        [--preview FILE.png] [--reference [--spp 256] [--seeds 8] [--max-depth 8]]

The scene (Blender axes, Z up, metres): a grey floor and back wall, two diffuse boxes (Principled,
Specular 0: Lambert-like in both renderers), a rough metal sphere, lit only by area lights, which
Blender's exporter alone drops: a 1.2 x 0.6 m rectangle (100 W, warm) above, tilted 20 degrees, and
a 0.8 m disk (80 W, blue) at the right, facing left and down; a dim constant world. 160x128
camera; the lights are out of frame (Cycles 3.4 does not show lights to camera rays by default).

--preview renders a 32-spp Cycles PNG of the scene as built (to look at).
--reference renders Cycles references of the scene as built (blender_common.render_reference;
`--seeds` independent seeds of spp/seeds samples) and writes next to the glTF:
  area.cycles.json          Principled materials as authored;
  area.cycles_lambert.json  non-metallic Principled BSDFs replaced by Lambert (Blender 3.4's
                            Principled diffuse is Disney's, not Lambert): what Candela's glTF
                            model renders for Specular 0 (KHR_materials_specular factor 0), so the
                            lights alone are compared (tests/test_blender_area.c).
It also writes area_nolights.gltf, the scene without its lights (the dim world alone), and with
--reference its area_nolights.cycles_lambert.json: the world, the materials (Specular 0 as the add-on
writes it) and the constant-colour world EXR checked apart from the lights.
"""
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blender_common as bc  # noqa: E402

import bpy  # noqa: E402

WIDTH, HEIGHT = 160, 128


def build():
    bc.reset()
    scene = bpy.context.scene
    grey = bc.principled("floor_grey", base=(0.55, 0.55, 0.55), roughness=0.6, specular=0.0)
    wall = bc.principled("wall", base=(0.7, 0.68, 0.62), roughness=0.6, specular=0.0)
    red = bc.principled("red", base=(0.7, 0.12, 0.08), roughness=0.5, specular=0.0)
    green = bc.principled("green", base=(0.15, 0.55, 0.2), roughness=0.5, specular=0.0)
    metal = bc.principled("metal", base=(0.9, 0.8, 0.65), roughness=0.3, metallic=1.0)
    bc.quad("floor", [(-4, -4, 0), (4, -4, 0), (4, 4, 0), (-4, 4, 0)], grey)
    bc.quad("back_wall", [(-4, 2, 0), (4, 2, 0), (4, 2, 4), (-4, 2, 4)], wall)
    bc.box("red_box", (-1.1, 0.6, 0.45), (0.9, 0.9, 0.9), red, rotation_z=math.radians(20))
    bc.box("green_box", (1.1, 0.9, 0.35), (0.6, 0.6, 0.7), green, rotation_z=math.radians(-30))
    bc.sphere("metal_sphere", (0.1, -0.2, 0.45), 0.45, metal)
    bc.add_light("AREA", "rect_light", (-0.4, -0.6, 2.9), (math.radians(20), 0, 0),
                 shape="RECTANGLE", size=1.2, size_y=0.6, energy=100.0, color=(1.0, 0.9, 0.75))
    bc.add_light("AREA", "disk_light", (3.0, 0.3, 1.4), (0, math.radians(60), 0),
                 shape="DISK", size=0.8, energy=80.0, color=(0.6, 0.75, 1.0))
    world = bpy.data.worlds.new("dim_world")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.03, 0.03, 0.04, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    scene.world = world
    bc.camera("camera", (0.0, -5.0, 1.6), (0.0, 0.3, 0.5), lens_mm=35.0)
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT


def main():
    out, spp, seeds, depth, reference, preview = bc.generator_args(
        "make_area.py", os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "blender_area"))
    build()
    bc.export_gltf(os.path.join(out, "area.gltf"))
    if preview:
        bc.render_preview(preview, WIDTH, HEIGHT)
    if reference:
        bc.render_reference(os.path.join(out, "area.cycles.json"), WIDTH, HEIGHT, spp, seeds, depth,
                            note="make_area.py, Principled materials as authored")
        bc.to_lambert()
        bc.render_reference(os.path.join(out, "area.cycles_lambert.json"), WIDTH, HEIGHT, spp, seeds, depth,
                            note="make_area.py, non-metallic Principled BSDFs replaced by Lambert")
    # the same scene without its lights: the world, materials and geometry alone, which Candela
    # renders without the area lights (tests/test_blender_area.c checks both)
    build()
    for obj in [o for o in bpy.context.scene.objects if o.type == "LIGHT"]:
        bpy.data.objects.remove(obj)
    bc.export_gltf(os.path.join(out, "area_nolights.gltf"))
    if reference:
        bc.to_lambert()
        bc.render_reference(os.path.join(out, "area_nolights.cycles_lambert.json"), WIDTH, HEIGHT, spp, seeds,
                            depth, note="make_area.py without its lights (the dim world alone), Lambert as above")


main()
