#!/usr/bin/env python3
"""scenes/make_manylights.py: the many-lights scenes of the cache-points work (issue 3).

Python 3 standard library only; deterministic (fixed seeds, Mersenne Twister), so running it
twice writes byte-identical files. The files are large (the 1M-light city is ~90 MB of JSON),
so they are generated on demand into a build folder (default build/scenes/, git-ignored)
rather than committed. Blender light units (cd, lux; the renderer divides by 683).

  city.gltf            night city block: 8x8 blocks of buildings, 100,000 lights (window
                       lights on facades + street lights), occluded from most points; the
                       scale series keeps the total power of city_1k
  city_1k/_10k/_100k/_1m.gltf   the same layout with 1k ... 1M lights (the scale series)
  windows.gltf         four closed rooms in a row, each with a small window facing a low sun
                       and 120 ceiling lights; the camera is in room 0, so the other rooms'
                       360 lights are occluded (the paper's occlusion case)
  emissive_mesh.gltf   an emissive mesh of 102,400 triangles among 64 point lights
  spotlights.gltf      96 narrow spot lights (1 to 8 degree cones) over a large floor
  street.gltf          the night street of issue 12: the city with 20,000 lights (18,000 on
                       facades, 2,000 street lights), seen from its street camera
  street_1m.gltf       issue 28's production-scale street: city_1m written as Blender's exporter
                       writes light objects (every node and light definition named, one light
                       definition per light), 211 MB; street_100k and street_20k (tests/test_phases.sh)
                       the same at 100,000 and 20,000 lights
  glossy.gltf          a wet night plaza (issue 12, BSDF-aware selection): 4x4 blocks, a glossy
                       wet floor (roughness 0.15), polished metal facades (roughness 0.3) on half
                       the buildings, diffuse concrete on the rest; 4,000 window and street lights

usage: make_manylights.py [OUT_DIR] [--only NAME ...]
"""

import json
import math
import os
import random
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_scenes import (Gltf, ROOT, box, quad, quat_axis_angle, look_rotation, sub,  # noqa: E402
                         uv_sphere, r, rv)
import base64  # noqa: E402


def light_node(g, light_index, translation, rotation=None):
    """A node placing an existing light definition (lights are shared between nodes, which
    keeps a 1M-light file to one small JSON object per light)."""
    n = {'translation': rv(translation)}
    if rotation is not None:
        n['rotation'] = rv(rotation, 8)
    n['extensions'] = {'KHR_lights_punctual': {'light': light_index}}
    g.doc['nodes'].append(n)
    g.doc['scenes'][0]['nodes'].append(len(g.doc['nodes']) - 1)


def light_def(g, kind, intensity, color, inner=None, outer=None):
    g.use('KHR_lights_punctual')
    lt = {'type': kind, 'color': rv(color), 'intensity': r(intensity)}
    if kind == 'spot':
        lt['spot'] = {'innerConeAngle': r(inner), 'outerConeAngle': r(outer)}
    g.lights.append(lt)
    return len(g.lights) - 1


def write_compact(g, path):
    doc = dict(g.doc)
    if not doc['extensionsUsed']:
        del doc['extensionsUsed']
    if g.lights:
        doc['extensions'] = {'KHR_lights_punctual': {'lights': g.lights}}
    if g.cameras:
        doc['cameras'] = g.cameras
    doc['buffers'] = [{'byteLength': len(g.buf),
                       'uri': 'data:application/octet-stream;base64,' + base64.b64encode(bytes(g.buf)).decode('ascii')}]
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = path + '.tmp'
    with open(tmp, 'w', newline='\n') as fh:
        json.dump(doc, fh, separators=(',', ':'))
        fh.write('\n')
    os.replace(tmp, path)
    n_lights = sum(1 for n in doc['nodes'] if 'extensions' in n)
    print('wrote %s (%d light nodes, %d bytes)' % (path, n_lights, os.path.getsize(path)))


# ----------------------------------------------------------------------------------------------


