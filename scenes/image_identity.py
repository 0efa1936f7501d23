#!/usr/bin/env python3
"""Bit-identity check between two candela binaries (for refactors that must not change images).

    python3 scenes/image_identity.py OLD_CANDELA NEW_CANDELA [--out DIR] [--res WxH] [--spp N]

Renders every scene below with every light sampler (and the cache point variants) with both
binaries at the same seed, then the EXTRA renders (volumes, guiding, progressive and BSDF-aware
cache points, a render resumed from a checkpoint), and compares the images' pixels bit for bit
(`build/tests/exr_same`: every channel, not the header's provenance, which names the build; byte
for byte when that program is absent). Generated scenes are used when
`python3 scenes/make_manylights.py` and `python3 scenes/make_volumes.py` have written them to
build/scenes/. Prints one line per render and exits non-zero if any pair differs or a render
fails.
"""
import argparse
import filecmp
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(ROOT, "..", "shared", "assets", "gltf")

SCENES = [
    os.path.join(ROOT, "scenes", "default.gltf"),
    os.path.join(SHARED, "cornell_lights.gltf"),
    os.path.join(SHARED, "cornell_area_only.gltf"),
    os.path.join(SHARED, "cornell_many_lights.gltf"),
    os.path.join(SHARED, "cornell_1k_lights.gltf"),
    os.path.join(ROOT, "tests", "scenes", "env_directions.gltf"),
    os.path.join(ROOT, "tests", "scenes", "masked_plane.gltf"),
    os.path.join(ROOT, "build", "scenes", "windows.gltf"),
    os.path.join(ROOT, "build", "scenes", "spotlights.gltf"),
    os.path.join(ROOT, "build", "scenes", "emissive_mesh.gltf"),
    os.path.join(ROOT, "build", "scenes", "city_1k.gltf"),
]

VARIANTS = [
    ("uniform", ["--light-sampler", "uniform"]),
    ("power", ["--light-sampler", "power"]),
    ("tree", ["--light-sampler", "tree"]),
    ("optimal", ["--light-sampler", "optimal"]),
    ("optimal-occl", ["--light-sampler", "optimal", "--optimal-occlusion"]),
    ("cachepoints", ["--light-sampler", "cachepoints"]),
    ("cachepoints-novis", ["--light-sampler", "cachepoints", "--no-visibility"]),
    ("cachepoints-linear", ["--light-sampler", "cachepoints", "--cachepoint-build", "linear"]),
]

VOLUMES = os.path.join(ROOT, "build", "scenes", "volumes")
# (name, scene, flags): what the light-sampler matrix does not reach. "@ckpt" in a variant's
# flags: render with --checkpoint, then again with --resume-from that checkpoint (the second
# image is the one compared)
EXTRA = [
    ("torch_mist", os.path.join(VOLUMES, "torch_mist.gltf"), []),
    ("camera_in_fog", os.path.join(VOLUMES, "camera_in_fog.gltf"), []),
    ("glass_absorb", os.path.join(VOLUMES, "glass_absorb.gltf"), []),
    ("cloud_point_env", os.path.join(VOLUMES, "cloud_point_env.gltf"), []),
    ("cloud_point_env-guided", os.path.join(VOLUMES, "cloud_point_env.gltf"), ["--guiding", "mis"]),
    ("rect_fog", os.path.join(ROOT, "tests", "scenes", "rect_fog.gltf"), []),
    ("shapes_mix", os.path.join(ROOT, "tests", "scenes", "shapes_mix.gltf"), []),
    ("cornell_indirect-mis", os.path.join(ROOT, "scenes", "cornell_indirect.gltf"), ["--guiding", "mis", "--spp", "24"]),
    ("cornell_indirect-ris", os.path.join(ROOT, "scenes", "cornell_indirect.gltf"), ["--guiding", "ris", "--spp", "24"]),
    ("cornell_indirect-auto", os.path.join(ROOT, "scenes", "cornell_indirect.gltf"), ["--guiding", "auto", "--spp", "24"]),
    ("guiding_interior-mis-ckpt", os.path.join(ROOT, "scenes", "guiding_interior.gltf"),
     ["--guiding", "mis", "--spp", "24", "@ckpt"]),
    ("default-progressive", os.path.join(ROOT, "scenes", "default.gltf"),
     ["--light-sampler", "cachepoints", "--cachepoint-progressive", "on", "--spp", "16"]),
    ("default-bsdf-off", os.path.join(ROOT, "scenes", "default.gltf"),
     ["--light-sampler", "cachepoints", "--cachepoint-bsdf", "off"]),
]


EXR_SAME = os.path.join(ROOT, "build", "tests", "exr_same")


def same_images(a, b):
    if os.access(EXR_SAME, os.X_OK):
        return subprocess.run([EXR_SAME, a, b], capture_output=True).returncode == 0
    return filecmp.cmp(a, b, shallow=False)


def render(binary, scene, flags, out, res, spp):
    if "@ckpt" in flags:
        flags = [f for f in flags if f != "@ckpt"]
        ckpt = out + ".ckpt"
        good, err = render(binary, scene, flags + ["--checkpoint", ckpt], out + ".first.exr", res, spp)
        if not good:
            return good, err
        return render(binary, scene, flags + ["--resume-from", ckpt], out, res, spp)
    cmd = [binary, "render", scene, "--res", res, "--spp", str(spp), "--seed", "7", "--quiet", "--no-png",
           "-o", out] + flags
    r = subprocess.run(cmd, capture_output=True, text=True)
    return r.returncode == 0, r.stderr.strip()


def compare(a, label, stem, scene, flags):
    """Renders scene with both binaries; prints one line; 1 when they differ or one failed."""
    outs = []
    ok = True
    for tag, binary in (("old", a.old), ("new", a.new)):
        out = os.path.join(a.out, f"{stem}-{tag}.exr")
        for f in (out, out + ".ckpt"):
            if os.path.exists(f):
                os.remove(f)
        good, err = render(binary, scene, flags, out, a.res, a.spp)
        if not good:
            print(f"FAIL   {label} ({tag}): {err}")
            ok = False
        outs.append(out)
    if ok and same_images(outs[0], outs[1]):
        print(f"same   {label}")
        return 0
    if ok:
        print(f"DIFFER {label}")
    return 1


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--out", default="/tmp/candela-identity")
    ap.add_argument("--res", default="96x72")
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--only", default="", help="comma-separated substrings of scene names")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    bad = 0
    total = 0
    for scene in SCENES:
        if not os.path.exists(scene):
            print(f"skip   {scene} (absent)")
            continue
        name = os.path.splitext(os.path.basename(scene))[0]
        if a.only and not any(s in name for s in a.only.split(",")):
            continue
        for vname, flags in VARIANTS:
            if vname.startswith("optimal") and "1k" in name:
                continue  # O(lights) per vertex: slow and adds nothing the other scenes do not test
            total += 1
            bad += compare(a, f"{name} {vname}", f"{name}-{vname}", scene, flags)
    for name, scene, flags in EXTRA:
        if not os.path.exists(scene):
            print(f"skip   {name} (absent)")
            continue
        if a.only and not any(s in name for s in a.only.split(",")):
            continue
        total += 1
        bad += compare(a, name, f"extra-{name}", scene, flags)
    print(f"{total - bad} of {total} renders identical")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
