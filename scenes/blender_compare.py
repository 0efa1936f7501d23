"""scenes/blender_compare.py: renders a Blender-built scene (scenes/blender/make_*.py) with Candela and
compares it with the Cycles 3.4 reference statistics stored beside it (NAME.cycles.json, written by
`make_*.py --reference`). Needs no Blender: only Candela and oiiotool (Debian openimageio-tools).

    python3 scenes/blender_compare.py scenes/blender_interior/interior.gltf [--json FILE]
        [--candela build/renderer/candela] [--spp N] [--seed S] [--threads N] [--png FILE]
        [--blocks] [--max-mean-diff PCT] -- [candela flags, e.g. --material-model blender3 --light-model blender3]

Candela renders at the reference's resolution, spp and --max-depth (its JSON says which) with the
flags after `--`. Printed: the image mean per channel of both renders, the ratio Candela / Cycles of
the channel-averaged means with its standard error (Candela's from its per-pixel variance of the
mean, Cycles' from the spread of its independent seeds) and the mean's z score; then every 32x32
block's ratio (channel-averaged means): the worst, and how many are outside 10%. With
--max-mean-diff PCT the exit status is 1 when |ratio - 1| exceeds PCT percent.
"""
import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile


def oiio_stats(exr, channels, cut=None):
    """Per-channel average of `channels` of the EXR, optionally in the region cut = (w, h, x, y)."""
    cmd = ["oiiotool", exr, "--ch", channels]
    if cut is not None:
        cmd += ["--cut", "%dx%d+%d+%d" % cut]
    r = subprocess.run(cmd + ["--printstats"], capture_output=True, text=True)
    m = re.search(r"Stats Avg: ([0-9.eE+\-naif ]+)", r.stdout)
    if r.returncode != 0 or not m:
        sys.exit("blender_compare.py: oiiotool gave no statistics for %s:\n%s" % (exr, r.stdout + r.stderr))
    return [float(v) for v in m.group(1).split()]


def main():
    argv = sys.argv[1:]
    extra = []
    if "--" in argv:
        k = argv.index("--")
        argv, extra = argv[:k], argv[k + 1:]
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser(prog="blender_compare.py")
    ap.add_argument("gltf")
    ap.add_argument("--json", default=None, help="reference statistics (default: NAME.cycles.json beside the glTF)")
    ap.add_argument("--candela", default=os.path.join(root, "build", "renderer", "candela"))
    ap.add_argument("--spp", type=int, default=None, help="default: the reference's spp")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--png", default=None, help="also keep Candela's preview PNG here")
    ap.add_argument("--blocks", action="store_true", help="print every block's ratio and its standard error")
    ap.add_argument("--max-mean-diff", type=float, default=None, help="exit 1 if the mean differs by more (percent)")
    a = ap.parse_args(argv)
    ref_path = a.json or os.path.splitext(a.gltf)[0] + ".cycles.json"
    with open(ref_path) as f:
        ref = json.load(f)
    w, h, block = ref["width"], ref["height"], ref["block"]
    spp = a.spp or ref["spp"]
    with tempfile.TemporaryDirectory() as tmp:
        exr = os.path.join(tmp, "candela.exr")
        cmd = [a.candela, "render", a.gltf, "--res", "%dx%d" % (w, h), "--spp", str(spp),
               "--max-depth", str(ref["max_depth"]), "--seed", str(a.seed), "--threads", str(a.threads),
               "-o", exr] + extra
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit("blender_compare.py: candela failed: %s\n%s" % (" ".join(cmd), r.stderr))
        for line in r.stderr.splitlines():
            if "warning" in line.lower():
                print("candela: " + line)
        if a.png:
            os.replace(os.path.join(tmp, "candela.png"), a.png)
        mean = oiio_stats(exr, "R,G,B")
        var = oiio_stats(exr, "variance.R,variance.G,variance.B")
        blocks = [[oiio_stats(exr, "R,G,B", (block, block, bx * block, by * block))
                   for bx in range(len(ref["blocks"][by]))] for by in range(len(ref["blocks"]))]
        blocks_var = [[oiio_stats(exr, "variance.R,variance.G,variance.B", (block, block, bx * block, by * block))
                       for bx in range(len(ref["blocks"][by]))] for by in range(len(ref["blocks"]))]
    n = w * h
    c_mean, y_mean = sum(mean) / 3, sum(ref["mean"]) / 3
    # variance of the channel average of the image mean: per channel mean(var)/n, channels
    # treated as independent (an upper bound is not needed here: a printed estimate)
    c_se = math.sqrt(sum(v / n for v in var)) / 3
    y_se = math.sqrt(sum(s * s for s in ref["mean_se"])) / 3
    ratio = c_mean / y_mean
    ratio_se = ratio * math.sqrt((c_se / c_mean) ** 2 + (y_se / y_mean) ** 2)
    print("scene      %s (%dx%d, %d spp, --max-depth %d) flags: %s" % (a.gltf, w, h, spp, ref["max_depth"],
                                                                     " ".join(extra) or "(defaults)"))
    print("reference  %s: %s, %d spp (%d seeds)" % (ref_path, ref["renderer"], ref["spp"], ref["seeds"]))
    print("mean RGB   candela %.5f %.5f %.5f   cycles %.5f %.5f %.5f" % (*mean, *ref["mean"]))
    print("mean ratio %.4f +- %.4f (candela/cycles; se candela %.2f%%, cycles %.2f%%; z = %+.1f)"
          % (ratio, ratio_se, 100 * c_se / c_mean, 100 * y_se / y_mean, (ratio - 1) / ratio_se if ratio_se else 0))
    worst, outside, count, noisy = None, 0, 0, 0
    nb = block * block
    for by, row in enumerate(ref["blocks"]):
        for bx, yb in enumerate(row):
            cb = sum(blocks[by][bx]) / 3
            yv = sum(yb) / 3
            q = cb / yv if yv > 0 else float("inf")
            # the block ratio's standard error (Cycles' from its seeds when the JSON has it)
            cse = math.sqrt(sum(v / nb for v in blocks_var[by][bx])) / 3
            yse = math.sqrt(sum(e * e for e in ref["blocks_se"][by][bx])) / 3 if "blocks_se" in ref else 0.0
            qse = q * math.sqrt((cse / cb) ** 2 + (yse / yv) ** 2) if cb > 0 and yv > 0 else float("inf")
            count += 1
            if a.blocks:
                print("block      (%d, %d) %.4f +- %.4f" % (bx, by, q, qse))
            outside += abs(q - 1) > 0.10
            noisy += 3 * qse > 0.10
            if worst is None or abs(q - 1) > abs(worst[0] - 1):
                worst = (q, bx, by, qse)
    print("blocks     %d of %d 32x32 blocks outside 10%%; worst %.4f +- %.4f at block (%d, %d) (column, row from "
          "the top left); %d blocks too noisy for a 10%% test (3 se > 10%%)"
          % (outside, count, worst[0], worst[3], worst[1], worst[2], noisy))
    if a.max_mean_diff is not None and abs(ratio - 1) * 100 > a.max_mean_diff:
        print("FAIL: mean differs by %.2f%% > %.2f%%" % (abs(ratio - 1) * 100, a.max_mean_diff))
        return 1
    return 0


sys.exit(main())
