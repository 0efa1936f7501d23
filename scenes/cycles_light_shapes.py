"""Cycles 3.4's light-shape conventions, measured (README "Light shapes"). Manual; never in CI.

Run (Blender 3.4, Debian bookworm's `blender` package):
  blender -b --factory-startup -noaudio --python scenes/cycles_light_shapes.py -- [--spp 256] [--out DIR]

Builds, in Blender's own axes (Z up), the scenes tests/scenes/{rect,disk,sphere,sun}_plane.gltf
describe (a Lambert 0.5 plane, an orthographic camera looking down over [-1, 1]^2, direct light
only) with Blender lights, renders them with Cycles (32x32, CPU, no denoising, adaptive sampling
off, light threshold 0) and prints one line per case: Cycles' image mean and what Candela
computes for the same light (the closed forms of tests/test_shapes.c, image means at 32x32):

  rect   1 m square, 1 m up, power 2 pi W     Cycles L = P / (4 A): Candela 0.129413 x pi/4
  disk   1 m diameter, 1 m up, 2 pi pi/4 W    the same convention:  Candela 0.103396 x pi/4
  sphere radius 0.5, 4 m up, I = 32 pi W/sr   Candela's sphere 0.941720 (Cycles 3.4: a disk facing
                                              the shading point, E = I cos / (d^2 + r^2))
  sun    20 degrees, 30 degrees off the normal, 2 pi W/m^2
                                              Candela 0.866025; --light-model blender3 0.859397
  seen   a 4 m square light above a camera looking up: Cycles' camera rays do not see lights
         (visible_camera is off by default in 3.4), image mean 0.

Measured with Blender 3.4.1 at 256 spp: rect 0.101666, disk 0.081219, sphere 0.927829 (centre
pixel 0.98445; the disk model's 16 / 16.25 = 0.98462), sun 0.859383, seen 0.
"""
import argparse
import math
import os
import sys

import bpy
import numpy as np

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
ap = argparse.ArgumentParser(prog="cycles_light_shapes.py")
ap.add_argument("--spp", type=int, default=256)
ap.add_argument("--out", default="/tmp/cycles_light_shapes")
args = ap.parse_args(argv)
os.makedirs(args.out, exist_ok=True)


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = 'CYCLES'
    sc.cycles.device = 'CPU'
    sc.cycles.samples = args.spp
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = False
    sc.cycles.max_bounces = 0
    sc.cycles.light_sampling_threshold = 0.0
    sc.cycles.filter_width = 0.01
    sc.render.resolution_x = sc.render.resolution_y = 32
    sc.render.threads_mode = 'FIXED'
    sc.render.threads = 2
    sc.view_settings.view_transform = 'Standard'
    sc.render.image_settings.file_format = 'OPEN_EXR'
    sc.render.image_settings.color_depth = '32'
    return sc


def plane():
    bpy.ops.mesh.primitive_plane_add(size=100)
    m = bpy.data.materials.new('lambert_half')
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    d = nt.nodes.new('ShaderNodeBsdfDiffuse')
    d.inputs['Color'].default_value = (0.5, 0.5, 0.5, 1.0)
    o = nt.nodes.new('ShaderNodeOutputMaterial')
    nt.links.new(d.outputs[0], o.inputs[0])
    bpy.context.object.data.materials.append(m)


def camera(sc, z, up=False):
    bpy.ops.object.camera_add(location=(0, 0, z), rotation=(math.pi if up else 0.0, 0, 0))
    c = bpy.context.object
    c.data.type = 'ORTHO'
    c.data.ortho_scale = 2.0
    sc.camera = c


def light(kind, location, rotation=(0, 0, 0), **props):
    bpy.ops.object.light_add(type=kind, location=location, rotation=rotation)
    lt = bpy.context.object
    for k, v in props.items():
        setattr(lt.data, k, v)
    return lt


def render(sc, name, candela):
    sc.render.filepath = os.path.join(args.out, name + '.exr')
    bpy.ops.render.render(write_still=True)
    px = np.array(bpy.data.images.load(sc.render.filepath).pixels[:]).reshape(-1, 4)
    print('LIGHT_SHAPES %-7s Cycles mean %.6f max %.6f   Candela %s' % (name, px[:, 0].mean(), px[:, 0].max(), candela))


sc = reset(); plane(); camera(sc, 0.5)
light('AREA', (0, 0, 1), shape='SQUARE', size=1.0, energy=2 * math.pi)
render(sc, 'rect', '%.6f (power / (4 A)); %.6f with power / (pi A)' % (0.129413 * math.pi / 4, 0.129413))
sc = reset(); plane(); camera(sc, 0.5)
light('AREA', (0, 0, 1), shape='DISK', size=1.0, energy=2 * math.pi * math.pi / 4)
render(sc, 'disk', '%.6f' % (0.103396 * math.pi / 4))
sc = reset(); plane(); camera(sc, 3.0)
light('POINT', (0, 0, 4), shadow_soft_size=0.5, energy=4 * math.pi * 32 * math.pi)
render(sc, 'sphere', '0.941720 (a sphere)')
sc = reset(); plane(); camera(sc, 3.0)
light('SUN', (0, 0, 10), (math.radians(30), 0, 0), angle=math.radians(20), energy=2 * math.pi)
render(sc, 'sun', '0.866025; 0.859397 with --light-model blender3')
sc = reset(); camera(sc, 0.0, up=True)
light('AREA', (0, 0, 1), shape='SQUARE', size=4.0, energy=32 * math.pi)
render(sc, 'seen', '0 (camera rays skip light shapes)')
