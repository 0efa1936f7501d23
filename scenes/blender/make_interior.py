"""scenes/blender/make_interior.py: builds issue 14's interior with Blender's Python and exports it with
Blender's glTF exporter (default settings) and the Candela add-on (scenes/blender/candela_gltf_extras.py)
to scenes/blender_interior/interior.gltf (+ .bin, tiles.png, tiles_normal.png, sky.exr).
Blender 3.4, on your machine only (never in CI):

    blender -b --factory-startup -noaudio -P scenes/blender/make_interior.py -- [--out DIR]
        [--preview FILE.png] [--reference [--spp 256] [--seeds 8] [--max-depth 8]]

The room (Blender axes, Z up, metres): 4 x 5 x 2.6 m, white walls and ceiling, a window in the
back wall; a floor of glossy tiles (a generated 128x128 sRGB colour texture with grout and a
tangent-space normal map of bevelled tile edges, Principled roughness 0.35, repeated every
0.5 m x 0.5 m); a gold metal sphere (roughness 0.2), a clear glass sphere (transmission 1,
IOR 1.45), a red plastic box (roughness 0.25, Specular 0.5); a floor lamp whose open cylindrical
shade is emissive (strength 3, two-sided) with a point light (40 W, radius 0.05 m) inside it;
a ceiling spot (60 W, radius 0.03 m, size 45 degrees, blend 0.3) on the box; a sun (3 W/m^2,
angle 2 degrees) through the window; a world of a generated 64x32 sky (sky.exr) behind a
Mapping node turned 30 degrees about Z. 160x128 camera; no light is in frame.

--preview renders a 32-spp Cycles PNG of the scene as built (to look at).
--reference renders the Cycles reference of the scene as built (blender_common.render_reference)
and writes scenes/blender_interior/interior.cycles.json (image mean, its standard error from
`--seeds` independent seeds, and every 32x32 block's mean). Compare Candela with
`python3 scenes/blender_compare.py scenes/blender_interior/interior.gltf -- --material-model blender3`.
"""
import math
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blender_common as bc  # noqa: E402

import bpy  # noqa: E402

WIDTH, HEIGHT = 160, 128
TEX = 128  # texels per side; one texture holds 2 x 2 tiles


