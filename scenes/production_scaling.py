#!/usr/bin/env python3
"""scenes/production_scaling.py: issue 28's scaling table of the production scene.

For each cell (lights as the paper counts them: punctual + emissive triangles + emissive
volumes; triangles after instancing), generates the scene with
`scenes/make_production.py --lights L --triangles T` (its docstring and plan_targets give the
rule that fills both targets) into SCENE_DIR/production_L_T.glb, reusing a file made before
with the same targets by the same generator (a sidecar .params.json holds the generator's
sha256), renders it with the default light sampler

    candela render FILE --res 640x360 --spp N --stats-json STATS -o OUT.exr --no-png -q

under /usr/bin/time -v, and prints a markdown table: the lights (the target, the paper's
count and Candela's: one per punctual light, per emissive primitive instance, per emissive
volume, plus the sky), the triangles, the light sampler used, the time to the first iteration
(the statistics' phases parse + flatten + embree + lights + sampler, in wall seconds), the peak
memory (the statistics' peak_memory_bytes; the process's max RSS beside it), the cache point
build (cachepoints.build_seconds, the points and their memory), the ms per spp of the
iterations after the first (time_total minus all phases, over spp_done - 1: the cache point
build and the first iteration are not in it), and the generation's seconds and file size. A
header gives the commit, the binary, the machine (CPU, cores, memory, load average) and the
command. A cell that fails (generator, renderer, timeout, unreadable statistics) is a row
saying why; the script goes on. Python 3 standard library only.

usage: production_scaling.py [--lights 10k,100k,1M,5M] [--triangles 1M,10M,50M] [--spp 8]
           [--res 640x360] [--threads N] [--candela PATH] [--scene-dir DIR] [--timeout S]
           [--stats-dir DIR] [--regenerate] [--dry-run]

The full table (issue 28; 12 cells, on an idle machine: the 5M-light cells take minutes each
and up to several GiB):

    python3 scenes/production_scaling.py --spp 8

A small check (one cell, ~1 minute on 2 cores):

    python3 scenes/production_scaling.py --lights 10k --triangles 1M --spp 4
"""

import argparse
import hashlib
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
GENERATOR = os.path.join(HERE, 'make_production.py')
LOAD_PHASES = ('parse', 'flatten', 'embree', 'lights', 'sampler')   # before the first iteration
ALL_PHASES = LOAD_PHASES + ('first_iteration',)
TIME = '/usr/bin/time'


def parse_count(text):
    """'10k' -> 10000, '1M' -> 1000000, '2500' -> 2500."""
    t = text.strip()
    m = re.fullmatch(r'([0-9]*\.?[0-9]+)([kKmM]?)', t)
    if not m:
        raise argparse.ArgumentTypeError('not a count: %r (e.g. 10k, 1M, 2500)' % text)
    v = float(m.group(1)) * {'': 1, 'k': 10 ** 3, 'm': 10 ** 6}[m.group(2).lower()]
    if v < 1:
        raise argparse.ArgumentTypeError('not a count: %r' % text)
    return int(round(v))


def label(n):
    """10000 -> '10k', 5000000 -> '5M' (file names and the table's first columns)."""
    for div, suffix in ((10 ** 6, 'M'), (10 ** 3, 'k')):
        if n >= div and n % (div // 10) == 0:
            v = n / div
            return ('%d' % v if v == int(v) else '%.1f' % v) + suffix
    return str(n)


def count_list(text):
    out = [parse_count(x) for x in text.split(',') if x.strip()]
    if not out:
        raise argparse.ArgumentTypeError('empty list')
    return out


def sha256(path):
    h = hashlib.sha256()
    with open(path, 'rb') as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b''):
            h.update(chunk)
    return h.hexdigest()


