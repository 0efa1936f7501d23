#!/usr/bin/env python3
"""scenes/cycles_volume_compare.py: Candela against Blender's Cycles on a VDB volume.

MANUAL VALIDATION ONLY. It needs Blender (Debian 12: `apt-get install blender python3-numpy
python3-openimageio`) installed on the machine where it runs; it is never run in CI and the
test suite does not depend on it (CI must not install Blender).

usage: python3 scenes/cycles_volume_compare.py [options]        (--help for all options)

What it does:
  1. writes OUT/volume_compare.gltf: a perspective camera, one KHR_lights_punctual point light
     and no meshes; one node carries the extras
     "candela_volume": {"uri": VDB, "density_scale": S, "albedo": [a, a, a], "anisotropy": g}
     (the VDB path is absolute), translated by --translate (glTF coordinates, Y-up);
  2. renders it with Candela (`--light-units blender`, --max-depth 8 surface bounces,
     --max-volume-bounces = --bounces) and with Cycles through the shared tool
     ../shared/tools/cycles_render.py (--lighting-mode SPEC: the importer's default, which is
     what Candela's `blender` units follow; the same VDB added with --vdb, --vdb-translate = the
     node translation: the tool maps glTF to Blender axes itself; --max-depth = --bounces, all
     bounce kinds), same resolution, box 1-pixel filter on both, black world (--world S: a
     constant sky of radiance S in both, through scenes/cycles_world.py on the Cycles side);
     Cycles once per --step-rates value (Cycles 3.4 ray-marches heterogeneous volumes, so its
     answer depends on the step: step = voxel size x step rate, but at most
     volume_max_steps = 1024 steps per ray segment, which the tool leaves at Blender's default:
     below a step rate of ~0.1 for this 1 m, 96^3 cloud the step is capped by the segment length /
     1024, not by the rate), and --cycles-seeds times per step rate with different seeds;
  3. prints the RGB image means, the ratio Candela / Cycles, Candela's standard error of the
     image mean (sqrt(sum of the per-pixel `variance.*` layers) / pixels: those layers are the
     variance of each pixel's mean), Cycles' standard error from the spread of its per-seed
     means (only with --cycles-seeds >= 2), the mean of each image quadrant (placement check)
     and the time per sample of each renderer (Candela: the render stages of --stats-json,
     without load and setup; Cycles: the tool's per_sample_s, Cycles' own render_time without
     sync, with the 1-spp render subtracted);
  4. writes PNGs with a common exposure: candela.png, cycles_sr<rate>.png, side-by-side
     compare.png (Candela | Cycles at the finest step | |difference| x 4) for looking at them.

Voxel-centre convention: Candela (like OpenVDB) puts voxel centres at integer index coordinates;
Blender 3.4's Cycles renders the same VDB shifted by about +half a voxel on each axis (measured
with this script: the silhouettes differ by ~0.5 px in x and y, and the image means by ~1 %,
until Candela's node is translated by +voxel/2 per axis: --candela-shift 0.005208333 0.005208333
0.005208333 for cloud.vdb's 1/96 m voxels (the Cycles side keeps --translate)).

The Python on PATH may lack OpenImageIO (a pyenv interpreter): the script then re-runs itself
with /usr/bin/python3 (Debian's python3-openimageio and python3-numpy).
"""

import argparse
import json
import math
import os
import subprocess
import sys
import time

DEBIAN_PYTHON = '/usr/bin/python3'
try:
    import numpy as np
    import OpenImageIO as oiio
except ImportError as e:
    if (os.path.exists(DEBIAN_PYTHON)
            and os.path.realpath(sys.executable) != os.path.realpath(DEBIAN_PYTHON)):
        os.execv(DEBIAN_PYTHON, [DEBIAN_PYTHON] + sys.argv)
    sys.exit('cycles_volume_compare.py: %s (apt-get install python3-openimageio python3-numpy)' % e)

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SHARED = os.path.join(os.path.dirname(ROOT), 'shared')


