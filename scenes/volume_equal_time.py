#!/usr/bin/env python3
"""Equal-time comparison of the volume estimators on the paper's cases (the cache points paper
Fig. 9, 11, 12): plain null-collision tracking, + emission sampling, + cache-point
in-scattering sampling (the full combination), all with the cache point light sampler.

    python3 scenes/make_volumes.py build/scenes/volumes
    python3 scenes/volume_equal_time.py [--scenes build/scenes/volumes] [--res 160x120]
                                        [--seconds 4] [--ref-spp 2048] [--out DIR]

For each scene: a reference (the full combination at --ref-spp with another seed, so its noise
is independent of every render compared; plain tracking's fireflies made a tracking reference
noisier than the renders it judged. test_volume_render shows the combinations agree), then, per
configuration a short calibration render for the time per sample, and a render with as many
samples as fit in --seconds (render time without scene loading: the cache point build, with
its scattering weights, is counted). MSE is against the reference over RGB (oiiotool --diff),
TTUV = MSE x time (lower is better; equal-time MSE ratios are TTUV ratios). Prints a Markdown
table. Needs oiiotool (Debian openimageio-tools). Timings are wall clock: run on an otherwise
idle machine and compare ratios within one run.
"""
import argparse
import json
import os
import re
import subprocess
import sys

from image_error import mse

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ["fig9_thin", "fig9_thick", "torch_mist", "spots_atmosphere"]
CONFIGS = [
    ("tracking", ["--volume-emission-sampling", "off", "--volume-cachepoint-scatter", "off"]),
    ("+emission sampling", ["--volume-emission-sampling", "on", "--volume-cachepoint-scatter", "off"]),
    ("+in-scattering (full)", ["--volume-emission-sampling", "on", "--volume-cachepoint-scatter", "on"]),
    ("both auto", ["--volume-emission-sampling", "auto", "--volume-cachepoint-scatter", "auto"]),
]
REFERENCE = CONFIGS[2][1]


def render(candela, scene, out, spp, seed, res, extra):
    stats = out + ".json"
    cmd = [candela, "render", scene, "--res", res, "--spp", str(spp), "--seed", str(seed), "-o", out,
           "--png", out[:-4] + ".png", "--stats-json", stats, "-q"] + extra
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("render failed: %s\n%s" % (" ".join(cmd), r.stderr))
    with open(stats) as f:
        t = json.load(f)["time_seconds"]
    return t["total"] - t["load"], t["build"]


def mse_trimmed(a, b, scratch, drop=0.001):
    """MSE without the worst `drop` fraction of pixels: a bright point light inside a thin
    medium gives every estimator a 1/r^2 tail in the few pixels whose rays pass within
    millimetres of it, and those pixels decide the plain MSE of a single render. Both columns
    are printed."""
    subprocess.run(["oiiotool", a, "--ch", "R,G,B", b, "--ch", "R,G,B", "--sub", "--powc", "2", "--chsum",
                    "-o", scratch], check=True, capture_output=True)
    out = subprocess.run(["oiiotool", "--dumpdata", scratch], capture_output=True, text=True).stdout
    v = sorted(float(m.group(1)) / 3.0 for m in re.finditer(r"Pixel \(\d+, \d+\):\s*(\S+)", out))
    keep = v[:len(v) - int(len(v) * drop)]
    return sum(keep) / max(len(keep), 1)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default=os.path.join(ROOT, "build", "scenes", "volumes"))
    ap.add_argument("--candela", default=os.path.join(ROOT, "build", "renderer", "candela"))
    ap.add_argument("--res", default="160x120")
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--only", nargs="*", default=SCENES)
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "equal_time"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    print("| scene | estimator | spp | time (s) | MSE | TTUV (MSE x s) | TTUV vs tracking "
          "| MSE w/o worst 0.1% px | its TTUV vs tracking |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in a.only:
        scene = os.path.join(a.scenes, name + ".gltf")
        if not os.path.exists(scene):
            sys.exit("%s: missing (run python3 scenes/make_volumes.py %s)" % (scene, a.scenes))
        ref = os.path.join(a.out, name + "_ref.exr")
        if not os.path.exists(ref):
            render(a.candela, scene, ref, a.ref_spp, 99, a.res, REFERENCE)
        base = base_t = None
        for label, extra in CONFIGS:
            tag = re.sub(r"[^a-z]+", "_", label).strip("_")
            cal = os.path.join(a.out, "%s_%s_cal.exr" % (name, tag))
            t8, build = render(a.candela, scene, cal, 8, 7, a.res, extra)
            per_spp = max((t8 - build) / 8.0, 1e-6)
            spp = max(1, int((a.seconds - build) / per_spp))
            out = os.path.join(a.out, "%s_%s.exr" % (name, tag))
            t, _ = render(a.candela, scene, out, spp, 5, a.res, extra)
            e = mse(out, ref)
            et = mse_trimmed(out, ref, os.path.join(a.out, "_se.exr"))
            ttuv, ttuv_t = e * t, et * t
            if base is None:
                base, base_t = ttuv, ttuv_t
            print("| %s | %s | %d | %.2f | %.3e | %.3e | %.2fx | %.3e | %.2fx |"
                  % (name, label, spp, t, e, ttuv, base / ttuv, et, base_t / ttuv_t))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
