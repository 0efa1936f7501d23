#!/usr/bin/env python3
"""The default light sampler against power, tree and cache points on every bundled, shared and
generated scene (issue 12, "a default that never loses"): one command, one table.

    python3 scenes/default_sampler_table.py [--candela build/renderer/candela] [--res 320x180]
            [--spp 16] [--threads 2] [--repeats 3] [--scenes a,b,...] [--samplers default,power,...]
            [--out DIR] [--no-generate] [--mse --ref-spp 512]

Scenes: every .gltf/.glb in scenes/ and in ../shared/assets/gltf*/ (those without lights are
listed and skipped: every sampler renders the same image there), and the generated many-light
scenes (scenes/make_manylights.py into build/scenes/, generated when missing unless
--no-generate; the 1M-light city is left out). Each sampler renders each scene at the same
spp and seed in its own process; time is the process's CPU time (user + system, load, build
and render included, the median of --repeats runs: the images are bit-identical, only the
time varies), which another process on the machine disturbs less than the wall clock. The
variance is the mean of the EXR's per-pixel variance of the mean (as `candela compare`), and
TTUV = variance x time (the cache points paper's Table 3 measure; lower is better). With --mse,
a reference (tree sampler, --ref-spp, another seed) is rendered per scene and MSE x time is
printed too. The verdict column compares the default's TTUV with the best of power, tree and
cachepoints (the issue's bar: within 5 %). The default's choice is read from the stats JSON
(`light_sampler_used`). Needs oiiotool (Debian openimageio-tools). Run it on an idle machine
for numbers to publish; on a busy one, compare ratios within one run.
"""
import argparse
import glob
import json
import os
import statistics
import subprocess
import sys

from image_error import mse, oiio_mean, run_render

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(os.path.dirname(ROOT), "shared", "assets")
GENERATED = ["windows", "spotlights", "emissive_mesh", "street", "city_1k", "city_10k", "city"]
PEERS = ["power", "tree", "cachepoints"]


def find_scenes(args):
    scenes = []
    for f in sorted(glob.glob(os.path.join(ROOT, "scenes", "*.gltf")) + glob.glob(os.path.join(ROOT, "scenes", "*.glb"))):
        scenes.append((os.path.splitext(os.path.basename(f))[0], f))
    for d in ("gltf", "gltf-thirdparty"):
        for f in sorted(glob.glob(os.path.join(SHARED, d, "**", "*.gltf"), recursive=True) +
                        glob.glob(os.path.join(SHARED, d, "**", "*.glb"), recursive=True)):
            scenes.append((os.path.splitext(os.path.basename(f))[0], f))
    gen_dir = os.path.join(ROOT, "build", "scenes")
    missing = [g for g in GENERATED if not os.path.exists(os.path.join(gen_dir, g + ".gltf"))]
    if missing and not args.no_generate:
        subprocess.run([sys.executable, os.path.join(ROOT, "scenes", "make_manylights.py"), gen_dir, "--only"] + missing,
                       check=True, stdout=subprocess.DEVNULL)
    for g in GENERATED:
        f = os.path.join(gen_dir, g + ".gltf")
        if os.path.exists(f):
            scenes.append((g, f))
    if args.scenes:
        want = args.scenes.split(",")
        scenes = [s for s in scenes if s[0] in want]
        found = {s[0] for s in scenes}
        for w in want:
            if w not in found:
                sys.exit("unknown scene %s" % w)
    return scenes


def render(args, scene, out, sampler, spp, seed):
    """Renders; returns the stats JSON with "cpu_seconds" (user + system time of the process)."""
    stats = out[:-4] + ".json"
    cmd = [args.candela, "render", scene, "--res", args.res, "--spp", str(spp), "--seed", str(seed),
           "--threads", str(args.threads), "-o", out, "--no-png", "--stats-json", stats, "-q"]
    if sampler != "default":
        cmd += ["--light-sampler", sampler]
    cmd += args.extra.split()
    return run_render(cmd, stats)




