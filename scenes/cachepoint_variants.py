#!/usr/bin/env python3
"""scenes/cachepoint_variants.py: MSE at equal spp of cache point variants against a reference.

Renders SCENE once per (variant, seed) with `candela render` at the given spp and resolution,
and prints per variant the MSE against the reference EXR (averaged over the seeds, with the
spread), and its ratio to the first variant. MSE only: other work may share the machine, so
times are not compared. Variants are NAME=FLAGS pairs (flags split at spaces).

usage: cachepoint_variants.py CANDELA SCENE REFERENCE.exr --res WxH --spp N [--seeds K]
           [--max-depth D] [--out DIR] NAME=FLAGS ...
example (the pooled visibility table in the README):
  python3 scenes/make_manylights.py build/scenes --only windows city
  build/renderer/candela render build/scenes/city.gltf --res 160x90 --max-depth 8 --spp 1024 \\
      --seed 777 -o build/ref_city.exr
  python3 scenes/cachepoint_variants.py build/renderer/candela build/scenes/city.gltf build/ref_city.exr \\
      --res 160x90 --max-depth 8 --spp 64 --seeds 3 off= points='--cachepoint-pooling points' \\
      lights='--cachepoint-pooling lights'
"""
import argparse
import os
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from image_error import mse  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("candela")
    ap.add_argument("scene")
    ap.add_argument("reference")
    ap.add_argument("variants", nargs="+", help="NAME=FLAGS")
    ap.add_argument("--res", required=True)
    ap.add_argument("--spp", type=int, required=True)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--max-depth", type=int, default=None)
    ap.add_argument("--out", default="out/cachepoint_variants")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    variants = []
    for v in a.variants:
        if "=" not in v:
            sys.exit("variant '%s' is not NAME=FLAGS" % v)
        name, flags = v.split("=", 1)
        variants.append((name, flags.split()))
    base = os.path.splitext(os.path.basename(a.scene))[0]
    results = []
    for name, flags in variants:
        errs = []
        for seed in range(1, a.seeds + 1):
            exr = os.path.join(a.out, "%s_%s_%dspp_s%d.exr" % (base, name, a.spp, seed))
            cmd = [a.candela, "render", a.scene, "--res", a.res, "--spp", str(a.spp), "--seed", str(seed),
                   "--light-sampler", "cachepoints", "--no-png", "--quiet", "-o", exr] + flags
            if a.max_depth is not None:
                cmd += ["--max-depth", str(a.max_depth)]
            subprocess.run(cmd, check=True)
            errs.append(mse(exr, a.reference))
        results.append((name, " ".join(flags), errs))
    first = results[0][2]
    # the variants share seeds, so each seed's ratio to the first variant is a paired comparison
    print("| %s %s, %d spp, %d seeds | flags | MSE (mean) | min | max | ratio of means | per-seed ratios |"
          % (base, a.res, a.spp, a.seeds))
    print("|---|---|---|---|---|---|---|")
    for name, flags, errs in results:
        m, m0 = statistics.mean(errs), statistics.mean(first)
        paired = " ".join("%.3f" % (e / f if f > 0 else 0.0) for e, f in zip(errs, first))
        print("| %s | `%s` | %.6g | %.6g | %.6g | %.3f | %s |" % (name, flags or "-", m, min(errs), max(errs),
                                                             m / m0 if m0 > 0 else 0.0, paired))


if __name__ == "__main__":
    main()
