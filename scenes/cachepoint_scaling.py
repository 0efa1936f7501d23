#!/usr/bin/env python3
"""scenes/cachepoint_scaling.py: the cache point scale series (issue 3) as a benchmark.

Renders each scene of the city scale series (1k, 10k, 100k, 1M lights; generate them with
make_manylights.py) at 1 spp with the cut and the linear cache point builds, and prints a
markdown table of the build time (light tree + candidates + cache points), the number of
points, the cache points' own memory, the process's peak memory and the entries per point.
The linear build visits every light for every point (the paper's §5.2.2 scaling failure):
above --linear-max-lights it is not run, and its time is projected from the largest measured
linear build (linear in the light count). Python 3 standard library only.

usage: cachepoint_scaling.py [SCENE_DIR] [--candela PATH] [--linear-max-lights N]
                             [--res WxH] [--threads N] [--only 1k,10k,...]
"""

import json
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SERIES = [('1k', 1000), ('10k', 10000), ('100k', 100000), ('1m', 1000000)]


def run(candela, scene, build, res, threads):
    with tempfile.TemporaryDirectory() as tmp:
        stats = os.path.join(tmp, 'stats.json')
        cmd = [candela, 'render', scene, '--spp', '1', '--res', res, '--light-sampler', 'cachepoints',
               '--cachepoint-build', build, '-o', os.path.join(tmp, 'out.exr'), '--no-png', '--quiet',
               '--stats-json', stats]
        if threads:
            cmd += ['--threads', str(threads)]
        t0 = time.monotonic()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.monotonic() - t0
        if proc.returncode != 0:
            raise RuntimeError('%s failed: %s' % (' '.join(cmd), proc.stderr.strip()))
        with open(stats) as fh:
            s = json.load(fh)
    cp = s['cachepoints']
    return {'build_s': cp['build_seconds'], 'points': cp['points'], 'cp_mib': cp['bytes'] / 2**20,
            'peak_mib': s['peak_memory_bytes'] / 2**20, 'near': cp['mean_near'], 'far': cp['mean_far'],
            'clusters': cp['mean_clusters'], 'wall_s': wall, 'lights': s['lights']}


def main():
    args = sys.argv[1:]
    scene_dir = os.path.join(ROOT, 'build', 'scenes')
    candela = os.path.join(ROOT, 'build', 'renderer', 'candela')
    linear_max, res, threads, only = 100000, '640x360', 0, None
    if args and not args[0].startswith('--'):
        scene_dir = args.pop(0)
    while args:
        a = args.pop(0)
        if a == '--candela':
            candela = args.pop(0)
        elif a == '--linear-max-lights':
            linear_max = int(args.pop(0))
        elif a == '--res':
            res = args.pop(0)
        elif a == '--threads':
            threads = int(args.pop(0))
        elif a == '--only':
            only = set(args.pop(0).split(','))
        else:
            sys.exit('cachepoint_scaling.py: unknown option %s (see the docstring)' % a)
    rows = []
    last_linear = None
    for name, n in SERIES:
        if only and name not in only:
            continue
        scene = os.path.join(scene_dir, 'city_%s.gltf' % name)
        if not os.path.exists(scene):
            sys.exit('cachepoint_scaling.py: %s: missing (run scenes/make_manylights.py %s)' % (scene, scene_dir))
        for build in ('cut', 'linear'):
            if build == 'linear' and n > linear_max:
                proj = '%.0f (projected)' % (last_linear[1] * n / last_linear[0]) if last_linear else 'not run'
                rows.append((name, n, build, None, proj))
                continue
            print('city_%s: %s build ...' % (name, build), file=sys.stderr, flush=True)
            r = run(candela, scene, build, res, threads)
            if build == 'linear':
                last_linear = (n, r['build_s'])
            rows.append((name, n, build, r, None))
    print('| lights | build | build s | points | cache point MiB | peak MiB | near / far (clusters) per point |')
    print('|---|---|---|---|---|---|---|')
    for name, n, build, r, note in rows:
        if r is None:
            print('| %s | %s | %s | - | - | - | not run (above --linear-max-lights) |' % (n, build, note))
        else:
            print('| %d | %s | %.2f | %d | %.1f | %.1f | %.1f / %.1f (%.1f) |' % (
                r['lights'], build, r['build_s'], r['points'], r['cp_mib'], r['peak_mib'], r['near'], r['far'],
                r['clusters']))
    cut = [(n, r['build_s']) for name, n, build, r, _ in rows if build == 'cut' and r]
    if len(cut) >= 2:
        (n0, t0), (n1, t1) = cut[0], cut[-1]
        print('\ncut build: %.1fx the time for %.0fx the lights (%d -> %d)' % (t1 / t0, n1 / n0, n0, n1))


if __name__ == '__main__':
    main()
