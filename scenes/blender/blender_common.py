"""Shared by the Blender scene generators in scenes/blender/ (run inside Blender 3.4, never in CI):
export through Blender's glTF exporter with the Candela add-on enabled, and render Cycles
references of the scene as built (not a re-import), with the settings of
../shared/tools/cycles_render.py: CPU, fixed spp, no adaptive sampling, no denoising, no
clamping, light threshold 0, no glossy filter, caustics on, box 1-pixel filter, Standard view
transform, scene-linear float EXR. Bounces: Cycles counts bounces after the first hit (0 is
direct light only), Candela's --max-depth counts surface vertices (1 is direct light only), so
Cycles gets max_bounces = depth - 1 in every kind.

Reference statistics (JSON): the image is rendered as K independent Cycles seeds of spp/K
samples; the JSON holds their average's mean per channel, its standard error (from the spread of
the K seeds' means), and the mean per channel of every 32x32 block (rows top to bottom) with its
standard error (the same way).
"""
import json
import math
import os
import sys
import tempfile

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
BLOCK = 32


def script_args():
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []


def generator_args(script, default_out):
    """The make_*.py scripts' shared arguments (after Blender's `--`): returns
    (out, spp, seeds, max_depth, reference, preview)."""
    args = script_args()
    out, spp, seeds, depth, reference, preview = default_out, 256, 8, 8, False, None
    valued = {"--out": str, "--spp": int, "--seeds": int, "--max-depth": int, "--preview": str}
    values = {}
    i = 0
    while i < len(args):
        a = args[i]
        if a in valued and i + 1 < len(args):
            values[a] = valued[a](args[i + 1])
            i += 1
        elif a == "--reference":
            reference = True
        else:
            sys.exit("%s: unknown argument %s" % (script, a))
        i += 1
    return (values.get("--out", out), values.get("--spp", spp), values.get("--seeds", seeds),
            values.get("--max-depth", depth), reference, values.get("--preview", preview))


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    # Debian bookworm's numpy 1.24 removed np.bool, which io_scene_gltf2 3.4.50 still uses
    import numpy
    if not hasattr(numpy, "bool"):
        numpy.bool = bool


def enable_addon():
    """Enables scenes/blender/candela_gltf_extras.py as an installed add-on would be."""
    import addon_utils
    if HERE not in sys.path:
        sys.path.insert(0, HERE)
    addon_utils.enable("candela_gltf_extras", default_set=True, handle_error=None)
    assert "candela_gltf_extras" in bpy.context.preferences.addons, "the add-on did not enable"


def export_gltf(path, **options):
    """Blender's glTF exporter with its defaults (plus `options`) and the add-on enabled."""
    enable_addon()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    # defaults as a user would leave them, in the separate-files form so the scene is reviewable
    bpy.ops.export_scene.gltf(filepath=os.path.abspath(path), export_format="GLTF_SEPARATE",
                              export_cameras=True, export_lights=True, **options)


def link(obj):
    bpy.context.scene.collection.objects.link(obj)
    return obj


def add_light(kind, name, location, rotation=(0.0, 0.0, 0.0), **props):
    data = bpy.data.lights.new(name, kind)
    for k, v in props.items():
        setattr(data, k, v)
    obj = link(bpy.data.objects.new(name, data))
    obj.location = location
    obj.rotation_euler = rotation
    return obj


def principled(name, base=(0.8, 0.8, 0.8), roughness=0.5, metallic=0.0, specular=0.5,
               transmission=0.0, ior=1.45, emission=None, emission_strength=1.0, double_sided=True):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.use_backface_culling = not double_sided
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (*base, 1.0)
    p.inputs["Roughness"].default_value = roughness
    p.inputs["Metallic"].default_value = metallic
    p.inputs["Specular"].default_value = specular
    p.inputs["Transmission"].default_value = transmission
    p.inputs["IOR"].default_value = ior
    if emission is not None:
        p.inputs["Emission"].default_value = (*emission, 1.0)
        p.inputs["Emission Strength"].default_value = emission_strength
    return mat


