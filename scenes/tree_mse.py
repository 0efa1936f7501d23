#!/usr/bin/env python3
"""scenes/tree_mse.py: light-tree quality at equal spp on the many-lights scenes (issue 12).

Renders every scene of make_manylights.py (generate them first: python3 scenes/make_manylights.py)
with each variant at --spp for --seeds seeds and prints a Markdown table of the MSE against a
high-spp reference, averaged over the seeds, with the reference's own variance of the mean (its
EXR's variance channels, averaged) subtracted, and each variant's ratio to the first variant;
also the renders' own variance of the mean (their variance channels, averaged: the expected
MSE of an unbiased render, free of the reference's noise, which bounds what the MSE column
can resolve for low-noise variants such as cache points).
Also the CPU time per sample (user + system of the whole process over the paths, load and
builds included; a busy machine disturbs it: compare ratios within one run).

    python3 scenes/tree_mse.py [SCENE_DIR] [--candela PATH] [--old-candela PATH]
                               [--variants NAME=FLAGS;...] [--scenes a,b] [--res 160x90]
                               [--spp 16] [--seeds 4] [--ref-spp 1024] [--threads 2] [--out DIR]

--old-candela adds the variant `tree-old` (`--light-sampler tree` of another build, e.g. the
commit before the tree changes) before the others, so one command compares old and new trees.
A variant's flags may start with `@PATH ` to render it with another binary. The reference is
rendered once per scene (cache points, seed 1000003, another seed than every variant) and
reused from --out while its file exists. Needs oiiotool (Debian openimageio-tools).
"""
import argparse
import os
import sys

from image_error import mse, oiio_mean, run_render

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = "city_1k,city_10k,city,windows,spotlights,emissive_mesh"
VARIANTS = "tree=--light-sampler tree;power=--light-sampler power;cachepoints=--light-sampler cachepoints"


def render(candela, scene, out, spp, seed, res, threads, extra):
    """Renders; returns the stats JSON with "cpu_seconds" (the process's user + system time)."""
    stats = out[:-4] + ".json"
    cmd = [candela, "render", scene, "--res", res, "--spp", str(spp), "--seed", str(seed), "-o", out,
           "--png", out[:-4] + ".png", "--stats-json", stats, "-q"] + extra
    if threads > 0:
        cmd += ["--threads", str(threads)]
    return run_render(cmd, stats)



def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene_dir", nargs="?", default=os.path.join(ROOT, "build", "scenes"))
    ap.add_argument("--candela", default=os.path.join(ROOT, "build", "renderer", "candela"))
    ap.add_argument("--old-candela", help="another build: adds the variant tree-old first")
    ap.add_argument("--variants", default=VARIANTS, help="NAME=FLAGS;NAME=FLAGS (default: %(default)s)")
    ap.add_argument("--scenes", default=SCENES)
    ap.add_argument("--res", default="160x90")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "tree_mse"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    variants = []
    if a.old_candela:
        variants.append(("tree-old", a.old_candela, ["--light-sampler", "tree"]))
    for item in filter(None, (v.strip() for v in a.variants.split(";"))):
        name, flags = item.split("=", 1)
        words = flags.split()
        binary = a.candela
        if words and words[0].startswith("@"):
            binary = words.pop(0)[1:]
        variants.append((name.strip(), binary, words))
    print("%s, %d spp, %d seeds, reference %d spp (cache points, seed 1000003), %d threads\n" % (
        a.res, a.spp, a.seeds, a.ref_spp, a.threads))
    print("| scene | variant | MSE (mean of seeds) | min..max over seeds | MSE / %s | variance of the mean | variance / %s | CPU us/path |" % (variants[0][0], variants[0][0]))
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for name in a.scenes.split(","):
        scene = os.path.join(a.scene_dir, name + ".gltf")
        if not os.path.exists(scene):
            sys.exit("%s: no such scene (python3 scenes/make_manylights.py)" % scene)
        ref = os.path.join(a.out, "%s_%s_ref%d.exr" % (name, a.res, a.ref_spp))
        if not os.path.exists(ref):
            render(a.candela, scene, ref, a.ref_spp, 1000003, a.res, a.threads, ["--light-sampler", "cachepoints"])
        ref_var = oiio_mean([ref, "--ch", "variance.R,variance.G,variance.B"])
        base = None
        for vname, binary, flags in variants:
            errs, vars_, cpu, paths = [], [], 0.0, 0
            for seed in range(a.seeds):
                out = os.path.join(a.out, "%s_%s_s%d.exr" % (name, vname, seed))
                st = render(binary, scene, out, a.spp, seed, a.res, a.threads, flags)
                errs.append(max(mse(out, ref) - ref_var, 1e-30))
                vars_.append(oiio_mean([out, "--ch", "variance.R,variance.G,variance.B"]))
                cpu += st["cpu_seconds"]
                paths += st["paths"]
            err, var = sum(errs) / len(errs), sum(vars_) / len(vars_)
            if base is None:
                base, base_var = err, var
            print("| %s | %s | %.4g | %.3g..%.3g | %.3f | %.4g | %.3f | %.2f |" % (
                name, vname, err, min(errs), max(errs), err / base, var, var / base_var, 1e6 * cpu / max(paths, 1)))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
