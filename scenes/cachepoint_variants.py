#!/usr/bin/env python3
"""scenes/cachepoint_variants.py: MSE at equal spp of cache point variants against a reference.

Renders SCENE once per (variant, seed) with `candela render` at the given spp and resolution,
and prints per variant the MSE against the reference EXR (averaged over the seeds, with the
spread), its ratio to the first variant, and the cache points' share of the render's CPU time
(build, and insertion between iterations, from --stats-json's CPU seconds over the process's).
MSE only: other work may share the machine, so wall times are not compared. Variants are
NAME=FLAGS pairs (flags split at spaces).

usage: cachepoint_variants.py CANDELA SCENE REFERENCE.exr --res WxH --spp N [--seeds K]
           [--max-depth D] [--out DIR] NAME=FLAGS ...
       cachepoint_variants.py CANDELA --table progressive [--scenes-dir DIR] [--res WxH]
           [--spp N ...] [--seeds K] [--max-depth D] [--out DIR]
example (the pooled visibility table in the README):
  python3 scenes/make_manylights.py build/scenes --only windows city
  build/renderer/candela render build/scenes/city.gltf --res 160x90 --max-depth 8 --spp 1024 \\
      --seed 777 -o build/ref_city.exr
  python3 scenes/cachepoint_variants.py build/renderer/candela build/scenes/city.gltf build/ref_city.exr \\
      --res 160x90 --max-depth 8 --spp 64 --seeds 3 off= points='--cachepoint-pooling points' \\
      lights='--cachepoint-pooling lights'
`--table progressive` is issue 12's acceptance table in one command: progressive insertion and
pooled visibility against the one-shot build on windows and city (160x90, depth 8, seeds 1-3,
16 and 64 spp by default). It generates the scenes (make_manylights.py) and the 1024-spp
references (seed 777, cache points) into --scenes-dir when they are missing, then prints one
table per scene and spp:
  python3 scenes/cachepoint_variants.py build/renderer/candela --table progressive
"""
import argparse
import os
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from image_error import mse, run_render  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))

# --table progressive: the one-shot build (the first, the ratios' base), progressive insertion,
# pooled visibility, and both
PROGRESSIVE_TABLE = [
    ("one-shot", "--cachepoint-progressive off --cachepoint-pooling off"),
    ("progressive", "--cachepoint-progressive on --cachepoint-pooling off"),
    ("pooling points", "--cachepoint-progressive off --cachepoint-pooling points"),
    ("pooling lights", "--cachepoint-progressive off --cachepoint-pooling lights"),
    ("progressive + lights", "--cachepoint-progressive on --cachepoint-pooling lights"),
]
TABLE_SCENES = ["windows", "city"]