def mesh_object(name, verts, faces, material, uvs=None):
    """A mesh from vertex and face lists; uvs: per face-corner (u, v) list, same order as faces."""
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    if uvs is not None:
        layer = me.uv_layers.new(name="UVMap")
        for i, loop in enumerate(me.loops):
            layer.data[i].uv = uvs[i]
    me.materials.append(material)
    me.validate()
    me.update()
    return link(bpy.data.objects.new(name, me))


def quad(name, corners, material, uv_scale=None):
    """A one-quad mesh; corners counter-clockwise seen from the side the normal points to."""
    uvs = None
    if uv_scale is not None:
        su, sv = uv_scale
        uvs = [(0, 0), (su, 0), (su, sv), (0, sv)]
    return mesh_object(name, corners, [(0, 1, 2, 3)], material, uvs)


def box(name, center, size, material, rotation_z=0.0):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=center, rotation=(0.0, 0.0, rotation_z))
    obj = bpy.context.object
    obj.name = name
    obj.scale = size
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    obj.data.materials.append(material)
    return obj


def sphere(name, center, radius, material, segments=48, rings=24):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=radius, location=center)
    obj = bpy.context.object
    obj.name = name
    bpy.ops.object.shade_smooth()
    obj.data.materials.append(material)
    return obj


def camera(name, location, look_at, lens_mm=28.0):
    from mathutils import Vector
    data = bpy.data.cameras.new(name)
    data.lens = lens_mm
    data.sensor_fit = "AUTO"
    obj = link(bpy.data.objects.new(name, data))
    obj.location = location
    d = Vector(look_at) - Vector(location)
    obj.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = obj
    return obj


def save_png(name, width, height, rgba_rows_top_down, path, non_color=False):
    """Writes an 8-bit PNG from a list of rows (top to bottom) of (r, g, b, a) floats in [0, 1]
    (already in the file's encoding: sRGB values for colour images) and returns the loaded image."""
    img = bpy.data.images.new(name, width, height, alpha=False)
    flat = []
    for row in reversed(rgba_rows_top_down):  # Blender's pixels start at the bottom row
        for px in row:
            flat.extend(px)
    img.pixels[:] = flat
    img.filepath_raw = path
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)
    img = bpy.data.images.load(path)
    if non_color:
        img.colorspace_settings.name = "Non-Color"
    return img


