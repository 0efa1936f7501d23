#!/usr/bin/env python3
"""The sample-quality benchmark (issue 26): MSE at equal spp of --sampler independent and sobol
(the default) against a high-spp reference, with the per-sample time and the time to unit
variance, over 3 seeds, on the scenes a user would compare renderers with.

    python3 scenes/sampler_benchmark.py [--candela build/renderer/candela] [--scenes a,b,...]
                                        [--spp 4,16,64] [--seeds 1,2,3] [--ref-spp N] [--out DIR]
                                        [--threads N] [--quick]

Scenes (generated ones are made on demand: scenes/make_manylights.py, make_volumes.py):
  cornell      scenes/cornell_box.gltf, 128x128, max depth 65 (the Lambert Cornell box)
  many_lights  ../shared/assets/gltf/cornell_many_lights.gltf, 160x120
  street       build/scenes/street.gltf (20k facade and street lights), 160x90, depth 8, --light-sampler tree
  interior     scenes/guiding_interior.gltf, 160x120
  torch        build/scenes/volumes/torch_mist.gltf, 160x90
  cloud        build/scenes/volumes/cornell_cloud.gltf (a VDB cloud in the Cornell box, one area
               light), 64x64, max depth 64, also at 256 spp
  default      scenes/default.gltf, 160x120

MSE is over RGB against the reference (rendered once per scene with sobol at --ref-spp and
a seed no render uses, kept in --out and reused while its .key file matches); the table also
gives the reference's own variance-layer mean (an upper bound of its squared error under
Sobol': compare it with the MSEs). Time is the render's wall clock without the scene load;
TTUV = MSE x time. The ratio columns are independent / sobol (above 1: sobol is better).
Timings are wall clock: run on an otherwise idle machine; ratios within one run.
"""
import argparse
import os
import subprocess
import sys

from image_error import mse, oiio_mean, run_render

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(os.path.dirname(ROOT), "shared", "assets", "gltf")
# name: (scene, res, extra flags, extra spp counts, how to make it)
SCENES = {
    "cornell": ("scenes/cornell_box.gltf", "128x128", ["--max-depth", "65"], [], None),
    "many_lights": (os.path.join(SHARED, "cornell_many_lights.gltf"), "160x120", [], [], None),
    "street": ("build/scenes/street.gltf", "160x90", ["--max-depth", "8", "--light-sampler", "tree"], [],
               ["scenes/make_manylights.py", "build/scenes", "--only", "street"]),
    "interior": ("scenes/guiding_interior.gltf", "160x120", [], [], None),
    "torch": ("build/scenes/volumes/torch_mist.gltf", "160x90", [], [], ["scenes/make_volumes.py"]),
    "cloud": ("build/scenes/volumes/cornell_cloud.gltf", "64x64", ["--max-depth", "64"], [256],
              ["scenes/make_volumes.py"]),
    "default": ("scenes/default.gltf", "160x120", [], [], None),
}


def render(candela, scene, out, res, spp, seed, sampler, extra, threads):
    stats = out[:-4] + ".json"
    cmd = [candela, "render", scene, "--res", res, "--spp", str(spp), "--seed", str(seed), "--sampler", sampler,
           "-o", out, "--no-png", "--stats-json", stats, "-q"] + extra
    if threads:
        cmd += ["--threads", str(threads)]
    st = run_render(cmd, stats)
    return st["time_seconds"]["total"] - st["time_seconds"]["load"]


def reference(a, name, scene, res, extra):
    ref = os.path.join(a.out, name + "_reference.exr")
    key = "%s %s %d %s %s\n" % (scene, res, a.ref_spp, " ".join(extra), os.path.getmtime(a.candela))
    keyfile = ref[:-4] + ".key"
    if not (os.path.exists(ref) and os.path.exists(keyfile) and open(keyfile).read() == key):
        render(a.candela, scene, ref, res, a.ref_spp, 1000003, "sobol", extra, a.threads)
        with open(keyfile, "w") as f:
            f.write(key)
    return ref


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--candela", default=os.path.join(ROOT, "build", "renderer", "candela"))
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--spp", default="4,16,64")
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--ref-spp", type=int, default=8192)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "sampler_benchmark"))
    ap.add_argument("--threads", type=int, default=0)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    seeds = [int(s) for s in a.seeds.split(",")]
    print("candela %s, seeds %s, reference: sobol at %d spp\n" % (a.candela, a.seeds, a.ref_spp))
    print("| scene | res | spp | MSE independent | MSE sobol | MSE ratio | time ratio (sobol / ind.) | TTUV ratio | reference variance |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for name in a.scenes.split(","):
        scene, res, extra, more_spp, make = SCENES[name]
        scene = os.path.join(ROOT, scene)
        if not os.path.exists(scene):
            if not make:
                print("| %s | (missing: %s) |" % (name, scene))
                continue
            subprocess.run([sys.executable, os.path.join(ROOT, make[0])] + [os.path.join(ROOT, x) if "/" in x else x
                                                                            for x in make[1:]],
                           check=True, capture_output=True)
        ref = reference(a, name, scene, res, extra)
        ref_var = oiio_mean([ref, "--ch", "variance.R,variance.G,variance.B"])
        for spp in [int(s) for s in a.spp.split(",")] + more_spp:
            err, t = {}, {}
            for sampler in ("independent", "sobol"):
                e = tt = 0.0
                for seed in seeds:
                    out = os.path.join(a.out, "%s_%s_%d_%d.exr" % (name, sampler, spp, seed))
                    tt += render(a.candela, scene, out, res, spp, seed, sampler, extra, a.threads)
                    e += mse(out, ref)
                err[sampler], t[sampler] = e / len(seeds), tt / len(seeds)
            r_mse = err["independent"] / err["sobol"]
            r_t = t["sobol"] / t["independent"]
            print("| %s | %s | %d | %.3e | %.3e | %.2fx | %.2f | %.2fx | %.1e |" % (
                name, res, spp, err["independent"], err["sobol"], r_mse, r_t, r_mse / r_t, ref_var))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
