#!/usr/bin/env python3
"""scenes/material_probes.py: Candela's two material models against Blender 3.4's Cycles on small
glTF probes (issue 14, "Materials render darker"). Manual: needs Blender 3.4 (`blender`,
Debian bookworm's package) and oiiotool; never run in CI.

Each probe is a glTF written here (make_scenes.Gltf), lit by one sun (KHR_lights_punctual
directional, RAW units: Candela --light-units raw = the importer's COMPAT mode), black world:
  plastic       a red plastic sphere (base 0.8 0.25 0.2, roughness 0.4) on a grey plastic floor
                (base 0.5, roughness 0.5), sun 40 degrees up, camera 25 degrees down
  glossy_floor  a grey glossy floor (base 0.5, roughness 0.25) seen at grazing view (camera 0.35 m
                up, looking 8 degrees down), sun 20 degrees up, in front of the camera
  metal         a gold sphere (base 1 0.78 0.34, metallic 1, roughness 0.3) on the grey floor
  coat          a blue plastic sphere with KHR_materials_clearcoat 1 (coat roughness 0.05)
                on the grey floor
  glass         a rough glass sphere (KHR_materials_transmission 1, ior 1.5, roughness 0.2,
                base 0.9 0.95 1) on the grey floor
For each: Cycles renders the glTF as Blender 3.4's glTF importer sets it up
(../shared/tools/cycles_render.py: importer, box filter, no denoising/clamping, --max-depth
bounces), Candela renders it with --material-model gltf and blender3 (--max-depth the same),
and the image means (RGB average) are printed with their ratios to Cycles'.

Usage: python3 scenes/material_probes.py [--out DIR] [--res 160x120] [--spp 256]
           [--candela build/renderer/candela] [--cycles-tool ../shared/tools/cycles_render.py]
           [--probes plastic,glossy_floor,metal,coat,glass]
"""
import argparse
import json
import math
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_scenes import Gltf, quad, look_rotation, uv_sphere  # noqa: E402
from image_error import oiio_mean  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
FLOOR = quad((-20.0, 0.0, -20.0), (-20.0, 0.0, 20.0), (20.0, 0.0, 20.0), (20.0, 0.0, -20.0))  # faces +y