def save_exr(name, width, height, rgb_rows_top_down, path):
    img = bpy.data.images.new(name, width, height, alpha=True, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"  # else Blender 3.4 writes display-transformed values
    flat = []
    for row in reversed(rgb_rows_top_down):
        for px in row:
            flat.extend((px[0], px[1], px[2], 1.0))
    img.pixels[:] = flat
    img.filepath_raw = path
    img.file_format = "OPEN_EXR"
    img.save()
    bpy.data.images.remove(img)
    return bpy.data.images.load(path)


# ---------------------------------------------------------------- Cycles references

def cycles_settings(width, height, spp, max_depth, threads=2, seed=0):
    scene = bpy.context.scene
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.threads_mode = "FIXED"
    r.threads = threads
    r.use_motion_blur = False
    r.film_transparent = False
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_mode = "RGBA"
    r.image_settings.color_depth = "32"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    c = scene.cycles
    c.device = "CPU"
    c.feature_set = "SUPPORTED"
    c.samples = spp
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.use_preview_denoising = False
    c.seed = seed
    c.use_animated_seed = False
    c.light_sampling_threshold = 0.0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = True
    c.caustics_refractive = True
    b = max(0, max_depth - 1)
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = b
    c.volume_bounces = c.transparent_max_bounces = b
    c.min_light_bounces = 0
    c.min_transparent_bounces = 0
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.use_auto_tile = False
    c.use_camera_cull = False
    c.use_distance_cull = False
    c.film_exposure = 1.0
    c.use_fast_gi = False


def to_lambert():
    """Replaces every non-metallic Principled BSDF by a Lambert Diffuse BSDF of its base colour
    (plus its emission), as ../shared/tools/cycles_render.py --lambert does; metals are kept."""
    for mat in bpy.data.materials:
        if not mat.use_nodes:
            continue
        nt = mat.node_tree
        for node in list(nt.nodes):
            if node.type != "BSDF_PRINCIPLED" or node.inputs["Metallic"].default_value > 0:
                continue
            diff = nt.nodes.new("ShaderNodeBsdfDiffuse")
            diff.inputs["Roughness"].default_value = 0.0
            base = node.inputs["Base Color"]
            if base.is_linked:
                nt.links.new(base.links[0].from_socket, diff.inputs["Color"])
            else:
                diff.inputs["Color"].default_value = base.default_value
            emis = nt.nodes.new("ShaderNodeEmission")
            emis.inputs["Color"].default_value = node.inputs["Emission"].default_value
            emis.inputs["Strength"].default_value = node.inputs["Emission Strength"].default_value
            add = nt.nodes.new("ShaderNodeAddShader")
            nt.links.new(diff.outputs[0], add.inputs[0])
            nt.links.new(emis.outputs[0], add.inputs[1])
            for lk in list(node.outputs["BSDF"].links):
                nt.links.new(add.outputs[0], lk.to_socket)
            nt.nodes.remove(node)


def render_preview(png_path, width, height, spp=32, max_depth=8):
    """A quick Cycles PNG (Standard view transform, sRGB) of the scene as built, to look at."""
    cycles_settings(width, height, spp, max_depth)
    settings = bpy.context.scene.render.image_settings
    settings.file_format, settings.color_mode, settings.color_depth = "PNG", "RGB", "8"
    bpy.context.scene.render.filepath = os.path.abspath(png_path)
    bpy.ops.render.render(write_still=True)


def _render_pixels(path):
    """Renders the scene to path (EXR); returns rows top to bottom of (r, g, b) as a numpy array."""
    import numpy as np
    scene = bpy.context.scene
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.array(img.pixels[:], dtype=np.float64).reshape(h, w, 4)[::-1, :, :3]
    bpy.data.images.remove(img)
    return px


def render_reference(json_path, width, height, spp, seeds, max_depth, threads=2, note="", exr_path=None):
    """Renders `seeds` Cycles images of spp/seeds samples and writes the statistics JSON."""
    import time
    import numpy as np
    per = max(1, spp // seeds)
    images, means = [], []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(seeds):
            cycles_settings(width, height, per, max_depth, threads, seed=k + 1)
            px = _render_pixels(os.path.join(tmp, "ref%d.exr" % k))
            images.append(px)
            means.append(px.reshape(-1, 3).mean(axis=0))
    seconds = time.perf_counter() - t0
    img = np.mean(images, axis=0)
    means = np.array(means)
    mean = img.reshape(-1, 3).mean(axis=0)
    se = means.std(axis=0, ddof=1) / math.sqrt(seeds) if seeds > 1 else np.zeros(3)
    blocks, blocks_se = [], []
    for by in range(0, height - BLOCK + 1, BLOCK):
        row, row_se = [], []
        for bx in range(0, width - BLOCK + 1, BLOCK):
            row.append([round(float(v), 7) for v in img[by:by + BLOCK, bx:bx + BLOCK].reshape(-1, 3).mean(axis=0)])
            seed_blocks = np.array([im[by:by + BLOCK, bx:bx + BLOCK].reshape(-1, 3).mean(axis=0) for im in images])
            bse = seed_blocks.std(axis=0, ddof=1) / math.sqrt(seeds) if seeds > 1 else np.zeros(3)
            row_se.append([round(float(v), 7) for v in bse])
        blocks.append(row)
        blocks_se.append(row_se)
    if exr_path:
        save_exr("reference", width, height, img.tolist(), exr_path)
    out = {
        "renderer": "Cycles %s" % bpy.app.version_string,
        "note": note,
        "width": width, "height": height, "spp": per * seeds, "seeds": seeds, "spp_per_seed": per,
        "max_depth": max_depth, "cycles_max_bounces": max(0, max_depth - 1),
        "filter": "box 1 px", "view_transform": "Standard", "denoise": False, "clamp": False,
        "render_seconds": round(seconds, 2), "threads": threads,
        "mean": [round(float(v), 7) for v in mean],
        "mean_se": [round(float(v), 7) for v in se],
        "seed_means": [[round(float(v), 7) for v in m] for m in means],
        "block": BLOCK, "blocks": blocks, "blocks_se": blocks_se,
    }
    with open(json_path, "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")
    print("reference %s: mean %s +- %s (%d seeds x %d spp, %.1f s)" % (json_path, out["mean"], out["mean_se"],
                                                                   seeds, per, seconds))
    return out