def city(out, name, n_lights, seed=1, per_light=False):
    """8x8 blocks of 16 m with 8 m streets (a 184 m square); one building per block, 12-60 m
    tall. 90% of the lights are window lights 0.25 m in front of a facade (warm or cool, 80-800
    cd at 1,000 lights), 10% street lights at 6 m (6000 cd at 1,000 lights). Intensities scale
    with 1000 / n_lights, so every member of the scale series has the same total power and
    the same exposure. The camera stands in a street at 1.7 m.

    per_light: written as Blender's glTF exporter writes a scene of light objects, every node
    named and with its own named light definition (issue 28's street: about 232 bytes of JSON
    per light instead of 102); the same lights at the same places."""
    rng = random.Random(seed)
    g = Gltf('candela scenes/make_manylights.py')
    ground = g.material('asphalt', base=(0.08, 0.08, 0.09), roughness=0.8)
    concrete = g.material('concrete', base=(0.45, 0.43, 0.4), lambert=True)
    B, S, N = 16.0, 8.0, 8
    span = N * B + (N + 1) * S
    h = span / 2.0
    g.mesh('ground', 'ground', quad((-h, 0, -h), (-h, 0, h), (h, 0, h), (h, 0, -h)), ground)
    buildings = []
    for i in range(N):
        for j in range(N):
            x0 = -h + S + i * (B + S)
            z0 = -h + S + j * (B + S)
            height = 12.0 + 48.0 * rng.random()
            buildings.append((x0, z0, height))
            g.mesh('building_%d_%d' % (i, j), 'unit_box', box(1.0, 1.0, 1.0), concrete)
            node = g.doc['nodes'][-1]
            node['translation'] = rv((x0 + B / 2, height / 2, z0 + B / 2))
            node['scale'] = rv((B, height, B))
    # shared light definitions
    scale = 1000.0 / n_lights
    warm = [light_def(g, 'point', scale * (80.0 + 720.0 * k / 7.0), (1.0, 0.75, 0.45)) for k in range(8)]
    cool = [light_def(g, 'point', scale * (80.0 + 720.0 * k / 7.0), (0.7, 0.8, 1.0)) for k in range(8)]
    street = light_def(g, 'point', scale * 6000.0, (1.0, 0.85, 0.6))
    n_street = max(1, n_lights // 10)
    n_window = n_lights - n_street
    shared = len(g.lights)

    def place(light, p):
        if not per_light:
            light_node(g, light, p)
            return
        k = len(g.lights) - shared
        own = dict(g.lights[light], name='Lamp.%07d' % k)
        g.lights.append(own)
        light_node(g, len(g.lights) - 1, p)
        g.doc['nodes'][-1] = dict(name='Lamp.%07d' % k, **g.doc['nodes'][-1])

    for _ in range(n_window):
        x0, z0, height = buildings[rng.randrange(len(buildings))]
        face = rng.randrange(4)
        t = rng.random() * B
        y = 1.5 + rng.random() * (height - 2.0)
        off = 0.25
        if face == 0:
            p = (x0 + t, y, z0 - off)
        elif face == 1:
            p = (x0 + t, y, z0 + B + off)
        elif face == 2:
            p = (x0 - off, y, z0 + t)
        else:
            p = (x0 + B + off, y, z0 + t)
        pal = warm if rng.random() < 0.7 else cool
        place(pal[rng.randrange(8)], p)
    for k in range(n_street):
        # along the streets between blocks, both directions
        street_i = rng.randrange(N + 1)
        along = -h + rng.random() * span
        across = -h + S / 2 + street_i * (B + S) + (rng.random() - 0.5) * S * 0.8
        p = (across, 6.0, along) if k % 2 == 0 else (along, 6.0, across)
        place(street, p)
    street_x = -h + S / 2 + 4 * (B + S)
    g.perspective('street', (street_x, 1.7, h - 10.0), (street_x + 6.0, 12.0, -h / 2), 60.0, aspect=16 / 9)
    write_compact(g, os.path.join(out, name + '.gltf'))


def windows(out, seed=2):
    """Four 6 x 3 x 6 m rooms in a row along x, closed except a 1.2 x 1.2 m window in each
    front (+z) wall; a sun at 35 degrees elevation from +z shines through the windows; each
    room has a 10 x 12 grid of small ceiling lights (20 cd). The camera is in room 0."""
    rng = random.Random(seed)
    g = Gltf('candela scenes/make_manylights.py')
    wall = g.material('plaster', base=(0.75, 0.73, 0.7), lambert=True)
    floor = g.material('wood', base=(0.45, 0.3, 0.18), roughness=0.6)
    W, H, D = 6.0, 3.0, 6.0
    wx0, wx1, wy0, wy1 = 2.4, 3.6, 1.0, 2.2   # window opening in room coordinates
    ceiling_light = light_def(g, 'point', 20.0, (1.0, 0.9, 0.8))
    for k in range(4):
        x = k * (W + 0.2)
        def room_quad(name, a, b, c, d, m):
            g.mesh(name, name, quad(*(tuple(v[i] + (x if i == 0 else 0.0) for i in range(3)) for v in (a, b, c, d))), m)
        room_quad('floor_%d' % k, (0, 0, 0), (0, 0, D), (W, 0, D), (W, 0, 0), floor)
        room_quad('ceiling_%d' % k, (0, H, 0), (W, H, 0), (W, H, D), (0, H, D), wall)
        room_quad('back_%d' % k, (0, 0, 0), (W, 0, 0), (W, H, 0), (0, H, 0), wall)
        room_quad('left_%d' % k, (0, 0, 0), (0, H, 0), (0, H, D), (0, 0, D), wall)
        room_quad('right_%d' % k, (W, 0, 0), (W, 0, D), (W, H, D), (W, H, 0), wall)
        # front wall (z = D, facing -z into the room) around the window opening
        for (a0, a1, b0, b1, tag) in ((0, W, 0, wy0, 'below'), (0, W, wy1, H, 'above'),
                                     (0, wx0, wy0, wy1, 'left'), (wx1, W, wy0, wy1, 'right')):
            room_quad('front_%s_%d' % (tag, k), (a0, b0, D), (a0, b1, D), (a1, b1, D), (a1, b0, D), wall)
        for i in range(10):
            for j in range(12):
                jitter = 0.05 * (rng.random() - 0.5)
                light_node(g, ceiling_light, (x + 0.3 + 0.6 * i + jitter, H - 0.05, 0.25 + 0.5 * j))
    g.use('KHR_lights_punctual')
    g.lights.append({'type': 'directional', 'color': [1.0, 0.95, 0.85], 'intensity': 200000.0})
    sun_dir = (0.25, -math.sin(math.radians(35)), -math.cos(math.radians(35)))
    light_node(g, len(g.lights) - 1, (0.0, 10.0, 10.0), look_rotation(sun_dir))
    g.perspective('room0', (1.0, 1.6, 0.6), (3.5, 0.8, 4.5), 70.0, aspect=16 / 9)
    write_compact(g, os.path.join(out, 'windows.gltf'))


def emissive_mesh(out, seed=3):
    """A 102,400-triangle emissive sphere (radius 1.5, radiance 2) on a floor, surrounded by
    64 point lights (100 cd) on a ring."""
    rng = random.Random(seed)
    g = Gltf('candela scenes/make_manylights.py')
    floor = g.material('floor', base=(0.6, 0.6, 0.6), lambert=True)
    glow = g.material('glow', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 0.6, 0.3), strength=2.0)
    g.mesh('floor', 'floor', quad((-30, 0, -30), (-30, 0, 30), (30, 0, 30), (30, 0, -30)), floor)
    g.mesh('glow', 'glow', uv_sphere(1.5, segments=320, rings=160), glow, translation=(0.0, 1.6, 0.0))
    pt = light_def(g, 'point', 100.0, (0.8, 0.9, 1.0))
    for k in range(64):
        a = 2 * math.pi * k / 64
        rad = 6.0 + 2.0 * rng.random()
        light_node(g, pt, (rad * math.cos(a), 0.5 + 3.0 * rng.random(), rad * math.sin(a)))
    g.perspective('view', (0.0, 5.0, 12.0), (0.0, 1.0, 0.0), 50.0, aspect=16 / 9)
    write_compact(g, os.path.join(out, 'emissive_mesh.gltf'))


