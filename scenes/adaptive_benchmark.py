#!/usr/bin/env python3
"""Adaptive sampling at the same sample budget (issue 26): a render with --noise-threshold T
(at most --spp S per pixel) against a plain render with the same total samples (its mean spp,
rounded), both against a high-spp reference: MSE, relMSE, time and the time to unit variance.

    python3 scenes/adaptive_benchmark.py [--candela build/renderer/candela] [--scenes a,b]
                                         [--res 640x360] [--spp 256] [--thresholds 0.25,0.5,1]
                                         [--min-spp 16] [--ref-spp 4096] [--seeds 1,2] [--out DIR]
                                         [--keep-reference]

Scenes: interior (scenes/guiding_interior.gltf) and blender_interior
(scenes/blender_interior/interior.gltf with --material-model blender3 --light-model blender3), the
default ones; also default (scenes/default.gltf) and cornell_box (scenes/cornell_box.gltf).
The reference is a plain render (sobol, another seed) at --ref-spp, kept in --out and reused
while its .key file matches (the key names the binary's mtime; --keep-reference reuses it
whatever build made it: a plain render, so only a change to plain sampling invalidates it). relMSE is the mean of (x - ref)^2 / (ref^2 + 0.01) over pixels
and channels. Time is the render's wall clock without the scene load: run on an idle machine.
The image mean against the reference's (mean over pixels and channels), averaged over the seeds,
with two standard errors: across the seeds, and from the renders' and the reference's variance
layers (sqrt(mean variance / 3 pixels) per render); the plain render's as the control.
"""
import math
import argparse
import os
import subprocess
import sys

from image_error import mse, oiio_mean, run_render

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = {
    "interior": ("scenes/guiding_interior.gltf", []),
    "blender_interior": ("scenes/blender_interior/interior.gltf", ["--material-model", "blender3", "--light-model",
                                                                  "blender3"]),
    "default": ("scenes/default.gltf", []),
    "cornell_box": ("scenes/cornell_box.gltf", []),
}


def rel_mse(a, b):
    """Mean over pixels and channels of (a - b)^2 / (b^2 + 0.01) (oiiotool)."""
    r = subprocess.run(["oiiotool", a, "--ch", "R,G,B", b, "--ch", "R,G,B", "--sub", "--dup", "--mul",
                        b, "--ch", "R,G,B", "--dup", "--mul", "--addc", "0.01", "--div", "--printstats"],
                       capture_output=True, text=True)
    for line in r.stdout.splitlines():
        if "Stats Avg" in line:
            vals = [float(x) for x in line.split(":")[1].split("(")[0].split()]
            return sum(vals) / len(vals)
    sys.exit("oiiotool gave no stats:\n" + r.stdout + r.stderr)


