#!/usr/bin/env python3
"""Path guiding at equal spp (issue 10's benchmark): unguided, guided by one-sample MIS and by
RIS, all with the default light sampler (cache points), on the indirect-dominated interior
(scenes/guiding_interior.gltf: a room lit through a small window) and the direct-dominated
default scene.

    python3 scenes/guiding_benchmark.py [--candela build/renderer/candela] [--res 640x480]
                                        [--spp 256] [--ref-spp 4096] [--out DIR] [--scenes a,b]
                                        [--light-sampler S] [--reference NAME=FILE.exr] [--ref-res WxH]
                                        [--repeats N]

Per scene: a reference (guided RIS at --ref-spp with another seed: its noise is independent of
every render compared, and it is unbiased: tests/test_guiding.c checks that guided and unguided
converge to the same image), then each configuration at --spp. MSE is against the reference
over RGB (oiiotool --diff), with the reference's own variance of the mean (its EXR's variance
channels, averaged) subtracted; time is the render's wall clock without scene loading (the cache
point build, guiding's training and the recorder are counted); TTUV = MSE x time, lower is
better; the ratio is unguided's TTUV over the configuration's. Also the mean path length
(bounce rays per camera ray), the radiance recorder's vertices per path and the training time
per guiding update. Prints a Markdown table. Needs oiiotool (Debian openimageio-tools).
Timings are wall clock: run on an otherwise idle machine and compare ratios within one run.
"""
import argparse
import os
import subprocess
import sys

from image_error import mse, oiio_mean, run_render

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = {"interior": "scenes/guiding_interior.gltf", "default": "scenes/default.gltf"}
CONFIGS = [("unguided", ["--guiding", "off"]), ("guided MIS", ["--guiding", "mis"]), ("guided RIS", ["--guiding", "ris"])]


def render(candela, scene, out, spp, seed, res, extra):
    """Renders; returns the stats JSON with "cpu_seconds" added (the process's user + system time)."""
    stats = out[:-4] + ".json"
    cmd = [candela, "render", scene, "--res", res, "--spp", str(spp), "--seed", str(seed), "-o", out,
           "--png", out[:-4] + ".png", "--stats-json", stats, "-q"] + extra
    return run_render(cmd, stats)



def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--candela", default=os.path.join(ROOT, "build", "renderer", "candela"))
    ap.add_argument("--res", default="640x480",
                    help="render resolution (default: the scenes' own, 640 wide; guiding learns from every "
                         "path, so its gain grows with the paths per iteration)")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "guiding_benchmark"))
    ap.add_argument("--scenes", default="interior,default")
    ap.add_argument("--reference", action="append", default=[], help="NAME=FILE.exr: reuse a reference")
    ap.add_argument("--ref-res", default="160x120",
                    help="render the reference at this lower resolution (an integer fraction of --res) and "
                         "compare box-downsampled renders with it: a box-filtered pixel is the mean of the "
                         "pixels it covers, so this measures the renders' error at that scale, for a "
                         "fraction of the reference's cost")
    ap.add_argument("--repeats", type=int, default=1,
                    help="render each configuration this many times (same seed, same image) and keep the "
                         "shortest time: a shared machine's noise only ever adds time")
    ap.add_argument("--time", choices=["wall", "cpu"], default="wall",
                    help="the time of TTUV: the render's wall clock without scene loading (default), or the "
                         "process's CPU time (user + system; with --threads 1 it is the work done, which a "
                         "busy shared machine disturbs far less than the wall clock)")
    ap.add_argument("--threads", type=int, default=0, help="render threads (0: all cores)")
    ap.add_argument("--light-sampler", default="cachepoints",
                    help="the light sampler of every render (default cachepoints, the renderer's default)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    given = dict(x.split("=", 1) for x in a.reference)
    print("light sampler: %s, %s, reference %d spp at %s (guided RIS, another seed), time: %s, threads: %s\n" % (
        a.light_sampler, a.res, a.ref_spp, a.ref_res or a.res, a.time, a.threads or "all"))
    print("| scene | configuration | spp | time (s) | MSE | TTUV ratio vs unguided | mean path length | recorder vertices/path | training s/update |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for name in a.scenes.split(","):
        scene = os.path.join(ROOT, SCENES[name])
        ref = given.get(name) or os.path.join(a.out, name + "_reference.exr")
        if name not in given:
            render(a.candela, scene, ref, a.ref_spp, 1000003, a.ref_res or a.res,
                   ["--guiding", "ris", "--light-sampler", a.light_sampler])
        ref_var = oiio_mean([ref, "--ch", "variance.R,variance.G,variance.B"])
        base = None
        for label, extra in CONFIGS:
            out = os.path.join(a.out, "%s_%s_%s.exr" % (name, a.light_sampler, extra[1]))
            t = None
            for _ in range(max(a.repeats, 1)):
                st = render(a.candela, scene, out, a.spp, 0, a.res,
                            extra + ["--light-sampler", a.light_sampler] +
                            (["--threads", str(a.threads)] if a.threads > 0 else []))
                if a.time == "cpu":
                    ti = st["cpu_seconds"]
                else:
                    ti = st["time_seconds"]["total"] - st["time_seconds"]["load"]
                t = ti if t is None else min(t, ti)
            compared = out
            if a.ref_res and a.ref_res != a.res:
                compared = out[:-4] + "_at_ref_res.exr"
                subprocess.run(["oiiotool", out, "--ch", "R,G,B", "--resize:filter=box", a.ref_res, "-o", compared],
                               check=True, capture_output=True)
            err = max(mse(compared, ref) - ref_var, 1e-30)
            ttuv = err * t
            if base is None:
                base = ttuv
            paths = max(st["paths"], 1)
            rec = st.get("recorder", {})
            gd = st.get("guiding", {})
            vpp = rec.get("vertices", 0) / max(rec.get("paths", 0), 1) if rec.get("paths") else 0.0
            spu = gd.get("train_seconds", 0.0) / gd["updates"] if gd.get("updates") else 0.0
            print("| %s | %s | %d | %.2f | %.4g | %.2fx | %.2f | %s | %s |" % (
                name, label, a.spp, t, err, base / ttuv, st["rays"]["bounce"] / paths,
                "%.2f" % vpp if vpp else "-", "%.4f" % spu if spu else "-"))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