def sun(g, elevation_deg, azimuth_deg, irradiance=3.0):
    """A sun whose light travels towards the scene from elevation/azimuth (azimuth 0: from +z)."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    towards_sun = (math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az))
    travel = tuple(-c for c in towards_sun)
    g.light('sun', 'directional', irradiance, translation=(0.0, 10.0, 0.0), rotation=look_rotation(travel))


def probe(name):
    g = Gltf(generator='candela scenes/material_probes.py')
    floor = g.material('grey_plastic', base=(0.5, 0.5, 0.5), roughness=0.5)
    if name == 'glossy_floor':
        glossy = g.material('glossy_floor', base=(0.5, 0.5, 0.5), roughness=0.25)
        g.mesh('floor', 'floor', FLOOR, glossy)
        sun(g, 20.0, 180.0)  # in front of the camera (which looks towards -z)
        g.perspective('camera', (0.0, 0.35, 4.0), (0.0, 0.35 - 4.0 * math.tan(math.radians(8.0)), 0.0), 40.0,
                      aspect=4.0 / 3.0)
        return g
    g.mesh('floor', 'floor', FLOOR, floor)
    if name == 'plastic':
        m = g.material('red_plastic', base=(0.8, 0.25, 0.2), roughness=0.4)
    elif name == 'metal':
        m = g.material('gold', base=(1.0, 0.78, 0.34), metallic=1.0, roughness=0.3)
    elif name == 'coat':
        m = g.material('coated_blue', base=(0.1, 0.2, 0.6), roughness=0.5)
        g.use('KHR_materials_clearcoat')
        g.doc['materials'][m]['extensions'] = {'KHR_materials_clearcoat': {'clearcoatFactor': 1.0,
                                                                           'clearcoatRoughnessFactor': 0.05}}
    elif name == 'glass':
        m = g.material('rough_glass', base=(0.9, 0.95, 1.0), roughness=0.2, transmission=1.0, ior=1.5)
    else:
        sys.exit('unknown probe %s' % name)
    g.mesh('sphere', 'sphere', uv_sphere(1.0, 64, 32), m, translation=(0.0, 1.0, 0.0))
    sun(g, 40.0, 30.0)
    g.perspective('camera', (0.0, 2.0 + 0.0, 5.5), (0.0, 0.8, 0.0), 40.0, aspect=4.0 / 3.0)
    return g


def block_means(exr, blocks_x, blocks_y, tmp):
    """Mean RGB of each block of the image (oiiotool's box resize, read back with --dumpdata)."""
    small = tmp + '.exr'
    subprocess.run(['oiiotool', exr, '--ch', 'R,G,B', '--resize:filter=box', '%dx%d' % (blocks_x, blocks_y),
                    '-o', small], check=True)
    out = subprocess.run(['oiiotool', '--dumpdata', small], check=True, capture_output=True, text=True).stdout
    os.remove(small)
    vals = [[float(v) for v in line.split(':')[1].split()] for line in out.splitlines() if 'Pixel (' in line]
    return [sum(v) / len(v) for v in vals]


def block_ratios(test, ref, blocks_x, blocks_y, tmp):
    """Candela / Cycles per block, over the blocks whose Cycles mean is above 2% of the image's."""
    a, b = block_means(test, blocks_x, blocks_y, tmp + 'a'), block_means(ref, blocks_x, blocks_y, tmp + 'b')
    cut = 0.02 * sum(b) / len(b)
    return [x / y for x, y in zip(a, b) if y > cut]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--out', default='/tmp/material_probes')
    ap.add_argument('--res', default='160x120')
    ap.add_argument('--spp', type=int, default=256)
    ap.add_argument('--max-depth', type=int, default=8)
    ap.add_argument('--candela', default=os.path.join(ROOT, 'build', 'renderer', 'candela'))
    ap.add_argument('--cycles-tool', default=os.path.join(ROOT, '..', 'shared', 'tools', 'cycles_render.py'))
    ap.add_argument('--blender', default='blender')
    ap.add_argument('--probes', default='plastic,glossy_floor,metal,coat,glass')
    ap.add_argument('--threads', type=int, default=2)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    w, h = (int(x) for x in a.res.split('x'))
    rows = []
    for name in a.probes.split(','):
        gltf = os.path.join(a.out, name + '.gltf')
        probe(name).write(gltf)
        means = {}
        for model in ('gltf', 'blender3'):
            exr = os.path.join(a.out, '%s.%s.exr' % (name, model))
            subprocess.run([a.candela, 'render', gltf, '--res', a.res, '--spp', str(a.spp), '--max-depth',
                            str(a.max_depth), '--light-units', 'raw', '--material-model', model, '--threads',
                            str(a.threads), '--quiet', '-o', exr], check=True)
            means[model] = oiio_mean([exr, '--ch', 'R,G,B'])
        exr = os.path.join(a.out, '%s.cycles.exr' % name)
        if not os.path.exists(exr):
            # Blender's bundled Python must not see a pyenv / virtualenv interpreter's paths (it
            # then misses the system numpy its glTF importer needs)
            env = {k: v for k, v in os.environ.items() if not k.startswith(('PYENV', 'PYTHON', 'VIRTUAL_ENV'))}
            env['PATH'] = '/usr/local/bin:/usr/bin:/bin'
            subprocess.run([a.blender, '-b', '--factory-startup', '-noaudio', '--python', a.cycles_tool, '--',
                            '--input', gltf, '--output', exr, '--width', str(w), '--height', str(h), '--spp',
                            str(a.spp), '--max-depth', str(a.max_depth), '--threads', str(a.threads),
                            '--lighting-mode', 'COMPAT'], check=True, capture_output=True, env=env)
            if not os.path.exists(exr):
                sys.exit('Cycles wrote no %s (run the blender command by hand to see why)' % exr)
        means['cycles'] = oiio_mean([exr, '--ch', 'R,G,B'])
        row = {'probe': name, 'cycles': means['cycles'], 'gltf': means['gltf'], 'blender3': means['blender3'],
               'gltf/cycles': means['gltf'] / means['cycles'], 'blender3/cycles': means['blender3'] / means['cycles']}
        # 8x8-pixel blocks (the lit ones): the worst ratios to Cycles
        for model in ('gltf', 'blender3'):
            r = block_ratios(os.path.join(a.out, '%s.%s.exr' % (name, model)), exr, w // 8, h // 8,
                             os.path.join(a.out, 'blocks'))
            row[model + '_blocks'] = [min(r), max(r)]
        rows.append(row)
        print('%-13s cycles %.5f  gltf %.5f (%.4fx, 8x8 blocks %.3f..%.3f)  blender3 %.5f (%.4fx, blocks %.3f..%.3f)' % (
            name, means['cycles'], means['gltf'], row['gltf/cycles'], row['gltf_blocks'][0], row['gltf_blocks'][1],
            means['blender3'], row['blender3/cycles'], row['blender3_blocks'][0], row['blender3_blocks'][1]), flush=True)
    print('MATERIAL_PROBES ' + json.dumps(rows))


if __name__ == '__main__':
    main()