def spotlights(out, seed=4):
    """96 spot lights 20 m above a 200 x 200 m floor, cones of 1 to 8 degrees (outer half
    angle), pointing straight down at random spots; 20000-200000 cd."""
    rng = random.Random(seed)
    g = Gltf('candela scenes/make_manylights.py')
    floor = g.material('floor', base=(0.7, 0.7, 0.7), lambert=True)
    g.mesh('floor', 'floor', quad((-100, 0, -100), (-100, 0, 100), (100, 0, 100), (100, 0, -100)), floor)
    down = look_rotation((0.0, -1.0, 0.0), up_hint=(0.0, 0.0, -1.0))
    for k in range(96):
        outer = math.radians(1.0 + 7.0 * rng.random())
        li = light_def(g, 'spot', 20000.0 + 180000.0 * rng.random(),
                       (0.8 + 0.2 * rng.random(), 0.8 + 0.2 * rng.random(), 0.8 + 0.2 * rng.random()),
                       inner=0.7 * outer, outer=outer)
        light_node(g, li, (-40 + 80 * rng.random(), 20.0, -40 + 80 * rng.random()), down)
    g.perspective('view', (0.0, 35.0, 60.0), (0.0, 0.0, 0.0), 55.0, aspect=16 / 9)
    write_compact(g, os.path.join(out, 'spotlights.gltf'))