def run_variants(a, scene, reference, spp, variants):
    base = os.path.splitext(os.path.basename(scene))[0]
    results = []
    for name, flags in variants:
        errs, shares, inserted = [], [], []
        for seed in range(1, a.seeds + 1):
            tag = name.replace(" ", "_").replace("+", "p")
            exr = os.path.join(a.out, "%s_%s_%dspp_s%d.exr" % (base, tag, spp, seed))
            stats = exr[:-4] + ".json"
            cmd = [a.candela, "render", scene, "--res", a.res, "--spp", str(spp), "--seed", str(seed),
                   "--light-sampler", "cachepoints", "--no-png", "--quiet", "-o", exr, "--stats-json", stats] + flags
            if a.max_depth is not None:
                cmd += ["--max-depth", str(a.max_depth)]
            st = run_render(cmd, stats)
            errs.append(mse(exr, reference))
            cp = st.get("cachepoints", {})
            cpu = st["cpu_seconds"]
            shares.append(((cp.get("build_cpu_seconds", 0.0) / cpu) if cpu > 0 else 0.0,
                           (cp.get("insertion_cpu_seconds", 0.0) / cpu) if cpu > 0 else 0.0))
            inserted.append((cp.get("points", 0), cp.get("inserted", 0)))
        results.append((name, " ".join(flags), errs, shares, inserted))
    first = results[0][2]
    # the variants share seeds, so each seed's ratio to the first variant is a paired comparison
    print("| %s %s, %d spp, %d seeds | flags | MSE (mean) | min | max | ratio of means | per-seed ratios "
          "| points (inserted) | CPU share: build, insertion |" % (base, a.res, spp, a.seeds))
    print("|---|---|---|---|---|---|---|---|---|")
    for name, flags, errs, shares, inserted in results:
        m, m0 = statistics.mean(errs), statistics.mean(first)
        paired = " ".join("%.3f" % (e / f if f > 0 else 0.0) for e, f in zip(errs, first))
        pts = statistics.mean(p for p, _ in inserted)
        ins = statistics.mean(i for _, i in inserted)
        sb = statistics.mean(b for b, _ in shares)
        si = statistics.mean(i for _, i in shares)
        print("| %s | `%s` | %.6g | %.6g | %.6g | %.3f | %s | %.0f (%.0f) | %.1f %%, %.1f %% |"
              % (name, flags or "-", m, min(errs), max(errs), m / m0 if m0 > 0 else 0.0, paired, pts, ins,
                 100 * sb, 100 * si))
    print()
    sys.stdout.flush()


def ensure_reference(a, scene, reference):
    if os.path.exists(reference):
        return
    print("rendering the reference %s (1024 spp, seed 777)" % reference, file=sys.stderr)
    cmd = [a.candela, "render", scene, "--res", a.res, "--spp", "1024", "--seed", "777", "--light-sampler",
           "cachepoints", "--no-png", "--quiet", "-o", reference]
    if a.max_depth is not None:
        cmd += ["--max-depth", str(a.max_depth)]
    subprocess.run(cmd, check=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("candela")
    ap.add_argument("scene", nargs="?")
    ap.add_argument("reference", nargs="?")
    ap.add_argument("variants", nargs="*", help="NAME=FLAGS")
    ap.add_argument("--table", choices=["progressive"], help="a predefined table (see above)")
    ap.add_argument("--scenes-dir", default="build/scenes", help="--table: the generated scenes and references")
    ap.add_argument("--res", default=None)
    ap.add_argument("--spp", type=int, nargs="+", default=None)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--max-depth", type=int, default=None)
    ap.add_argument("--out", default="out/cachepoint_variants")
    a = ap.parse_intermixed_args()
    os.makedirs(a.out, exist_ok=True)
    if a.table:
        a.res = a.res or "160x90"
        a.max_depth = 8 if a.max_depth is None else a.max_depth
        spps = a.spp or [16, 64]
        missing = [s for s in TABLE_SCENES if not os.path.exists(os.path.join(a.scenes_dir, s + ".gltf"))]
        if missing:
            subprocess.run([sys.executable, os.path.join(HERE, "make_manylights.py"), a.scenes_dir, "--only"] + missing,
                           check=True)
        variants = [(n, f.split()) for n, f in PROGRESSIVE_TABLE]
        for s in TABLE_SCENES:
            scene = os.path.join(a.scenes_dir, s + ".gltf")
            reference = os.path.join(a.scenes_dir, "ref_%s_%s_d%d.exr" % (s, a.res, a.max_depth))
            ensure_reference(a, scene, reference)
            for spp in spps:
                run_variants(a, scene, reference, spp, variants)
        return
    if not a.scene or not a.reference or not a.variants or not a.res or not a.spp or len(a.spp) != 1:
        ap.error("SCENE, REFERENCE, --res, one --spp and at least one NAME=FLAGS variant are needed without --table")
    variants = []
    for v in a.variants:
        if "=" not in v:
            sys.exit("variant '%s' is not NAME=FLAGS" % v)
        name, flags = v.split("=", 1)
        variants.append((name, flags.split()))
    run_variants(a, a.scene, a.reference, a.spp[0], variants)


if __name__ == "__main__":
    main()
