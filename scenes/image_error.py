"""scenes/image_error.py: image error measures and the timed render the comparison scripts share
(oiiotool, Debian openimageio-tools). Imported by volume_equal_time.py, guiding_benchmark.py,
tree_mse.py and default_sampler_table.py."""
import json
import re
import resource
import subprocess
import sys


def mse(a, b):
    """Mean squared error between the RGB channels of two EXRs (oiiotool --diff's RMS squared)."""
    r = subprocess.run(["oiiotool", a, "--ch", "R,G,B", b, "--ch", "R,G,B", "--diff"], capture_output=True, text=True)
    m = re.search(r"RMS error = ([0-9.eE+-]+)", r.stdout + r.stderr)
    if not m and r.returncode == 0 and "PASS" in r.stdout:
        return 0.0  # identical pixels: oiiotool prints no error figures
    if not m:
        sys.exit("oiiotool --diff gave no RMS error for %s %s:\n%s" % (a, b, r.stdout + r.stderr))
    return float(m.group(1)) ** 2


def oiio_mean(args):
    """Mean over the pixels and channels of an oiiotool image expression (oiiotool prints 6
    decimals: the values are scaled by 1e9 first, so variances of 1e-6 keep their digits)."""
    r = subprocess.run(["oiiotool"] + args + ["--mulc", "1e9", "--printstats"], capture_output=True, text=True)
    m = re.search(r"Stats Avg: ([0-9.eE+\-naif ]+)", r.stdout)
    if not m:
        sys.exit("oiiotool gave no stats for %s:\n%s" % (" ".join(args), r.stdout + r.stderr))
    vals = [float(x) for x in m.group(1).split()]
    return sum(vals) / len(vals) * 1e-9


def run_render(cmd, stats):
    """Runs a candela render command that writes --stats-json to `stats`; returns that JSON with
    "cpu_seconds" added (the process's user + system time)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run(cmd, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        sys.exit("render failed: %s\n%s" % (" ".join(cmd), r.stderr))
    with open(stats) as f:
        st = json.load(f)
    st["cpu_seconds"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return st