def parse_args():
    ap = argparse.ArgumentParser(
        prog='cycles_volume_compare.py',
        description='Render a VDB volume lit by a point light with Candela and with Blender Cycles '
                    '(through ../shared/tools/cycles_render.py) and compare the image means. '
                    'Needs Blender installed locally; manual validation, never run in CI.',
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument('--out', default='/tmp/cycles-cmp/run', help='output folder')
    ap.add_argument('--candela', default=os.path.join(ROOT, 'build', 'renderer', 'candela'))
    ap.add_argument('--blender', default='blender')
    ap.add_argument('--tool', default=os.path.join(SHARED, 'tools', 'cycles_render.py'))
    ap.add_argument('--vdb', default=os.path.join(SHARED, 'assets', 'vdb', 'cloud.vdb'))
    ap.add_argument('--density-scale', type=float, default=15.0, help='extinction per unit density, 1/m')
    ap.add_argument('--albedo', type=float, default=0.9)
    ap.add_argument('--g', type=float, default=0.0, help='Henyey-Greenstein anisotropy (> 0: forward)')
    ap.add_argument('--translate', type=float, nargs=3, default=[0.15, -0.1, 0.2],
                    help='volume node translation, glTF coordinates (Y-up, m)')
    ap.add_argument('--candela-shift', type=float, nargs=3, default=[0.0, 0.0, 0.0],
                    help='extra translation of the Candela node only (the voxel-centre convention: '
                         '+voxel/2 per axis puts it where Cycles draws the VDB)')
    ap.add_argument('--camera-pos', type=float, nargs=3, default=[0.0, 0.0, 3.0],
                    help='camera position; it looks down -Z (glTF default orientation)')
    ap.add_argument('--yfov', type=float, default=0.5, help='vertical field of view, radians')
    ap.add_argument('--light-pos', type=float, nargs=3, default=[1.5, 1.5, 1.5])
    ap.add_argument('--light-intensity', type=float, default=20000.0,
                    help='point light intensity in the glTF file (cd; W/sr = value / 683 in both renderers)')
    ap.add_argument('--res', type=int, default=128, help='square image size')
    ap.add_argument('--spp', type=int, default=1024, help='Candela samples per pixel')
    ap.add_argument('--cycles-spp', type=int, default=64, help='Cycles samples per pixel per render')
    ap.add_argument('--cycles-seeds', type=int, default=1,
                    help='Cycles renders per step rate (seeds 0..N-1); >= 2 gives a standard error')
    ap.add_argument('--step-rates', type=float, nargs='+', default=[1.0, 0.25, 0.1],
                    help='Cycles volume step rates (material volume_step_rate)')
    ap.add_argument('--bounces', type=int, default=64,
                    help='Cycles --max-depth (all bounces) and Candela --max-volume-bounces')
    ap.add_argument('--threads', type=int, default=2)
    ap.add_argument('--seed', type=int, default=1, help='Candela seed')
    ap.add_argument('--exposure', type=float, default=None,
                    help='PNG exposure in stops (default: Candela 99.5th percentile at 0.9)')
    ap.add_argument('--world', type=float, default=0.0,
                    help='constant environment radiance (0: black world): Candela --env of a constant '
                         'EXR with --env-strength, Cycles a Background of that strength (scenes/cycles_world.py)')
    ap.add_argument('--skip-cycles', action='store_true', help='reuse the Cycles EXRs already in --out')
    ap.add_argument('--skip-candela', action='store_true', help='reuse the Candela EXR already in --out')
    return ap.parse_args()


def write_gltf(path, a):
    doc = {
        'asset': {'version': '2.0', 'generator': 'candela scenes/cycles_volume_compare.py'},
        'scene': 0,
        'scenes': [{'nodes': [0, 1, 2]}],
        'extensionsUsed': ['KHR_lights_punctual'],
        'extensions': {'KHR_lights_punctual': {'lights': [
            {'name': 'point', 'type': 'point', 'color': [1.0, 1.0, 1.0], 'intensity': a.light_intensity}]}},
        'cameras': [{'name': 'camera', 'type': 'perspective',
                     'perspective': {'yfov': a.yfov, 'aspectRatio': 1.0, 'znear': 0.01}}],
        'nodes': [
            {'name': 'camera', 'camera': 0, 'translation': a.camera_pos},
            {'name': 'point', 'translation': a.light_pos, 'extensions': {'KHR_lights_punctual': {'light': 0}}},
            {'name': 'cloud', 'translation': [t + d for t, d in zip(a.translate, a.candela_shift)],
             'extras': {'candela_volume': {'uri': os.path.abspath(a.vdb), 'density_scale': a.density_scale,
                                           'albedo': [a.albedo] * 3, 'anisotropy': a.g}}},
        ],
    }
    with open(path, 'w') as f:
        json.dump(doc, f, indent=1)


def read_exr(path):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        sys.exit('cannot read %s: %s' % (path, buf.geterror()))
    names = list(buf.spec().channelnames)
    px = buf.get_pixels(oiio.FLOAT)  # H x W x C
    return {n: px[:, :, i].astype(np.float64) for i, n in enumerate(names)}


def rgb(ch):
    return np.stack([ch['R'], ch['G'], ch['B']], axis=-1)


def quadrants(img):
    h, w = img.shape[:2]
    lum = img.mean(axis=-1)
    return [lum[:h // 2, :w // 2].mean(), lum[:h // 2, w // 2:].mean(),
            lum[h // 2:, :w // 2].mean(), lum[h // 2:, w // 2:].mean()]


def write_png(path, img, scale):
    x = np.clip(img * scale, 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    x = (x * 255.0 + 0.5).astype(np.uint8)
    spec = oiio.ImageSpec(x.shape[1], x.shape[0], 3, oiio.UINT8)
    out = oiio.ImageOutput.create(path)
    out.open(path, spec)
    out.write_image(x)
    out.close()


def clean_env():
    """The environment without pyenv's interpreter directories and variables: run from a pyenv
    shim, PATH starts with /root/.pyenv/versions/X/bin and Blender's embedded Python then takes
    that prefix and cannot import Debian's numpy."""
    env = {k: v for k, v in os.environ.items() if not k.startswith('PYENV') and k != 'PYTHONHOME'}
    env['PATH'] = os.pathsep.join(d for d in env.get('PATH', '').split(os.pathsep)
                                  if '/.pyenv/versions/' not in d and not d.endswith('/.pyenv/libexec'))
    return env


def run(cmd, log):
    print('$ ' + ' '.join(cmd), flush=True)
    t = time.perf_counter()
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=clean_env())
    with open(log, 'w') as f:
        f.write(p.stdout)
    if p.returncode != 0:
        sys.exit('command failed (%d), see %s:\n%s' % (p.returncode, log, p.stdout[-2000:]))
    return p.stdout, time.perf_counter() - t


def fmt3(v, digits=6):
    return '(' + ', '.join('%.*f' % (digits, x) for x in v) + ')'


def main():
    a = parse_args()
    os.makedirs(a.out, exist_ok=True)
    gltf = os.path.join(a.out, 'volume_compare.gltf')
    write_gltf(gltf, a)
    res = '%dx%d' % (a.res, a.res)
    npix = a.res * a.res
    summary = {'params': vars(a)}

    # ------------------------------------------------------------------ Candela
    c_exr = os.path.join(a.out, 'candela.exr')
    c_json = os.path.join(a.out, 'candela_stats.json')
    env = []
    if a.world > 0.0:
        sky = os.path.join(a.out, 'sky_constant.exr')
        spec = oiio.ImageSpec(64, 32, 3, oiio.FLOAT)
        out = oiio.ImageOutput.create(sky)
        out.open(sky, spec)
        out.write_image(np.ones((32, 64, 3), dtype=np.float32))
        out.close()
        env = ['--env', sky, '--env-strength', '%.9g' % a.world]
    if not a.skip_candela:
        run([a.candela, 'render', gltf, '--res', res, '--spp', str(a.spp), '--max-depth', '8',
             '--max-volume-bounces', str(a.bounces), '--seed', str(a.seed), '--threads', str(a.threads),
             '--light-units', 'blender', '--no-png', '--stats-json', c_json, '-o', c_exr] + env,
            os.path.join(a.out, 'candela.log'))
    ch = read_exr(c_exr)
    c_img = rgb(ch)
    c_mean = c_img.reshape(-1, 3).mean(axis=0)
    c_var = np.stack([ch['variance.R'], ch['variance.G'], ch['variance.B']], axis=-1)
    c_se = np.sqrt(c_var.reshape(-1, 3).sum(axis=0)) / npix
    with open(c_json) as f:
        st = json.load(f)
    ts = st['time_seconds']
    c_render = sum(ts[k] for k in ('generate', 'sort', 'trace', 'medium', 'shade', 'shadow', 'film') if k in ts)
    c_tps = c_render / st['spp']
    summary['candela'] = {'mean': c_mean.tolist(), 'se': c_se.tolist(), 'render_s': c_render,
                          'per_sample_s': c_tps, 'total_s': ts.get('total'), 'spp': st['spp'],
                          'volume_collisions': st.get('volumes', {}).get('collisions')}

    # ------------------------------------------------------------------ Cycles
    cyc = []
    for rate in a.step_rates:
        means, tpss, imgs = [], [], []
        for seed in range(a.cycles_seeds):
            exr = os.path.join(a.out, 'cycles_sr%g_seed%d.exr' % (rate, seed))
            log = os.path.join(a.out, 'cycles_sr%g_seed%d.log' % (rate, seed))
            if not a.skip_cycles:
                tool = [a.tool, '--'] if a.world <= 0.0 else [
                    os.path.join(HERE, 'cycles_world.py'), '--', '--world-strength', '%.9g' % a.world, '--cycles-tool', a.tool]
                cmd = [a.blender, '-b', '--factory-startup', '-noaudio', '--python'] + tool + [
                       '--input', gltf, '--output', exr, '--width', str(a.res), '--height', str(a.res),
                       '--spp', str(a.cycles_spp), '--max-depth', str(a.bounces), '--threads', str(a.threads),
                       '--seed', str(seed), '--lighting-mode', 'SPEC',
                       '--vdb', os.path.abspath(a.vdb), '--vdb-translate'] + ['%.9g' % x for x in a.translate] + [
                       '--vdb-density', '%.9g' % a.density_scale, '--vdb-albedo'] + ['%.9g' % a.albedo] * 3 + [
                       '--vdb-g', '%.9g' % a.g, '--vdb-step-rate', '%.9g' % rate]
                if seed == 0:
                    cmd.append('--time-per-sample')
                run(cmd, log)
            with open(log) as f:
                line = [ln for ln in f if ln.startswith('CYCLES_RESULT ')]
            r = json.loads(line[-1][len('CYCLES_RESULT '):]) if line else {}
            img = rgb(read_exr(exr))
            imgs.append(img)
            means.append(img.reshape(-1, 3).mean(axis=0))
            if 'per_sample_s' in r and seed == 0:
                tpss.append(r['per_sample_s'])
        means = np.array(means)
        m = means.mean(axis=0)
        se = means.std(axis=0, ddof=1) / math.sqrt(len(means)) if len(means) >= 2 else None
        cyc.append({'step_rate': rate, 'mean': m, 'se': se, 'per_sample_s': tpss[0] if tpss else None,
                    'img': np.mean(imgs, axis=0), 'seed_means': means})

    # ------------------------------------------------------------------ images
    scale = (2.0 ** a.exposure) if a.exposure is not None else 0.9 / max(np.percentile(c_img, 99.5), 1e-12)
    write_png(os.path.join(a.out, 'candela.png'), c_img, scale)
    for c in cyc:
        write_png(os.path.join(a.out, 'cycles_sr%g.png' % c['step_rate']), c['img'], scale)
    fine = min(cyc, key=lambda c: c['step_rate'])
    diff = np.abs(c_img - fine['img']) * 4.0
    write_png(os.path.join(a.out, 'compare.png'), np.concatenate([c_img, fine['img'], diff], axis=1), scale)

    # ------------------------------------------------------------------ report
    print()
    print('scene: %s  (density_scale %g, albedo %g, g %g, %s, Candela %d spp, Cycles %d spp x %d seeds, '
          'bounces %d, %d threads)' % (gltf, a.density_scale, a.albedo, a.g, res, a.spp, a.cycles_spp,
                                        a.cycles_seeds, a.bounces, a.threads))
    print('%-22s %-40s %-34s %-12s %s' % ('renderer', 'mean RGB', '+- SE (G)', 'rel SE', 's / sample'))
    print('%-22s %-40s %-34s %-12s %.5f' % ('Candela', fmt3(c_mean), '+- %.6f' % c_se[1],
                                             '%.3f%%' % (100 * c_se[1] / c_mean[1]), c_tps))
    summary['cycles'] = []
    for c in cyc:
        se = '+- %.6f' % c['se'][1] if c['se'] is not None else '(1 seed: no SE)'
        rel = '%.3f%%' % (100 * c['se'][1] / c['mean'][1]) if c['se'] is not None else '-'
        tps = '%.5f' % c['per_sample_s'] if c['per_sample_s'] is not None else '-'
        print('%-22s %-40s %-34s %-12s %s' % ('Cycles step %g' % c['step_rate'], fmt3(c['mean']), se, rel, tps))
        summary['cycles'].append({'step_rate': c['step_rate'], 'mean': c['mean'].tolist(),
                                  'se': c['se'].tolist() if c['se'] is not None else None,
                                  'seed_means': c['seed_means'].tolist(), 'per_sample_s': c['per_sample_s']})
    print()
    for c in cyc:
        ratio = c_mean / c['mean']
        sig = None
        if c['se'] is not None:
            tot = math.sqrt(c_se[1] ** 2 + c['se'][1] ** 2)
            sig = (c_mean[1] - c['mean'][1]) / tot
        print('Candela / Cycles(step %g) = %s%s' % (c['step_rate'], fmt3(ratio, 4),
              '   difference %.2f sigma (G)' % sig if sig is not None else ''))
    print()
    print('quadrant means (luminance; top-left, top-right, bottom-left, bottom-right):')
    print('  Candela            ' + ' '.join('%.5f' % q for q in quadrants(c_img)))
    for c in cyc:
        print('  Cycles step %-6g ' % c['step_rate'] + ' '.join('%.5f' % q for q in quadrants(c['img'])))
    qc, qf = quadrants(c_img), quadrants(fine['img'])
    print('  ratio (finest)     ' + ' '.join('%.4f' % (x / y if y else float('nan')) for x, y in zip(qc, qf)))
    if c_tps > 0 and fine['per_sample_s']:
        print('\ntime per sample (%d threads): Candela %.5f s, Cycles (step %g) %.5f s: Cycles / Candela = %.1f'
              % (a.threads, c_tps, fine['step_rate'], fine['per_sample_s'], fine['per_sample_s'] / c_tps))
    print('PNGs (common exposure x%.3g): %s' % (scale, os.path.join(a.out, 'compare.png')))
    with open(os.path.join(a.out, 'summary.json'), 'w') as f:
        json.dump(summary, f, indent=1, default=float)


if __name__ == '__main__':
    main()
