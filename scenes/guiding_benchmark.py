#!/usr/bin/env python3
"""The path-guiding benchmark (issues 10 and 25): unguided and guided renders at equal spp on
the scenes guiding exists for and on scenes it should leave alone.

    python3 scenes/guiding_benchmark.py [--candela build/renderer/candela] [--scenes box,interior,...]
                                        [--res WxH,...] [--spp N] [--configs off,mis,ris,auto]
                                        [--ref-spp N] [--ref-candela BIN] [--out DIR] [--repeats N] [--seeds N]
                                        [--threads N]

Scenes and their default resolutions and sample counts (--res and --spp override them):
  box        scenes/cornell_indirect.gltf (a Lambert Cornell box lit through the ceiling: its light
             faces the ceiling), max depth 64, 128x128, 256x256 and 640x480, 256 spp
  interior   scenes/guiding_interior.gltf (a room lit through a small window), 640x480, 256 spp
  blender    scenes/blender_interior/interior.gltf (--material-model blender3 --light-model blender3;
             lit mostly by the lamp's bulb inside its shade), 640x360, 128 spp
  pane       the box above with a glass pane between its light and the ceiling (written to --out by
             make_pane): the ceiling is lit only through the glass, a caustic the guide learns, where
             the caustic guard must keep guiding; 128x128, 256 spp
  default    scenes/default.gltf (direct light dominates), 320x240, 64 spp
  bench      scenes/bench.gltf (direct light), 320x240, 16 spp
  city, windows, emissive_mesh, spotlights, street, glossy
             the many-light scenes of scenes/make_manylights.py (written to build/scenes when absent;
             direct light through cache points), 160x120, 64 spp

Per scene and resolution: a reference (guided MIS with independent samples, a seed no render
uses, --ref-spp, at a quarter of the resolution per side, compared with 4x4 box-downsampled
renders; kept in --out and reused while its .key file matches), then each configuration at the
same spp. Guided renders converge to the unguided image (tests/test_guiding.c), and with
independent samples the reference's variance layer estimates its own squared error without bias,
so it is subtracted from the errors below (the renders' noise is independent of it). Columns:
  relMSE      mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01) of the downsampled
              render (the guiding literature's metric), less the reference's own (its variance
              layer / (ref^2 + 0.01)), and MSE beside it (less the reference's mean variance);
              with --seeds N, the mean over N renders (seeds 0 .. N-1), its standard error (s.e.)
              and the median: where rare paths carry much of the error (blender: caustics through
              the glass sphere), one render's relMSE varies 36x from seed to seed, and only the
              mean over seeds estimates the expected error; the median shows a typical render;
  rel. var.   mean over pixels and channels of the EXR's variance layer / (mean^2 + 0.01) at full
              resolution (the expected relMSE; with Sobol' samples an upper bound);
  time        the render's wall clock without the scene load (training, the recorder and the
              field updates included); the minimum over --repeats;
  TTUV        relMSE x time (time: the mean over the seeds), and its ratio to unguided's (lower is
              better); median TTUV: the same with the median relMSE;
  path len.   bounce rays per camera ray; ns/vertex: time per traced ray (camera + bounce), guided
              over unguided.
Timings are wall clock: run on an otherwise idle machine and compare ratios within one run.
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import sys

from image_error import mse, run_render

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = {
    "box": ("scenes/cornell_indirect.gltf", ["--max-depth", "64"], ["128x128", "256x256", "640x480"], 256),
    "interior": ("scenes/guiding_interior.gltf", [], ["640x480"], 256),
    "blender": ("scenes/blender_interior/interior.gltf", ["--material-model", "blender3", "--light-model", "blender3"],
                ["640x360"], 128),
    "pane": ("PANE", ["--max-depth", "64"], ["128x128"], 256),
    "default": ("scenes/default.gltf", [], ["320x240"], 64),
    "bench": ("scenes/bench.gltf", [], ["320x240"], 16),
}
# the many-light scenes (direct light through cache points), generated on demand into build/scenes
MANYLIGHTS = ("city", "windows", "emissive_mesh", "spotlights", "street", "glossy")
for _name in MANYLIGHTS:
    SCENES[_name] = ("build/scenes/%s.gltf" % _name, [], ["160x120"], 64)


def make_pane(out_dir):
    """scenes/cornell_indirect.gltf with a 1.9 x 0.04 x 1.6 glass slab (the short box's mesh, scaled) at
    y = 5.1, between the light (y = 4.75, facing up) and the ceiling (5.5); written as out_dir/pane.gltf."""
    g = json.load(open(os.path.join(ROOT, "scenes", "cornell_indirect.gltf")))
    box = next(m for m in g["meshes"] if m.get("name") == "short_box")
    acc = g["accessors"][box["primitives"][0]["attributes"]["POSITION"]]
    lo, hi = acc["min"], acc["max"]
    g["materials"].append({"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0,
                           "roughnessFactor": 0.0}, "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                                                                   "KHR_materials_ior": {"ior": 1.45}}})
    prim = dict(box["primitives"][0], material=len(g["materials"]) - 1)
    g["meshes"].append({"name": "pane", "primitives": [prim]})
    scale = [1.9 / (hi[0] - lo[0]), 0.04 / (hi[1] - lo[1]), 1.6 / (hi[2] - lo[2])]
    g["nodes"].append({"name": "glass_pane", "mesh": len(g["meshes"]) - 1, "translation": [0.0, 5.1, 0.0], "scale": scale})
    g["scenes"][g.get("scene", 0)]["nodes"].append(len(g["nodes"]) - 1)
    for ext in ("KHR_materials_transmission", "KHR_materials_ior"):
        if ext not in g.setdefault("extensionsUsed", []):
            g["extensionsUsed"].append(ext)
    path = os.path.join(out_dir, "pane.gltf")
    with open(path + ".tmp", "w") as f:
        json.dump(g, f)
    os.replace(path + ".tmp", path)
    return path


def oiio_stat(args):
    """Mean over pixels and channels of an oiiotool expression's result."""
    r = subprocess.run(["oiiotool"] + args + ["--printstats"], capture_output=True, text=True)
    for line in r.stdout.splitlines():
        if "Stats Avg" in line:
            vals = [float(x) for x in line.split(":")[1].split("(")[0].split()]
            return sum(vals) / len(vals)
    sys.exit("oiiotool gave no stats for %s:\n%s" % (" ".join(args), r.stdout + r.stderr))


def rel_mse(a, ref):
    return oiio_stat([a, "--ch", "R,G,B", ref, "--ch", "R,G,B", "--sub", "--dup", "--mul", ref, "--ch", "R,G,B", "--dup",
                      "--mul", "--addc", "0.01", "--div"])


def ref_noise(ref):
    """The reference's own expected relMSE and MSE (its variance layer: unbiased with independent samples)."""
    rel = oiio_stat([ref, "--ch", "variance.R,variance.G,variance.B", ref, "--ch", "R,G,B", "--dup", "--mul", "--addc", "0.01",
                     "--div"])
    return rel, oiio_stat([ref, "--ch", "variance.R,variance.G,variance.B"])


def rel_var(a):
    return oiio_stat([a, "--ch", "variance.R,variance.G,variance.B", a, "--ch", "R,G,B", "--dup", "--mul", "--addc", "0.01",
                      "--div"])


def render(a, scene, out, res, spp, seed, extra, candela=None):
    stats = out[:-4] + ".json"
    cmd = [candela or a.candela, "render", scene, "--res", res, "--spp", str(spp), "--seed", str(seed), "-o", out, "--no-png",
           "--stats-json", stats, "-q"] + extra + (["--threads", str(a.threads)] if a.threads > 0 else [])
    return run_render(cmd, stats)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--candela", default=os.path.join(ROOT, "build", "renderer", "candela"))
    ap.add_argument("--ref-candela", default="", help="the binary that renders the references (default: --candela); "
                    "a reference is kept while its binary is unchanged, so a fixed one spares re-rendering them "
                    "while the renders' binary changes")
    ap.add_argument("--scenes", default="box,interior,blender,default")
    ap.add_argument("--res", default="", help="resolutions (comma-separated) instead of the scenes' own")
    ap.add_argument("--spp", type=int, default=0, help="instead of the scenes' own")
    ap.add_argument("--configs", default="off,mis,ris")
    ap.add_argument("--ref-spp", type=int, default=32768)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "guiding_benchmark"))
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--seeds", type=int, default=1, help="renders per configuration, seeds 0 .. N-1 (relMSE: their mean)")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--extra", default="", help="flags added to every guided render (e.g. '--guide-training-spp 64')")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    print("candela %s; reference: guided MIS, independent samples, %d spp at a quarter of the resolution\n" % (
        a.candela, a.ref_spp))
    print("| scene | res | spp | config | relMSE | s.e. | median relMSE | MSE | rel. var. | time (s) | TTUV vs off | "
          "median TTUV vs off | rel. var. vs off | time vs off | path len. | ns/vertex vs off |")
    print("|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in a.scenes.split(","):
        scene, extra, resolutions, spp = SCENES[name]
        scene = make_pane(a.out) if scene == "PANE" else os.path.join(ROOT, scene)
        if name in MANYLIGHTS and not os.path.exists(scene):
            subprocess.run([sys.executable, os.path.join(ROOT, "scenes", "make_manylights.py"), os.path.dirname(scene),
                            "--only", name], check=True, capture_output=True)
        spp = a.spp or spp
        for res in (a.res.split(",") if a.res else resolutions):
            w, h = (int(x) for x in res.split("x"))
            ref_res = "%dx%d" % (max(w // 4, 1), max(h // 4, 1))
            ref = os.path.join(a.out, "%s_%s_reference.exr" % (name, ref_res))
            ref_candela = a.ref_candela or a.candela
            key = "%s %s %d %s %s %s\n" % (scene, ref_res, a.ref_spp, extra, ref_candela, os.path.getmtime(ref_candela))
            if not (os.path.exists(ref) and os.path.exists(ref[:-4] + ".key") and open(ref[:-4] + ".key").read() == key):
                render(a, scene, ref, ref_res, a.ref_spp, 1000003, extra + ["--guiding", "mis", "--sampler", "independent"],
                       candela=ref_candela)
                with open(ref[:-4] + ".key", "w") as f:
                    f.write(key)
            ref_rel, ref_mse = ref_noise(ref)
            base = None
            for config in a.configs.split(","):
                flags = extra + ["--guiding", config] + (a.extra.split() if config != "off" and a.extra else [])
                runs = []
                for seed in range(max(a.seeds, 1)):
                    out = os.path.join(a.out, "%s_%s_%s%s.exr" % (name, res, config, "_s%d" % seed if seed else ""))
                    t = None
                    for _ in range(max(a.repeats, 1)):
                        st = render(a, scene, out, res, spp, seed, flags)
                        ti = st["time_seconds"]["total"] - st["time_seconds"]["load"]
                        t = ti if t is None else min(t, ti)
                    small = out[:-4] + "_small.exr"
                    subprocess.run(["oiiotool", out, "--ch", "R,G,B", "--resize:filter=box", ref_res, "-o", small],
                                   check=True, capture_output=True)
                    rays = st["rays"]["camera"] + st["rays"]["bounce"]
                    runs.append({"rm": rel_mse(small, ref) - ref_rel, "m": mse(small, ref) - ref_mse, "rv": rel_var(out),
                                 "t": t, "rays": rays, "len": st["rays"]["bounce"] / st["rays"]["camera"]})
                rms = [r["rm"] for r in runs]
                rm, med, t = statistics.mean(rms), statistics.median(rms), statistics.mean(r["t"] for r in runs)
                row = {"ttuv": rm * t, "ttuv_med": med * t, "t": t, "rv": statistics.mean(r["rv"] for r in runs),
                       "ns": t / statistics.mean(r["rays"] for r in runs) * 1e9}
                if base is None:
                    base = row
                several = len(runs) > 1
                print("| %s | %s | %d | %s | %.4g | %s | %.4g | %.4g | %.4g | %.2f | %.2fx | %s | %.2fx | %.2fx | %.2f | %.2fx |" % (
                    name, res, spp, config, rm, "%.2g" % (statistics.stdev(rms) / math.sqrt(len(rms))) if several else "-",
                    med, statistics.mean(r["m"] for r in runs), row["rv"], t, row["ttuv"] / base["ttuv"],
                    "%.2fx" % (row["ttuv_med"] / base["ttuv_med"]) if several else "-", base["rv"] / row["rv"],
                    t / base["t"], statistics.mean(r["len"] for r in runs), row["ns"] / base["ns"]))
                sys.stdout.flush()


if __name__ == "__main__":
    main()