def render(a, scene, out, spp, seed, extra):
    stats = out[:-4] + ".json"
    cmd = [a.candela, "render", scene, "--res", a.res, "--spp", str(spp), "--seed", str(seed), "-o", out, "--no-png",
           "--stats-json", stats, "-q"] + extra
    st = run_render(cmd, stats)
    return st, st["time_seconds"]["total"] - st["time_seconds"]["load"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--candela", default=os.path.join(ROOT, "build", "renderer", "candela"))
    ap.add_argument("--scenes", default="interior,blender_interior")
    ap.add_argument("--res", default="640x360")
    ap.add_argument("--spp", type=int, default=256, help="the most samples any pixel gets")
    ap.add_argument("--thresholds", default="0.25,0.5,1")
    ap.add_argument("--min-spp", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "adaptive_benchmark"))
    ap.add_argument("--keep-reference", action="store_true", help="reuse OUT's reference whatever build made it")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    seeds = [int(s) for s in a.seeds.split(",")]
    print("candela %s, %s, at most %d spp, min %d, reference %d spp, seeds %s\n" % (a.candela, a.res, a.spp, a.min_spp,
                                                                                  a.ref_spp, a.seeds))
    print(subprocess.run([a.candela, "--version"], capture_output=True, text=True).stdout.strip() + "\n")
    print("| scene | threshold | mean spp | MSE adaptive | MSE plain | MSE ratio | relMSE ratio | time adaptive / plain | TTUV ratio "
          "| image mean adaptive / reference - 1 (SE seeds, SE variance) | plain / reference - 1 | MSE ratio per seed |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in a.scenes.split(","):
        scene, extra = SCENES[name]
        scene = os.path.join(ROOT, scene)
        ref = os.path.join(a.out, "%s_%s_reference.exr" % (name, a.res))
        key = "%s %s %d %s\n" % (scene, a.res, a.ref_spp, os.path.getmtime(a.candela))
        kept = a.keep_reference and os.path.exists(ref)
        if not kept and not (os.path.exists(ref) and os.path.exists(ref[:-4] + ".key") and
                             open(ref[:-4] + ".key").read() == key):
            render(a, scene, ref, a.ref_spp, 1000003, extra)
            with open(ref[:-4] + ".key", "w") as f:
                f.write(key)
        for t in [float(x) for x in a.thresholds.split(",")]:
            m = {"ad": [0.0, 0.0, 0.0], "plain": [0.0, 0.0, 0.0]}
            mean_spp = 0.0
            biases, plain_bias, var_se2, per_seed = [], 0.0, 0.0, []  # a rule that reads a pixel's own samples can stop it low
            ref_mean = oiio_mean([ref, "--ch", "R,G,B"])
            w, h = (int(x) for x in a.res.split("x"))

            def mean_se2(f):  # squared standard error of an image's mean, from its variance layer
                return oiio_mean([f, "--ch", "variance.R,variance.G,variance.B"]) / (3.0 * w * h)
            for seed in seeds:
                out = os.path.join(a.out, "%s_ad_%g_%d.exr" % (name, t, seed))
                st, ta = render(a, scene, out, a.spp, seed, extra + ["--aov", "spp", "--noise-threshold", str(t), "--min-spp",
                                                                     str(a.min_spp)])
                spp_plain = max(1, int(round(st["spp_mean"])))
                mean_spp += st["spp_mean"] / len(seeds)
                outp = os.path.join(a.out, "%s_plain_%d_%d.exr" % (name, spp_plain, seed))
                _, tp = render(a, scene, outp, spp_plain, seed, extra)
                biases.append(oiio_mean([out, "--ch", "R,G,B"]) / ref_mean - 1.0)
                plain_bias += (oiio_mean([outp, "--ch", "R,G,B"]) / ref_mean - 1.0) / len(seeds)
                var_se2 += mean_se2(out) / len(seeds) ** 2
                pair = [mse(out, ref), mse(outp, ref)]
                per_seed.append("%.2f" % (pair[1] / pair[0]))
                for k, o, tt in (("ad", out, ta), ("plain", outp, tp)):
                    m[k][0] += pair[k == "plain"] / len(seeds)
                    m[k][1] += rel_mse(o, ref) / len(seeds)
                    m[k][2] += tt / len(seeds)
            r_mse = m["plain"][0] / m["ad"][0]
            r_t = m["ad"][2] / m["plain"][2]
            bias = sum(biases) / len(biases)
            k = len(biases)
            se_seeds = math.sqrt(sum((b - bias) ** 2 for b in biases) / (k - 1) / k) if k > 1 else float("nan")
            se_var = math.sqrt(var_se2 + mean_se2(ref)) / ref_mean
            print("| %s | %g | %.1f | %.3e | %.3e | %.2fx | %.2fx | %.2f | %.2fx | %+.2f%% (%.2f%%, %.2f%%) | %+.2f%% | %s |" % (
                name, t, mean_spp, m["ad"][0], m["plain"][0], r_mse, m["plain"][1] / m["ad"][1], r_t, r_mse / r_t,
                100.0 * bias, 100.0 * se_seeds, 100.0 * se_var, 100.0 * plain_bias, " ".join(per_seed)))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