def glossy(out, seed=5):
    """4x4 blocks of 12 m with 10 m streets; buildings 8-30 m tall, alternately polished metal
    (metallic 1, roughness 0.3) and concrete (diffuse); the floor is wet stone (dark dielectric,
    roughness 0.15, whose Fresnel reflection dominates at the camera's grazing view). 3,600
    window lights 0.25 m in front of the facades (40-400 cd, warm or cool) and 400 street lights
    at 5 m (1500 cd). The camera stands in a street at 1.7 m, looking along it."""
    rng = random.Random(seed)
    g = Gltf('candela scenes/make_manylights.py')
    wet = g.material('wet_stone', base=(0.05, 0.05, 0.055), roughness=0.15)
    metal = g.material('polished_metal', base=(0.85, 0.85, 0.88), metallic=1.0, roughness=0.3)
    concrete = g.material('concrete', base=(0.45, 0.43, 0.4), lambert=True)
    B, S, N = 12.0, 10.0, 4
    span = N * B + (N + 1) * S
    h = span / 2.0
    g.mesh('ground', 'ground', quad((-h, 0, -h), (-h, 0, h), (h, 0, h), (h, 0, -h)), wet)
    buildings = []
    for i in range(N):
        for j in range(N):
            x0 = -h + S + i * (B + S)
            z0 = -h + S + j * (B + S)
            height = 8.0 + 22.0 * rng.random()
            buildings.append((x0, z0, height))
            mat = metal if (i + j) % 2 == 0 else concrete
            g.mesh('building_%d_%d' % (i, j), 'unit_box_%d' % mat, box(1.0, 1.0, 1.0), mat)
            node = g.doc['nodes'][-1]
            node['translation'] = rv((x0 + B / 2, height / 2, z0 + B / 2))
            node['scale'] = rv((B, height, B))
    warm = [light_def(g, 'point', 40.0 + 360.0 * k / 7.0, (1.0, 0.75, 0.45)) for k in range(8)]
    cool = [light_def(g, 'point', 40.0 + 360.0 * k / 7.0, (0.7, 0.8, 1.0)) for k in range(8)]
    street = light_def(g, 'point', 1500.0, (1.0, 0.85, 0.6))
    for _ in range(3600):
        x0, z0, height = buildings[rng.randrange(len(buildings))]
        face = rng.randrange(4)
        t = rng.random() * B
        y = 1.0 + rng.random() * (height - 1.5)
        off = 0.25
        if face == 0:
            p = (x0 + t, y, z0 - off)
        elif face == 1:
            p = (x0 + t, y, z0 + B + off)
        elif face == 2:
            p = (x0 - off, y, z0 + t)
        else:
            p = (x0 + B + off, y, z0 + t)
        pal = warm if rng.random() < 0.7 else cool
        light_node(g, pal[rng.randrange(8)], p)
    for k in range(400):
        street_i = rng.randrange(N + 1)
        along = -h + rng.random() * span
        across = -h + S / 2 + street_i * (B + S) + (rng.random() - 0.5) * S * 0.8
        p = (across, 5.0, along) if k % 2 == 0 else (along, 5.0, across)
        light_node(g, street, p)
    street_x = -h + S / 2 + 2 * (B + S)
    g.perspective('street', (street_x, 1.7, h - 4.0), (street_x + 2.0, 3.0, -h / 2), 60.0, aspect=16 / 9)
    write_compact(g, os.path.join(out, 'glossy.gltf'))


def main():
    args = sys.argv[1:]
    out = os.path.join(ROOT, 'build', 'scenes')
    only = None
    if args and not args[0].startswith('--'):
        out = args.pop(0)
    if args and args[0] == '--only':
        only = set(args[1:])
    jobs = [
        ('city', lambda: city(out, 'city', 100000)),
        ('windows', lambda: windows(out)),
        ('emissive_mesh', lambda: emissive_mesh(out)),
        ('spotlights', lambda: spotlights(out)),
        ('street', lambda: city(out, 'street', 20000)),
        ('glossy', lambda: glossy(out)),
        ('city_1k', lambda: city(out, 'city_1k', 1000)),
        ('city_10k', lambda: city(out, 'city_10k', 10000)),
        ('city_100k', lambda: city(out, 'city_100k', 100000)),
        ('city_1m', lambda: city(out, 'city_1m', 1000000)),
        ('street_1m', lambda: city(out, 'street_1m', 1000000, per_light=True)),
        ('street_100k', lambda: city(out, 'street_100k', 100000, per_light=True)),
        ('street_20k', lambda: city(out, 'street_20k', 20000, per_light=True)),
    ]
    for name, job in jobs:
        if only is None or name in only:
            job()


if __name__ == '__main__':
    main()