def tile_textures(directory):
    """tiles.png (sRGB colour) and tiles_normal.png (tangent space, +Y up as glTF and Blender)."""
    grout = 0.04  # fraction of a tile, each side
    bevel = 0.10
    colors = [(0.62, 0.50, 0.38), (0.52, 0.40, 0.29)]  # sRGB-encoded values
    rows_c, rows_n = [], []
    half = TEX // 2
    for j in range(TEX):
        row_c, row_n = [], []
        for i in range(TEX):
            u = (i + 0.5) / half % 1.0  # position inside the tile, 0..1
            v = (j + 0.5) / half % 1.0
            tile = ((i // half) + (j // half)) % 2
            du, dv = min(u, 1 - u), min(v, 1 - v)
            if du < grout or dv < grout:
                row_c.append((0.30, 0.29, 0.27, 1.0))
                row_n.append((0.5, 0.5, 1.0, 1.0))
                continue
            row_c.append((*colors[tile], 1.0))
            # bevel: the surface slopes down towards the tile's edge over `bevel` of its width
            nx = ny = 0.0
            slope = 0.6
            if du - grout < bevel:
                nx = slope if u < 0.5 else -slope  # rows/columns: u grows to the right
            if dv - grout < bevel:
                ny = -slope if v < 0.5 else slope  # image rows go down, tangent-space +Y goes up
            n = (-nx, ny, 1.0)
            ln = math.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
            row_n.append((0.5 + 0.5 * n[0] / ln, 0.5 + 0.5 * n[1] / ln, 0.5 + 0.5 * n[2] / ln, 1.0))
        rows_c.append(row_c)
        rows_n.append(row_n)
    color = bc.save_png("tiles", TEX, TEX, rows_c, os.path.join(directory, "tiles.png"))
    normal = bc.save_png("tiles_normal", TEX, TEX, rows_n, os.path.join(directory, "tiles_normal.png"),
                         non_color=True)
    return color, normal


def sky_exr(directory):
    """A 64x32 equirectangular sky: blue above (brighter towards one side, so the rotation
    shows), dark ground below."""
    w, h = 64, 32
    rows = []
    for j in range(h):
        theta = (j + 0.5) / h * math.pi  # 0 at the top
        row = []
        for i in range(w):
            phi = (i + 0.5) / w * 2 * math.pi
            if theta < math.pi / 2:
                up = math.cos(theta)
                side = 0.5 + 0.5 * math.cos(phi)
                row.append((0.35 + 0.25 * side, 0.45 + 0.25 * side, 0.6 + 0.3 * up + 0.2 * side))
            else:
                row.append((0.08, 0.07, 0.06))
        rows.append(row)
    return bc.save_exr("sky", w, h, rows, os.path.join(directory, "sky.exr"))


def floor_material(color_img, normal_img):
    mat = bc.principled("tiles", roughness=0.35, specular=0.5)
    nt = mat.node_tree
    p = nt.nodes["Principled BSDF"]
    tc = nt.nodes.new("ShaderNodeTexImage")
    tc.image = color_img
    nt.links.new(tc.outputs["Color"], p.inputs["Base Color"])
    tn = nt.nodes.new("ShaderNodeTexImage")
    tn.image = normal_img
    nm = nt.nodes.new("ShaderNodeNormalMap")
    nt.links.new(tn.outputs["Color"], nm.inputs["Color"])
    nt.links.new(nm.outputs["Normal"], p.inputs["Normal"])
    return mat


def open_cylinder(name, center, radius, height, material, segments=32):
    cx, cy, z0 = center
    verts, faces = [], []
    for k in range(segments):
        a = 2 * math.pi * k / segments
        verts.append((cx + radius * math.cos(a), cy + radius * math.sin(a), z0))
        verts.append((cx + radius * math.cos(a), cy + radius * math.sin(a), z0 + height))
    for k in range(segments):
        a0, a1 = 2 * k, 2 * ((k + 1) % segments)
        faces.append((a0, a1, a1 + 1, a0 + 1))
    obj = bc.mesh_object(name, verts, faces, material)
    return obj


def build(texdir):
    bc.reset()
    scene = bpy.context.scene
    color_img, normal_img = tile_textures(texdir)
    sky = sky_exr(texdir)
    white = bc.principled("wall_white", base=(0.75, 0.75, 0.72), roughness=0.8)
    gold = bc.principled("gold", base=(1.0, 0.78, 0.34), roughness=0.2, metallic=1.0)
    glass = bc.principled("glass", base=(1.0, 1.0, 1.0), roughness=0.0, transmission=1.0, ior=1.45)
    plastic = bc.principled("red_plastic", base=(0.6, 0.05, 0.05), roughness=0.25, specular=0.5)
    shade = bc.principled("lamp_shade", base=(0.8, 0.7, 0.5), roughness=0.7,
                          emission=(1.0, 0.7, 0.4), emission_strength=3.0, double_sided=True)
    dark = bc.principled("lamp_pole", base=(0.05, 0.05, 0.05), roughness=0.4, metallic=1.0)
    x0, x1, y0, y1, h = -2.0, 2.0, -2.5, 2.5, 2.6
    bc.quad("floor", [(x0, y0, 0), (x1, y0, 0), (x1, y1, 0), (x0, y1, 0)], floor_material(color_img, normal_img),
            uv_scale=((x1 - x0) / 1.0, (y1 - y0) / 1.0))
    bc.quad("ceiling", [(x0, y0, h), (x0, y1, h), (x1, y1, h), (x1, y0, h)], white)
    bc.quad("wall_left", [(x0, y0, 0), (x0, y1, 0), (x0, y1, h), (x0, y0, h)], white)
    bc.quad("wall_right", [(x1, y0, 0), (x1, y0, h), (x1, y1, h), (x1, y1, 0)], white)
    bc.quad("wall_front", [(x0, y0, 0), (x0, y0, h), (x1, y0, h), (x1, y0, 0)], white)
    wx0, wx1, wz0, wz1 = -0.3, 1.3, 0.9, 2.1  # the window in the back wall
    for name, (a0, a1, b0, b1) in {"wall_back_left": (x0, wx0, 0, h), "wall_back_right": (wx1, x1, 0, h),
                                   "wall_back_below": (wx0, wx1, 0, wz0), "wall_back_above": (wx0, wx1, wz1, h)}.items():
        bc.quad(name, [(a0, y1, b0), (a0, y1, b1), (a1, y1, b1), (a1, y1, b0)], white)
    bc.sphere("gold_sphere", (0.8, 0.3, 0.35), 0.35, gold)
    bc.sphere("glass_sphere", (-0.1, 1.0, 0.3), 0.3, glass)
    bc.box("plastic_box", (-1.0, 0.5, 0.3), (0.6, 0.6, 0.6), plastic, rotation_z=math.radians(25))
    lamp = (1.4, -0.9)
    bc.box("lamp_pole", (lamp[0], lamp[1], 0.65), (0.04, 0.04, 1.3), dark)
    open_cylinder("lamp_shade", (lamp[0], lamp[1], 1.3), 0.2, 0.25, shade)
    bc.add_light("POINT", "lamp_bulb", (lamp[0], lamp[1], 1.42), energy=40.0, shadow_soft_size=0.05,
                 color=(1.0, 0.8, 0.6))
    bc.add_light("SPOT", "ceiling_spot", (-1.0, 0.5, 2.55), energy=60.0, shadow_soft_size=0.03,
                 spot_size=math.radians(45), spot_blend=0.3)
    # sun light travels along (0, -0.6, -0.8): rotation about X by -36.87 degrees turns -Z to it
    bc.add_light("SUN", "sun", (0.5, 4.0, 4.0), (math.radians(-36.87), 0, 0), energy=3.0,
                 angle=math.radians(2.0), color=(1.0, 0.95, 0.85))
    world = bpy.data.worlds.new("sky_world")
    world.use_nodes = True
    nt = world.node_tree
    bg = nt.nodes["Background"]
    bg.inputs["Strength"].default_value = 1.0
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = sky
    coords = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.vector_type = "POINT"
    mapping.inputs["Rotation"].default_value[2] = math.radians(30.0)
    nt.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    scene.world = world
    bc.camera("camera", (-1.75, -2.35, 1.5), (0.3, 0.7, 0.55), lens_mm=22.0)
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT


def main():
    out, spp, seeds, depth, reference, preview = bc.generator_args(
        "make_interior.py", os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "blender_interior"))
    with tempfile.TemporaryDirectory() as texdir:
        build(texdir)
        bc.export_gltf(os.path.join(out, "interior.gltf"))
        if preview:
            bc.render_preview(preview, WIDTH, HEIGHT)
        if reference:
            bc.render_reference(os.path.join(out, "interior.cycles.json"), WIDTH, HEIGHT, spp, seeds, depth,
                                note="make_interior.py, as built (Principled materials)")


main()