def run_measured(cmd, timeout):
    """Runs cmd; returns (returncode, wall seconds, max RSS bytes or None, stdout, stderr).
    The max RSS is /usr/bin/time -v's when it exists. returncode None: the timeout."""
    with tempfile.TemporaryDirectory() as tmp:
        tfile = os.path.join(tmp, 'time.txt')
        full = ([TIME, '-v', '-o', tfile] + cmd) if os.access(TIME, os.X_OK) else cmd
        t0 = time.monotonic()
        try:
            proc = subprocess.run(full, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired as e:
            return None, time.monotonic() - t0, None, e.stdout or '', e.stderr or ''
        wall = time.monotonic() - t0
        rss = None
        if os.path.exists(tfile):
            with open(tfile) as fh:
                m = re.search(r'Maximum resident set size \(kbytes\): (\d+)', fh.read())
            if m:
                rss = int(m.group(1)) * 1024
        return proc.returncode, wall, rss, proc.stdout, proc.stderr


def last_line(text):
    lines = [ln.strip() for ln in (text or '').splitlines() if ln.strip()]
    return lines[-1][:200] if lines else '(no message)'


def machine_facts():
    cpu = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as fh:
            for ln in fh:
                if ln.startswith('model name'):
                    cpu = ln.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    mem = ''
    try:
        with open('/proc/meminfo') as fh:
            for ln in fh:
                if ln.startswith('MemTotal:'):
                    mem = '%.1f GiB' % (int(ln.split()[1]) / 2 ** 20)
                    break
    except OSError:
        pass
    try:
        load = '%.2f %.2f %.2f' % os.getloadavg()
    except OSError:
        load = '?'
    return cpu, os.cpu_count(), mem, load


def git_commit():
    try:
        rev = subprocess.run(['git', '-C', ROOT, 'rev-parse', '--short', 'HEAD'], capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(['git', '-C', ROOT, 'status', '--porcelain', '--untracked-files=no'],
                               capture_output=True, text=True).stdout.strip()
        return rev + (' (with uncommitted changes)' if dirty else '')
    except (OSError, subprocess.CalledProcessError):
        return 'unknown'


class Cell:
    def __init__(self, lights, triangles, scene_dir):
        self.lights, self.triangles = lights, triangles
        self.name = 'production_%s_%s' % (label(lights), label(triangles))
        self.glb = os.path.join(scene_dir, self.name + '.glb')
        self.params = os.path.join(scene_dir, self.name + '.params.json')
        self.counts_path = os.path.join(scene_dir, self.name + '.counts.json')
        self.row = {'lights_target': lights, 'triangles_target': triangles}
        self.error = None

    def generate_cmd(self):
        return [sys.executable, GENERATOR, '-o', self.glb, '--lights', str(self.lights),
                '--triangles', str(self.triangles)]

    def reusable(self, generator_sha):
        """The .glb exists, and the sidecar says it came from these targets and this generator."""
        try:
            with open(self.params) as fh:
                p = json.load(fh)
            return (os.path.exists(self.glb) and os.path.exists(self.counts_path)
                    and p.get('lights') == self.lights and p.get('triangles') == self.triangles
                    and p.get('generator_sha256') == generator_sha)
        except (OSError, ValueError):
            return False


def generate(cell, generator_sha, timeout, regenerate):
    if not regenerate and cell.reusable(generator_sha):
        with open(cell.params) as fh:
            p = json.load(fh)
        cell.row['generate_s'] = p.get('seconds')
        cell.row['generate_rss'] = p.get('max_rss_bytes')
        cell.row['reused'] = True
    else:
        if os.path.exists(cell.params):
            os.remove(cell.params)   # a file of other targets or another generator: made again
        rc, wall, rss, out, err = run_measured(cell.generate_cmd(), timeout)
        if rc != 0:
            cell.error = 'generator %s: %s' % ('timed out after %.0f s' % wall if rc is None else 'exit %d' % rc,
                                               last_line(err))
            return False
        cell.row.update(generate_s=wall, generate_rss=rss, reused=False)
        with open(cell.params, 'w') as fh:
            json.dump({'lights': cell.lights, 'triangles': cell.triangles, 'generator_sha256': generator_sha,
                       'seconds': round(wall, 3), 'max_rss_bytes': rss}, fh, indent=1, sort_keys=True)
            fh.write('\n')
    try:
        with open(cell.counts_path) as fh:
            counts = json.load(fh)
    except (OSError, ValueError) as e:
        cell.error = 'generator wrote no readable counts (%s)' % e
        return False
    cell.row['counts'] = counts
    cell.row['glb_bytes'] = os.path.getsize(cell.glb)
    return True


def render_cmd(a, cell, stats, exr):
    cmd = [a.candela, 'render', cell.glb, '--res', a.res, '--spp', str(a.spp), '--stats-json', stats,
           '-o', exr, '--no-png', '-q']
    if a.threads:
        cmd += ['--threads', str(a.threads)]
    return cmd


def render(a, cell):
    os.makedirs(a.stats_dir, exist_ok=True)
    stats_path = os.path.join(a.stats_dir, cell.name + '.stats.json')
    if os.path.exists(stats_path):
        os.remove(stats_path)
    with tempfile.TemporaryDirectory() as tmp:
        rc, wall, rss, out, err = run_measured(render_cmd(a, cell, stats_path, os.path.join(tmp, 'out.exr')),
                                               a.timeout)
    if rc != 0:
        cell.error = 'render %s: %s' % ('timed out after %.0f s' % wall if rc is None else 'exit %d' % rc,
                                        last_line(err))
        return False
    try:
        with open(stats_path) as fh:
            s = json.load(fh)
        ph = s['phases']
        to_first = sum(ph[p]['seconds'] for p in LOAD_PHASES)
        after = s['time_seconds']['total'] - sum(ph[p]['seconds'] for p in ALL_PHASES)
        cp = s['cachepoints']
        cell.row.update(
            sampler=s['light_sampler_used'], candela_lights=s['lights'], candela_triangles=s['triangles'],
            to_first_s=to_first, first_iteration_s=ph['first_iteration']['seconds'],
            peak_bytes=s['peak_memory_bytes'], max_rss=rss, render_wall_s=wall,
            cp_build_s=cp['build_seconds'], cp_points=cp['points'], cp_bytes=cp['bytes'],
            ms_per_spp=(1000.0 * after / (s['spp_done'] - 1)) if s['spp_done'] > 1 else None,
            spp_done=s['spp_done'])
    except (OSError, ValueError, KeyError, TypeError) as e:
        cell.error = 'statistics %s unreadable: %s' % (stats_path, e)
        return False
    return True


def fmt_table(cells):
    head = ('| lights | paper count | Candela\'s | triangles | after instancing | sampler | to the first iteration '
            '| peak memory (max RSS) | cache point build | cache points | ms per spp | generated |')
    out = [head, '|' + '---|' * (head.count('|') - 1)]
    for c in cells:
        r = c.row
        counts = r.get('counts', {})
        cols = [label(c.lights), '{:,}'.format(counts['lights_paper']) if counts else '',
                '{:,}'.format(r['candela_lights']) if 'candela_lights' in r else '',
                label(c.triangles), '%.2fM' % (counts['triangles'] / 1e6) if counts else '']
        if 'sampler' in r:
            cols += [r['sampler'], '%.1f s' % r['to_first_s'],
                     '%.0f MiB (%s)' % (r['peak_bytes'] / 2 ** 20,
                                        '%.0f' % (r['max_rss'] / 2 ** 20) if r['max_rss'] else '?'),
                     '%.1f s' % r['cp_build_s'],
                     '{:,} points, {:.0f} MiB'.format(r['cp_points'], r['cp_bytes'] / 2 ** 20) if r['cp_points'] else '-',
                     '%.0f' % r['ms_per_spp'] if r['ms_per_spp'] is not None else '- (1 spp)']
        else:
            cols += ['**failed**: ' + (c.error or '?').replace('|', '/'), '', '', '', '', '']
        if 'generate_s' in r:
            gen = '%s s, %.0f MB' % ('%.1f' % r['generate_s'] if r['generate_s'] is not None else '?',
                                     r['glb_bytes'] / 1e6) if 'glb_bytes' in r else ''
            cols.append(gen + (' (reused)' if r.get('reused') else ''))
        else:
            cols.append('')
        out.append('| ' + ' | '.join(cols) + ' |')
    return '\n'.join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--lights', type=count_list, default=count_list('10k,100k,1M,5M'),
                    help='light targets, as the paper counts them (default 10k,100k,1M,5M)')
    ap.add_argument('--triangles', type=count_list, default=count_list('1M,10M,50M'),
                    help='triangle targets after instancing (default 1M,10M,50M)')
    ap.add_argument('--spp', type=int, default=8, help='samples per pixel (at least 2: ms per spp is after the first)')
    ap.add_argument('--res', default='640x360')
    ap.add_argument('--threads', type=int, default=0, help='candela --threads (default: candela\'s)')
    ap.add_argument('--candela', default=os.path.join(ROOT, 'build', 'renderer', 'candela'))
    ap.add_argument('--scene-dir', default=os.path.join(ROOT, 'build', 'scenes'))
    ap.add_argument('--stats-dir', default=None, help='the renders\' statistics (default SCENE_DIR/production_scaling)')
    ap.add_argument('--timeout', type=float, default=None, help='seconds per generation and per render')
    ap.add_argument('--regenerate', action='store_true', help='make the scenes again even when reusable')
    ap.add_argument('--dry-run', action='store_true', help='print the commands, run nothing')
    a = ap.parse_args()
    if a.spp < 2:
        ap.error('--spp must be at least 2 (ms per spp is measured after the first iteration)')
    if not re.fullmatch(r'[1-9][0-9]*x[1-9][0-9]*', a.res):
        ap.error('--res must be WxH, e.g. 640x360 (got %r)' % a.res)
    a.stats_dir = a.stats_dir or os.path.join(a.scene_dir, 'production_scaling')
    cells = [Cell(n, t, a.scene_dir) for n in a.lights for t in a.triangles]
    generator_sha = sha256(GENERATOR)

    if a.dry_run:
        for c in cells:
            if not a.regenerate and c.reusable(generator_sha):
                print('# %s: reused (%s)' % (c.name, c.glb))
            else:
                print(' '.join(c.generate_cmd()))
            print(' '.join(render_cmd(a, c, os.path.join(a.stats_dir, c.name + '.stats.json'), 'TMP/out.exr')))
        return 0
    if not os.access(a.candela, os.X_OK):
        sys.exit('production_scaling.py: %s: no candela binary (build it, or --candela PATH)' % a.candela)
    os.makedirs(a.scene_dir, exist_ok=True)

    cpu, cores, mem, load = machine_facts()
    version = subprocess.run([a.candela, '--version'], capture_output=True, text=True).stdout.strip()
    started = time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())
    for c in cells:
        sys.stderr.write('production_scaling.py: %s ...\n' % c.name)
        sys.stderr.flush()
        try:
            if generate(c, generator_sha, a.timeout, a.regenerate):
                render(a, c)
        except Exception as e:   # a row saying why, never a crash: the other cells still run
            c.error = '%s: %s' % (type(e).__name__, e)
        sys.stderr.write('production_scaling.py: %s: %s\n' % (c.name, c.error or 'done'))
    print('Production scene scaling (issue 28): commit %s, %s; %s, %d cores, %s; load average at the '
          'start %s, at the end %s; %s.' % (git_commit(), version or a.candela, cpu, cores, mem, load,
                                            machine_facts()[3], started))
    print('`python3 scenes/production_scaling.py %s` (%s, %d spp, the default light sampler%s).'
          % (' '.join(sys.argv[1:]), a.res, a.spp, ', %d threads' % a.threads if a.threads else ''))
    print()
    print(fmt_table(cells))
    return 1 if any(c.error for c in cells) else 0


if __name__ == '__main__':
    sys.exit(main())