def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--candela", default=os.path.join(ROOT, "build", "renderer", "candela"))
    ap.add_argument("--res", default="320x180")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3, help="renders per sampler and scene (median CPU time)")
    ap.add_argument("--scenes", default="", help="comma-separated scene names (default: all)")
    ap.add_argument("--samplers", default="default," + ",".join(PEERS))
    ap.add_argument("--extra", default="", help="flags added to every render (e.g. '--max-depth 4')")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "default_sampler_table"))
    ap.add_argument("--no-generate", action="store_true", help="do not generate missing many-light scenes")
    ap.add_argument("--mse", action="store_true", help="also MSE x time against a rendered reference")
    ap.add_argument("--ref-spp", type=int, default=512)
    args = ap.parse_args()
    samplers = args.samplers.split(",")
    os.makedirs(args.out, exist_ok=True)
    rows = []
    head = "| scene | lights | default uses | " + " | ".join("%s TTUV" % s for s in samplers) + \
           " | default / best peer | verdict |"
    print(head)
    print("|" + "---|" * (head.count("|") - 1), flush=True)
    for name, scene in find_scenes(args):
        res = {}
        used = ""
        lights = 0
        ref = None
        if args.mse:
            ref = os.path.join(args.out, "%s_reference.exr" % name)
            if not os.path.exists(ref):
                render(args, scene, ref, "tree", args.ref_spp, args.seed + 7919)
        for s in samplers:
            out = os.path.join(args.out, "%s_%s.exr" % (name, s))
            times = []
            for _ in range(max(1, args.repeats)):
                st = render(args, scene, out, s, args.spp, args.seed)
                times.append(st["cpu_seconds"])
            lights = st["lights"]
            if s == "default":
                used = st.get("light_sampler_used", st.get("light_sampler", "?"))
            var = oiio_mean([out, "--ch", "variance.R,variance.G,variance.B"])
            t = statistics.median(times)
            res[s] = {"var": var, "cpu": t, "ttuv": var * t, "build": st["cachepoints"]["build_seconds"],
                      "mse": mse(out, ref) if ref else None}
        if lights == 0:
            print("| %s | 0 | - | no lights: every sampler renders the same image |" % name, flush=True)
            continue
        peers = [res[p]["ttuv"] for p in PEERS if p in res]
        best = min(peers) if peers else None
        ratio = res["default"]["ttuv"] / best if best and "default" in res and best > 0 else float("nan")
        verdict = "ok" if ratio <= 1.05 else "LOSES"
        if ratio > 1.05 and used in res and used != "default" and res[used]["var"] == res["default"]["var"]:
            # the default ran that very sampler: the same image (the same variance), so the
            # ratio is CPU time: the default's probe (about 10 ms with 1,280 lights) and noise
            verdict = "same image as %s: CPU time only" % used
        cells = ["%.3g (%.2fs)" % (res[s]["ttuv"], res[s]["cpu"]) for s in samplers]
        print("| %s | %d | %s | %s | %.3f | %s |" % (name, lights, used, " | ".join(cells), ratio, verdict), flush=True)
        rows.append({"scene": name, "lights": lights, "default_uses": used, "results": res, "ratio": ratio})
    with open(os.path.join(args.out, "table.json"), "w") as f:
        json.dump({"res": args.res, "spp": args.spp, "threads": args.threads, "rows": rows}, f, indent=1)
    print("\nTTUV = mean per-pixel variance of the mean x CPU seconds (median of %d; load + build + render); "
          "in parentheses the CPU seconds. %s, %d spp, %d threads." % (args.repeats, args.res, args.spp, args.threads))
    if args.mse:
        print("\n| scene | " + " | ".join("%s MSE x time" % s for s in samplers) + " |")
        print("|" + "---|" * (len(samplers) + 1))
        for r in rows:
            print("| %s | %s |" % (r["scene"], " | ".join("%.3g" % (r["results"][s]["mse"] * r["results"][s]["cpu"])
                                                          for s in samplers)))


if __name__ == "__main__":
    main()
