#!/usr/bin/env python3
"""scenes/make_production.py: issue 28's production scene, a night city at the cache points
paper's Fig. 1 scale (4.9 million lights) with production geometry, as one .glb.

usage: make_production.py [-o OUT.glb] [--scale S]     (default build/scenes/production.glb, S 1)
       make_production.py [-o OUT.glb] --lights L --triangles T    (e.g. --lights 100k --triangles 10M)

Deterministic (fixed seeds, Mersenne Twister; nothing downloaded): running it twice writes
byte-identical files (the VDB's header UUID is written as a fixed one). Python 3's standard
library for everything but the fire's VDB, which needs Debian's python3-openvdb (module
pyopenvdb; .ci/setup installs it for /usr/bin/python3: when the python3 on PATH cannot import
it, the script re-runs itself with /usr/bin/python3, as make_volumes.py does).

Written next to OUT.glb: OUT_textures/tNNN.png (64x64 generated PNGs), OUT_fire.vdb (one
emissive fire, 32^3 voxels: density and emission grids), OUT_sky.exr (a dim night sky) and
OUT.counts.json (what the scene holds: lights by kind, triangles after instancing, instances,
textures, volumes, and the light count the renderer's statistics report: one light per
punctual light, per emissive primitive per instance (its triangles are sampled inside it),
per emissive volume, plus the environment). glTF 2.0, Y-up, metres, Blender light units
(cd, /683).

The scene: a grid of city blocks (40 m, streets of 14 m) with a camera at 1.7 m in a street near
the centre. --scale S makes round(256 S) blocks (1: 16 x 16, 0.1: 26, 0.01: 3) with the same
contents per block and max(minimum, round(full x S)) distinct meshes and textures, so every
count scales with S. Per block, at every scale:
  - 4 buildings (instances of the building meshes, 25-90 m tall: recessed windows with frames,
    mullions and sills, a ledge per floor, roof boxes and pipes; 4 textured primitives each),
    14 street trees (trunk, branches, 3,000 leaf cards), 40 props (lamp posts, benches, bins,
    bollards, cars), one textured ground tile;
  - emissive: 8 lit-window meshes on two facades of each building (42% of the windows lit,
    each lit pane 4 x 6 quads), one neon sign (letter strokes of thin boxes, an emissive
    texture), one string of bulbs across the street (octahedra): 10 emissive mesh instances
    of ~18,500 emissive triangles;
  - 1,200 punctual lights, plain nodes sharing 48 light records (io/README.md "Memory": the
    loader's bulk pass reads them): 16 street lamps (spots down), 40 shop-front spots, 144
    facade up-lights (spots), 700 lanterns in front of the facades and 300 path lights
    (points);
  - the whole city inside a box of homogeneous haze (candela_medium, 0.004/m scattering), and
    max(2, round(36 S)) fires (the VDB, with its emission grid) on braziers along the streets;
    a dim night sky (scene extras candela_environment).
At S = 1: 5,049,236 lights as the paper counts them (307,200 punctual: 256,000 points and
51,200 spots; 4,742,000 emissive triangles in 2,560 instances of 432 distinct emissive meshes;
36 fires), 309,797 lights as Candela counts them, 59.8 million triangles after instancing
(1.5 million distinct), 17,701 mesh instances, 300 textures; a 148 MB .glb, made in ~20 s.
At S = 0.01 (3 blocks): 52,898 lights (3,600 punctual), 0.69 million triangles, 5.8 MB.
--scale S writes the same bytes as before --lights and --triangles existed.

--lights L --triangles T (issue 28's scaling table; counts as 10000, 10k, 5M): L lights as the
paper counts them and T triangles after instancing, independently (one alone: the other at the
full scene's 11.85 triangles per light). The rule (plan_targets):
  - emissive triangles E = min(0.939 L, T / 2): the full scene's mix (93.9% of its lights are
    emissive triangles, 6.1% punctual) while the emissive triangles are at most half the
    triangles; past that (5M lights in 1M triangles: 4.7M emissive triangles cannot fit) the
    rest of the lights are punctual, so L holds and T holds;
  - B = max(1, round((T - E) / 215,143)) blocks: each block about the full scene's
    non-emissive geometry (ground tile and four buildings always; then up to 40 props and as
    many trees as fill the block's share of T);
  - emissive meshes per block in a fixed order (two lit facades per building, the sign, a
    string of bulbs, the other facades, up to 8 more strings), each placed while the emissive
    triangles stay within the blocks' share of E; lit-window panes subdivided s x s more when a
    block's share passes 80% of what its meshes hold at s = 1 (37,000; the full scene 18,523);
  - then P = L - E' - fires punctual lights (E' the emissive triangles placed), spread evenly
    over the blocks in the full scene's mix (lanterns, up-lights, shop spots, street lamps, path
    lights), so L is met exactly and T within half a mesh (a tree, ~6,000 triangles); E' is
    within half an emissive mesh of E (the mix drifts at small L: 10k lights in 1M triangles
    get 9,840 emissive triangles and 158 punctual lights, not 9,392 and 606);
  - the distinct meshes, textures and fires follow the blocks as --scale B / 256 would.
A warning on stderr when either count misses its target by more than 3%. Memory and time
grow with the punctual lights (nodes kept as their JSON, ~110 bytes each) and the distinct
triangles. Measured (a busy 2-core machine, CPU seconds beside the wall): 5M lights in 50M
triangles (211 blocks, 304k punctual lights) 51 s (9.6 s CPU), max RSS 348 MiB, a 128 MB .glb;
5M in 1M triangles (2 blocks, 4.48M punctual lights) 50 s (38 s CPU), 1.6 GiB, 473 MB.

stdout: one JSON line, OUT.counts.json's counts plus "output" (the path); with targets also
lights_target, triangles_target, emissive_capped (E was T / 2) and window_subdivision. The
summary line goes to stderr.
"""

import argparse
import array
import contextlib
import json
import math
import os
import random
import struct
import sys
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DEBIAN_PYTHON = '/usr/bin/python3'

try:
    import pyopenvdb as vdb
except ImportError as e:
    if (os.path.exists(DEBIAN_PYTHON)
            and os.path.realpath(sys.executable) != os.path.realpath(DEBIAN_PYTHON)):
        os.execv(DEBIAN_PYTHON, [DEBIAN_PYTHON] + sys.argv)
    sys.exit('make_production.py: %s (apt-get install python3-openvdb)' % e)

sys.path.insert(0, HERE)
from make_scenes import look_rotation, write_exr  # noqa: E402

BLOCK = 40.0          # block side, m
STREET = 14.0         # street width, m
FULL_BLOCKS = 256     # blocks at --scale 1
FIXED_UUID = b'00000000-0000-4000-8000-000000000028'  # the VDB header's UUID (determinism)

# distinct meshes and textures: (at scale 1, at least)
VARIANTS = {'building': (48, 2), 'tree': (12, 2), 'prop': (20, 5), 'ground': (16, 2),
            'window_pattern': (2, 1), 'sign': (32, 2), 'string': (16, 2), 'texture': (300, 12),
            'fire': (36, 2)}


# --lights / --triangles (plan_targets): the full scene's numbers (--scale 1, measured)
FULL_PUNCTUAL, FULL_EMISSIVE, FULL_TRIANGLES = 307200, 4742000, 59818620
EMISSIVE_SHARE = FULL_EMISSIVE / (FULL_PUNCTUAL + FULL_EMISSIVE)  # 0.939 of the non-volume lights
MAX_EMISSIVE_SHARE = 0.5      # of the triangles: at least half of them are the city the lights light
BLOCK_NON_EMISSIVE = 215143   # non-emissive triangles of a full-scene block ((59,818,620 - 4,742,000) / 256)
FACADE_EMISSIVE = 1940        # emissive triangles of a lit-window mesh (one facade) at subdivision 1, mean
SMALL_EMISSIVE = 1500         # ... of a neon sign or a string of bulbs (a block holds 1 sign and up to 9 strings)
TRIANGLES_PER_LIGHT = FULL_TRIANGLES / 5049236   # the full scene's ratio: a target given alone
# the full scene's punctual mix per block: lanterns, facade up-lights, shop spots, street lamps, path lights
PUNCTUAL_MIX = (('lantern', 700), ('uplight', 144), ('shop', 40), ('lamp', 16), ('path', 300))


def plan_targets(lights, triangles):
    """The rule for --lights L --triangles T (lights as the paper counts them): emissive
    triangles E = min(0.939 L, T / 2) (the full scene's mix, but at most half the triangles:
    a scene's lights need a city to light, and 5M lights in 1M triangles cannot be 4.7M
    emissive triangles), the other L - E lights punctual (less the fires); blocks
    B = max(1, round((T - E) / 215,143)) so that each block holds about the full scene's
    non-emissive geometry (four buildings and a ground tile always; props and trees fill the
    rest); lit-window panes subdivided s x s more, s the least for which a block's share of E
    is at most 80% of what its emissive meshes hold (16 facades, a sign and 9 strings:
    16 x 1,940 s^2 + 10 x 1,500; s = 1 up to 37,000 a block, the full scene's 18,523)."""
    emissive = EMISSIVE_SHARE * lights
    capped = emissive > MAX_EMISSIVE_SHARE * triangles
    emissive = min(emissive, MAX_EMISSIVE_SHARE * triangles)
    blocks = max(1, int(round((triangles - emissive) / BLOCK_NON_EMISSIVE)))
    sub = 1
    while emissive / blocks > 0.8 * (16 * FACADE_EMISSIVE * sub * sub + 10 * SMALL_EMISSIVE):
        sub += 1
    return {'blocks': blocks, 'emissive_triangles': int(round(emissive)), 'emissive_capped': capped,
            'window_subdivision': sub}


def variants(kind, scale):
    full, least = VARIANTS[kind]
    return max(least, min(full, int(round(full * scale))))


def r(x, digits=6):
    v = round(float(x), digits)
    return 0.0 if v == 0 else v


def rv(v, digits=6):
    return [r(c, digits) for c in v]


# ----------------------------------------------------------------------------------------------
# geometry: a primitive is flat-shaded triangles (positions, normals, uvs, indices)


class Prim:
    def __init__(self, material):
        self.material = material
        self.pos = array.array('f')
        self.nrm = array.array('f')
        self.uv = array.array('f')
        self.idx = array.array('I')

    @property
    def triangles(self):
        return len(self.idx) // 3

    def quad(self, p0, p1, p2, p3, uvs=((0, 0), (1, 0), (1, 1), (0, 1))):
        """p0..p3 counter-clockwise seen from the front (flat normal)."""
        ax, ay, az = p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]
        bx, by, bz = p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]
        nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        ln = math.sqrt(nx * nx + ny * ny + nz * nz) or 1.0
        base = len(self.pos) // 3
        for p, t in zip((p0, p1, p2, p3), uvs):
            self.pos.extend(p)
            self.nrm.extend((nx / ln, ny / ln, nz / ln))
            self.uv.extend(t)
        self.idx.extend((base, base + 1, base + 2, base, base + 2, base + 3))

    def tri(self, p0, p1, p2):
        ax, ay, az = p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]
        bx, by, bz = p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]
        nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        ln = math.sqrt(nx * nx + ny * ny + nz * nz) or 1.0
        base = len(self.pos) // 3
        for p, t in zip((p0, p1, p2), ((0, 0), (1, 0), (0.5, 1))):
            self.pos.extend(p)
            self.nrm.extend((nx / ln, ny / ln, nz / ln))
            self.uv.extend(t)
        self.idx.extend((base, base + 1, base + 2))

    def box(self, c, h, uv_scale=1.0):
        """Axis-aligned box, centre c, half extents h, faces outwards (12 triangles)."""
        x0, y0, z0 = c[0] - h[0], c[1] - h[1], c[2] - h[2]
        x1, y1, z1 = c[0] + h[0], c[1] + h[1], c[2] + h[2]
        u, v, w = 2 * h[0] * uv_scale, 2 * h[1] * uv_scale, 2 * h[2] * uv_scale
        self.quad((x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1), ((0, 0), (u, 0), (u, v), (0, v)))
        self.quad((x1, y0, z0), (x0, y0, z0), (x0, y1, z0), (x1, y1, z0), ((0, 0), (u, 0), (u, v), (0, v)))
        self.quad((x1, y0, z1), (x1, y0, z0), (x1, y1, z0), (x1, y1, z1), ((0, 0), (w, 0), (w, v), (0, v)))
        self.quad((x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0), ((0, 0), (w, 0), (w, v), (0, v)))
        self.quad((x0, y1, z1), (x1, y1, z1), (x1, y1, z0), (x0, y1, z0), ((0, 0), (u, 0), (u, w), (0, w)))
        self.quad((x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1), ((0, 0), (u, 0), (u, w), (0, w)))

    def cylinder(self, c, radius, height, segments, radius_top=None):
        rt = radius if radius_top is None else radius_top
        for k in range(segments):
            a0, a1 = 2 * math.pi * k / segments, 2 * math.pi * (k + 1) / segments
            p0 = (c[0] + radius * math.cos(a0), c[1], c[2] - radius * math.sin(a0))
            p1 = (c[0] + radius * math.cos(a1), c[1], c[2] - radius * math.sin(a1))
            p2 = (c[0] + rt * math.cos(a1), c[1] + height, c[2] - rt * math.sin(a1))
            p3 = (c[0] + rt * math.cos(a0), c[1] + height, c[2] - rt * math.sin(a0))
            self.quad(p0, p1, p2, p3, ((k / segments, 0), ((k + 1) / segments, 0), ((k + 1) / segments, 1), (k / segments, 1)))

    def octahedron(self, c, s):
        px, nx_ = (c[0] + s, c[1], c[2]), (c[0] - s, c[1], c[2])
        py, ny_ = (c[0], c[1] + s, c[2]), (c[0], c[1] - s, c[2])
        pz, nz_ = (c[0], c[1], c[2] + s), (c[0], c[1], c[2] - s)
        for a, b in ((px, pz), (pz, nx_), (nx_, nz_), (nz_, px)):
            self.tri(a, py, b)
            self.tri(b, ny_, a)


class Mesh:
    def __init__(self, name):
        self.name = name
        self.prims = []

    def prim(self, material):
        p = Prim(material)
        self.prims.append(p)
        return p

    @property
    def triangles(self):
        return sum(p.triangles for p in self.prims)


# ----------------------------------------------------------------------------------------------
# textures: 64x64 RGB PNGs (zlib + struct), a few procedural patterns


def png_bytes(w, h, rgb_rows):
    def chunk(tag, data):
        return struct.pack('>I', len(data)) + tag + data + struct.pack('>I', zlib.crc32(tag + data) & 0xffffffff)
    raw = b''.join(b'\x00' + bytes(row) for row in rgb_rows)
    return (b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, 8, 2, 0, 0, 0))
            + chunk(b'IDAT', zlib.compress(raw, 9)) + chunk(b'IEND', b''))


def texture(k, rng):
    """Texture k: one of bricks, planks, tiles, noise, stripes, leaves; colours from rng."""
    N = 64
    kind = k % 6
    base = [0.25 + 0.6 * rng.random() for _ in range(3)]
    alt = [c * (0.5 + 0.4 * rng.random()) for c in base]
    noise = [[rng.random() for _ in range(N)] for _ in range(N)]
    rows = []
    for y in range(N):
        row = bytearray()
        for x in range(N):
            if kind == 0:    # bricks
                off = 8 if (y // 8) % 2 else 0
                mortar = y % 8 == 0 or (x + off) % 16 == 0
                c = alt if mortar else base
            elif kind == 1:  # planks
                c = alt if x % 12 == 0 else base
            elif kind == 2:  # tiles
                c = alt if x % 16 == 0 or y % 16 == 0 else base
            elif kind == 3:  # noise
                c = base
            elif kind == 4:  # stripes
                c = alt if (x + y) % 16 < 6 else base
            else:            # leaves: blotches
                c = alt if noise[y][x] < 0.35 else base
            f = 0.85 + 0.3 * noise[y][x]
            row.extend(min(255, int(255 * min(1.0, ch * f))) for ch in c)
        rows.append(row)
    return png_bytes(N, N, rows)


# ----------------------------------------------------------------------------------------------
# the distinct meshes


def building_mesh(name, rng, mats, windows_out):
    """A building of 16 x H x 16 m (H 20-40; instances scale it), origin at its base centre:
    four facades of recessed windows (frame, reveal and a dark pane per window), a ledge per
    floor, roof boxes. Primitives: wall, frames, ledges and roof (4 materials). Records each
    facade's window rectangles in windows_out[face] for the lit-window meshes."""
    m = Mesh(name)
    wall, frame, ledge, roof = (m.prim(mt) for mt in mats)
    W = 8.0
    floors = rng.randrange(8, 17)
    fh = 3.4
    H = floors * fh + 1.0
    cols = 8
    cw = 2 * W / cols
    depth = 0.25
    for face in range(4):
        # facade frame: local (u along the facade, v up, out of the facade)
        def P(u, v, d, face=face):
            # u in [-W, W], v up, d outwards distance from the wall plane
            if face == 0:
                return (u, v, W + d)
            if face == 1:
                return (-u, v, -W - d)
            if face == 2:
                return (W + d, v, -u)
            return (-W - d, v, u)
        rects = []
        for fl in range(floors):
            v0, v1 = 1.0 + fl * fh, 1.0 + (fl + 1) * fh
            wv0, wv1 = v0 + 0.9, v1 - 0.5
            for cl in range(cols):
                u0, u1 = -W + cl * cw, -W + (cl + 1) * cw
                wu0, wu1 = u0 + 0.35, u1 - 0.35
                # wall around the window opening
                wall.quad(P(u0, v0, 0), P(u1, v0, 0), P(u1, wv0, 0), P(u0, wv0, 0))
                wall.quad(P(u0, wv1, 0), P(u1, wv1, 0), P(u1, v1, 0), P(u0, v1, 0))
                wall.quad(P(u0, wv0, 0), P(wu0, wv0, 0), P(wu0, wv1, 0), P(u0, wv1, 0))
                wall.quad(P(wu1, wv0, 0), P(u1, wv0, 0), P(u1, wv1, 0), P(wu1, wv1, 0))
                # reveal (the recess's four sides) and the pane at its back
                frame.quad(P(wu0, wv0, 0), P(wu0, wv0, -depth), P(wu1, wv0, -depth), P(wu1, wv0, 0))
                frame.quad(P(wu1, wv1, 0), P(wu1, wv1, -depth), P(wu0, wv1, -depth), P(wu0, wv1, 0))
                frame.quad(P(wu0, wv1, 0), P(wu0, wv1, -depth), P(wu0, wv0, -depth), P(wu0, wv0, 0))
                frame.quad(P(wu1, wv0, 0), P(wu1, wv0, -depth), P(wu1, wv1, -depth), P(wu1, wv1, 0))
                frame.quad(P(wu0, wv0, -depth), P(wu0, wv1, -depth), P(wu1, wv1, -depth), P(wu1, wv0, -depth))
                # mullion and sill
                mu = 0.5 * (wu0 + wu1)
                for (a0, a1, b0, b1, d0) in ((mu - 0.04, mu + 0.04, wv0, wv1, -depth + 0.06),
                                             (wu0 - 0.1, wu1 + 0.1, wv0 - 0.12, wv0, 0.12)):
                    frame.quad(P(a0, b0, d0), P(a1, b0, d0), P(a1, b1, d0), P(a0, b1, d0))
                    frame.quad(P(a0, b1, d0), P(a1, b1, d0), P(a1, b1, -depth), P(a0, b1, -depth))
                rects.append((wu0, wv0, wu1, wv1))
            # a ledge per floor
            ledge.quad(P(-W, v1 - 0.1, 0.3), P(W, v1 - 0.1, 0.3), P(W, v1 + 0.1, 0.3), P(-W, v1 + 0.1, 0.3))
            ledge.quad(P(-W, v1 + 0.1, 0.3), P(W, v1 + 0.1, 0.3), P(W, v1 + 0.1, 0), P(-W, v1 + 0.1, 0))
            ledge.quad(P(-W, v1 - 0.1, 0), P(W, v1 - 0.1, 0), P(W, v1 - 0.1, 0.3), P(-W, v1 - 0.1, 0.3))
        # ground floor band and parapet
        wall.quad(P(-W, 0, 0), P(W, 0, 0), P(W, 1.0, 0), P(-W, 1.0, 0))
        wall.quad(P(-W, H - 0.0, 0), P(W, H, 0), P(W, H + 1.0, 0), P(-W, H + 1.0, 0))
        windows_out[face] = (rects, P)
    roof.quad((-W, H, W), (W, H, W), (W, H, -W), (-W, H, -W))
    for _ in range(rng.randrange(20, 40)):
        c = (rng.uniform(-W + 1.5, W - 1.5), H + 0.6, rng.uniform(-W + 1.5, W - 1.5))
        roof.box(c, (rng.uniform(0.4, 1.4), rng.uniform(0.3, 0.9), rng.uniform(0.4, 1.4)))
        roof.cylinder((c[0], H, c[2] + 1.6), 0.15, 2.0, 12)
    return m, H


def window_mesh(name, rng, material, windows, lit_fraction, sub=1):
    """Lit windows of one facade: each lit pane 4 sub x 6 sub quads (48 sub^2 emissive
    triangles), 6 cm in front of the recessed pane, facing out. sub > 1 only with --lights /
    --triangles targets whose emissive triangles are denser than the full scene's per block."""
    rects, P = windows
    m = Mesh(name)
    p = m.prim(material)
    d = -0.25 + 0.06
    nu, nv = 4 * sub, 6 * sub
    for (u0, v0, u1, v1) in rects:
        if rng.random() >= lit_fraction:
            continue
        for i in range(nu):
            for j in range(nv):
                a0, a1 = u0 + (u1 - u0) * i / nu, u0 + (u1 - u0) * (i + 1) / nu
                b0, b1 = v0 + (v1 - v0) * j / nv, v0 + (v1 - v0) * (j + 1) / nv
                p.quad(P(a0, b0, d), P(a1, b0, d), P(a1, b1, d), P(a0, b1, d),
                       ((i / nu, j / nv), ((i + 1) / nu, j / nv), ((i + 1) / nu, (j + 1) / nv), (i / nu, (j + 1) / nv)))
    return m


def tree_mesh(name, rng, mats):
    """A street tree: trunk, 8 branches (tapered cylinders), ~1,600 leaf cards."""
    m = Mesh(name)
    bark, leaves_a, leaves_b = (m.prim(mt) for mt in mats)
    h = rng.uniform(4.0, 7.0)
    bark.cylinder((0, 0, 0), 0.22, h, 16, 0.12)
    crown = (0.0, h + 0.8, 0.0)
    for k in range(8):
        a = 2 * math.pi * k / 8 + rng.random() * 0.5
        bark.cylinder((0, h * rng.uniform(0.55, 0.9), 0), 0.08, 1.8, 8, 0.03)
    R = rng.uniform(2.0, 3.0)
    for k in range(3000):
        # a card in a random orientation, on an ellipsoidal crown
        u, v, w = rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 1)
        n = math.sqrt(u * u + v * v + w * w) or 1.0
        s = R * rng.random() ** 0.3
        c = (crown[0] + s * u / n, crown[1] + 0.8 * s * v / n, crown[2] + s * w / n)
        a = rng.random() * 2 * math.pi
        e = 0.12
        dx, dz = e * math.cos(a), e * math.sin(a)
        p = leaves_a if k % 2 else leaves_b
        p.quad((c[0] - dx, c[1] - e, c[2] - dz), (c[0] + dx, c[1] - e, c[2] + dz),
               (c[0] + dx, c[1] + e, c[2] + dz), (c[0] - dx, c[1] + e, c[2] - dz))
    return m


def prop_mesh(name, kind, rng, mats):
    """Street furniture, origin at its foot: lamp post, bench, bin, bollard or car."""
    m = Mesh(name)
    a, b, c = (m.prim(mt) for mt in mats)
    if kind == 0:    # lamp post: pole, arm, head
        a.cylinder((0, 0, 0), 0.12, 7.0, 24, 0.08)
        b.box((0.6, 7.0, 0), (0.7, 0.05, 0.05))
        c.cylinder((1.2, 6.7, 0), 0.3, 0.3, 32, 0.05)
        for k in range(40):
            a.cylinder((0, 0.2 + 0.15 * k, 0), 0.14, 0.05, 24)
    elif kind == 1:  # bench: slats, legs, bolts
        for k in range(12):
            a.box((0, 0.45, -0.3 + 0.055 * k), (1.0, 0.02, 0.022))
        for k in range(6):
            a.box((0, 0.6 + 0.07 * k, 0.35), (1.0, 0.025, 0.02))
        for x in (-0.9, 0.0, 0.9):
            b.box((x, 0.22, 0), (0.04, 0.22, 0.3))
        for k in range(60):
            c.cylinder((-0.95 + 0.032 * k, 0.47, 0.3), 0.01, 0.02, 8)
    elif kind == 2:  # bin with ribs
        a.cylinder((0, 0, 0), 0.3, 0.9, 48)
        for k in range(48):
            ang = 2 * math.pi * k / 48
            b.box((0.31 * math.cos(ang), 0.45, 0.31 * math.sin(ang)), (0.015, 0.45, 0.015))
        c.cylinder((0, 0.9, 0), 0.32, 0.05, 48, 0.0)
    elif kind == 3:  # bollard
        a.cylinder((0, 0, 0), 0.1, 0.9, 32, 0.09)
        b.cylinder((0, 0.9, 0), 0.09, 0.08, 32, 0.0)
        for k in range(10):
            c.cylinder((0, 0.1 + 0.07 * k, 0), 0.105, 0.02, 32)
    else:            # car: body, cabin, wheels with spokes
        a.box((0, 0.6, 0), (0.9, 0.3, 2.2))
        a.box((0, 1.05, -0.2), (0.8, 0.25, 1.1))
        for (x, z) in ((-0.9, -1.4), (0.9, -1.4), (-0.9, 1.4), (0.9, 1.4)):
            for k in range(16):
                ang = 2 * math.pi * k / 16
                b.box((x, 0.35 + 0.25 * math.sin(ang), z + 0.25 * math.cos(ang)), (0.12, 0.06, 0.06))
            for k in range(24):
                c.cylinder((x, 0.35, z), 0.05 + 0.01 * k, 0.01, 24)
    return m


def ground_mesh(name, mats):
    """A block's ground tile (block plus half the streets around it), origin at its centre:
    sidewalk (raised 15 cm, curbs) and asphalt, subdivided 2 m."""
    m = Mesh(name)
    walk, road = (m.prim(mt) for mt in mats)
    half = BLOCK / 2 + STREET / 2
    n = int(2 * half / 2.0)
    step = 2 * half / n
    for i in range(n):
        for j in range(n):
            x0, z0 = -half + i * step, -half + j * step
            x1, z1 = x0 + step, z0 + step
            inside = max(abs(x0 + step / 2), abs(z0 + step / 2)) < BLOCK / 2
            p, y = (walk, 0.15) if inside else (road, 0.0)
            p.quad((x0, y, z1), (x1, y, z1), (x1, y, z0), (x0, y, z0),
                   ((0, 0), (step / 4, 0), (step / 4, step / 4), (0, step / 4)))
    b = BLOCK / 2
    for (p0, p1) in (((-b, b), (b, b)), ((b, b), (b, -b)), ((b, -b), (-b, -b)), ((-b, -b), (-b, b))):
        walk.quad((p0[0], 0.0, p0[1]), (p1[0], 0.0, p1[1]), (p1[0], 0.15, p1[1]), (p0[0], 0.15, p0[1]))
    return m


def sign_mesh(name, rng, material):
    """A neon sign, 6 x 1.5 m in the x-y plane facing +z: 8 letters of thin emissive strokes,
    each stroke a box of 0.12 m subdivided along its length (~1,100 triangles)."""
    m = Mesh(name)
    p = m.prim(material)
    for letter in range(8):
        x0 = -3.0 + 0.75 * letter + 0.1
        for _ in range(rng.randrange(3, 6)):
            horizontal = rng.random() < 0.5
            if horizontal:
                y = rng.choice((0.15, 0.75, 1.35))
                a, b = (x0, y), (x0 + 0.55, y)
            else:
                x = x0 + rng.choice((0.0, 0.275, 0.55))
                a, b = (x, 0.15), (x, 1.35)
            segs = 4
            for k in range(segs):
                ta, tb = k / segs, (k + 1) / segs
                pa = (a[0] + (b[0] - a[0]) * ta, a[1] + (b[1] - a[1]) * ta)
                pb = (a[0] + (b[0] - a[0]) * tb, a[1] + (b[1] - a[1]) * tb)
                c = ((pa[0] + pb[0]) / 2, (pa[1] + pb[1]) / 2, 0.1)
                hx = abs(pb[0] - pa[0]) / 2 + 0.06
                hy = abs(pb[1] - pa[1]) / 2 + 0.06
                p.box(c, (hx, hy, 0.06))
    return m


def string_mesh(name, rng, material, span):
    """A string of bulbs sagging across a street of `span` m along x, 0.35 m apart: each bulb
    an octahedron subdivided into 4 rings (32 triangles)."""
    m = Mesh(name)
    p = m.prim(material)
    n = int(span / 0.35)
    sag = rng.uniform(0.6, 1.4)
    for k in range(n + 1):
        t = k / n
        c = (-span / 2 + span * t, -sag * 4 * t * (1 - t), 0.0)
        s = 0.05
        p.octahedron(c, s)
        p.octahedron((c[0], c[1] - 0.06, c[2]), s * 0.7)
        p.octahedron((c[0], c[1] - 0.1, c[2]), s * 0.5)
        p.octahedron((c[0], c[1] - 0.13, c[2]), s * 0.3)
    return m


def haze_mesh(name, material, half, height):
    """A closed box (inward and outward faces alike: a medium boundary is invisible)."""
    m = Mesh(name)
    m.prim(material).box((0.0, height / 2 - 1.0, 0.0), (half, height / 2, half))
    return m


# ----------------------------------------------------------------------------------------------
# the fire VDB


def write_fire_vdb(path):
    """A 1 m fire, 32^3 voxels of 1/32 m centred on x, z, from y = 0 up: density a flame-shaped
    blob (0..0.6) and emission (0..1) in its hot core. Deterministic (no random numbers)."""
    n = 32
    dens = vdb.FloatGrid(0.0)
    emis = vdb.FloatGrid(0.0)
    da, ea = dens.getAccessor(), emis.getAccessor()
    for i in range(n):
        for j in range(n):
            for k in range(n):
                x, y, z = (i + 0.5) / n - 0.5, (j + 0.5) / n, (k + 0.5) / n - 0.5
                # a flame narrowing upwards and wavering with height
                cx = 0.06 * math.sin(7.0 * y)
                cz = 0.05 * math.cos(5.0 * y)
                rad = 0.32 * (1.0 - y) ** 0.8 + 0.02
                d = math.sqrt((x - cx) ** 2 + (z - cz) ** 2) / rad
                if d >= 1.0 or y > 0.95:
                    continue
                flick = 0.75 + 0.25 * math.sin(23.0 * y + 11.0 * x) * math.cos(17.0 * z + 5.0 * y)
                rho = 0.6 * (1.0 - d * d) * flick
                if rho > 0.005:
                    da.setValueOn((i, j, k), rho)
                e = (1.0 - d) ** 2 * (1.0 - y) * flick
                if e > 0.01:
                    ea.setValueOn((i, j, k), min(1.0, 1.5 * e))
    xf = vdb.createLinearTransform([[1.0 / n, 0, 0, 0], [0, 1.0 / n, 0, 0], [0, 0, 1.0 / n, 0],
                                    [-0.5 + 0.5 / n, 0.5 / n, -0.5 + 0.5 / n, 1]])
    for g, nm in ((dens, 'density'), (emis, 'emission')):
        g.name = nm
        g.gridClass = vdb.GridClass.FOG_VOLUME
        g.transform = xf
    tmp = path + '.tmp'
    vdb.write(tmp, grids=[dens, emis])
    with open(tmp, 'r+b') as fh:   # OpenVDB writes a fresh UUID at bytes 21..56: fix it
        head = fh.read(57)
        if len(head) == 57 and head[:4] == b' BDV':
            fh.seek(21)
            fh.write(FIXED_UUID)
    os.replace(tmp, path)


# ----------------------------------------------------------------------------------------------
# the glTF document


class Doc:
    def __init__(self):
        self.bin = bytearray()
        self.doc = {'asset': {'version': '2.0', 'generator': 'candela scenes/make_production.py'},
                    'extensionsUsed': ['KHR_lights_punctual', 'KHR_materials_emissive_strength'],
                    'scene': 0, 'scenes': [{'nodes': []}], 'nodes': [], 'meshes': [],
                    'materials': [], 'textures': [], 'images': [], 'samplers': [
                        {'magFilter': 9729, 'minFilter': 9729, 'wrapS': 10497, 'wrapT': 10497}],
                    'accessors': [], 'bufferViews': [], 'buffers': [], 'cameras': []}
        self.lights = []
        self.light_nodes = []  # the punctual light nodes, as their JSON (bytes): compact at millions
        self.mesh_index = {}
        self.mesh_info = []   # per glTF mesh: (triangles, emissive primitives, emissive triangles)

    def view(self, data, target):
        while len(self.bin) % 4:
            self.bin.append(0)
        self.doc['bufferViews'].append({'buffer': 0, 'byteOffset': len(self.bin), 'byteLength': len(data),
                                        'target': target})
        self.bin.extend(data)
        return len(self.doc['bufferViews']) - 1

    def accessor(self, arr, ncomp, ctype, target, bounds=False):
        if sys.byteorder != 'little':
            arr = array.array(arr.typecode, arr)
            arr.byteswap()
        v = self.view(arr.tobytes(), target)
        count = len(arr) // ncomp
        a = {'bufferView': v, 'componentType': ctype, 'count': count,
             'type': {1: 'SCALAR', 2: 'VEC2', 3: 'VEC3'}[ncomp]}
        if bounds:
            a['min'] = [min(arr[c::ncomp]) for c in range(ncomp)]
            a['max'] = [max(arr[c::ncomp]) for c in range(ncomp)]
        self.doc['accessors'].append(a)
        return len(self.doc['accessors']) - 1

    def add_mesh(self, mesh, emissive_materials):
        prims = []
        tris = etris = eprims = 0
        for p in mesh.prims:
            if p.triangles == 0:
                continue
            prims.append({'attributes': {
                'POSITION': self.accessor(p.pos, 3, 5126, 34962, bounds=True),
                'NORMAL': self.accessor(p.nrm, 3, 5126, 34962),
                'TEXCOORD_0': self.accessor(p.uv, 2, 5126, 34962)},
                'indices': self.accessor(p.idx, 1, 5125, 34963), 'material': p.material})
            tris += p.triangles
            if p.material in emissive_materials:
                eprims += 1
                etris += p.triangles
        self.doc['meshes'].append({'name': mesh.name, 'primitives': prims})
        self.mesh_info.append((tris, eprims, etris))
        return len(self.doc['meshes']) - 1

    def node(self, node):
        self.doc['nodes'].append(node)
        self.doc['scenes'][0]['nodes'].append(len(self.doc['nodes']) - 1)

    def write(self, path):
        """The .glb: the nodes are self.doc's followed by self.light_nodes. The two node lists
        are spliced into json.dumps's output (as json.dumps would write them) so that millions
        of light nodes are never a list of dicts."""
        doc = dict(self.doc)
        doc['extensions'] = {'KHR_lights_punctual': {'lights': self.lights}}
        doc['buffers'] = [{'byteLength': len(self.bin)}]
        n_nodes = len(self.doc['nodes']) + len(self.light_nodes)
        assert self.doc['scenes'][0]['nodes'] == list(range(len(self.doc['nodes'])))
        doc['nodes'] = '@NODES@'
        doc['scenes'] = [dict(self.doc['scenes'][0], nodes='@SCENE_NODES@')]
        head = json.dumps(doc, separators=(',', ':')).encode('utf-8')
        a, rest = head.split(b'"@SCENE_NODES@"')
        b, c = rest.split(b'"@NODES@"')
        nodes = [json.dumps(n, separators=(',', ':')).encode('utf-8') for n in self.doc['nodes']]
        nodes.extend(self.light_nodes)
        js = b''.join((a, b'[', ','.join(map(str, range(n_nodes))).encode('ascii'), b']', b,
                       b'[', b','.join(nodes), b']', c))
        del nodes
        js += b' ' * (-len(js) % 4)
        while len(self.bin) % 4:
            self.bin.append(0)
        total = 12 + 8 + len(js) + 8 + len(self.bin)
        tmp = path + '.tmp'
        with open(tmp, 'wb') as fh:
            fh.write(struct.pack('<III', 0x46546C67, 2, total))
            fh.write(struct.pack('<II', len(js), 0x4E4F534A))
            fh.write(js)
            fh.write(struct.pack('<II', len(self.bin), 0x004E4942))
            fh.write(self.bin)
        os.replace(tmp, path)


def material(doc, name, tex=None, base=(1.0, 1.0, 1.0), roughness=0.8, metallic=0.0, emissive=None,
             strength=1.0, emissive_tex=None, double_sided=False, extras=None):
    pbr = {'baseColorFactor': rv(tuple(base) + (1.0,)), 'metallicFactor': r(metallic), 'roughnessFactor': r(roughness)}
    if tex is not None:
        pbr['baseColorTexture'] = {'index': tex}
    m = {'name': name, 'pbrMetallicRoughness': pbr}
    if emissive is not None:
        m['emissiveFactor'] = rv(emissive)
        if strength != 1.0:
            m['extensions'] = {'KHR_materials_emissive_strength': {'emissiveStrength': r(strength)}}
        if emissive_tex is not None:
            m['emissiveTexture'] = {'index': emissive_tex}
    if double_sided:
        m['doubleSided'] = True
    if extras:
        m['extras'] = extras
    doc.doc['materials'].append(m)
    return len(doc.doc['materials']) - 1


def translate_node(mesh, t, s=None, q=None):
    n = {'mesh': mesh, 'translation': rv(t, 4)}
    if q is not None:
        n['rotation'] = rv(q, 7)
    if s is not None:
        n['scale'] = rv(s, 4)
    return n


def yrot(a):
    return (0.0, math.sin(a / 2), 0.0, math.cos(a / 2))


# ----------------------------------------------------------------------------------------------


def build(out, scale, targets=None):
    """Writes the scene; targets (lights, triangles) instead of scale: plan_targets's rule."""
    stem = os.path.splitext(out)[0]
    folder = os.path.dirname(os.path.abspath(out))
    base = os.path.basename(stem)
    os.makedirs(folder, exist_ok=True)
    rng = random.Random(28)
    d = Doc()

    sub = 1
    if targets:
        plan = plan_targets(*targets)
        n_blocks, sub = plan['blocks'], plan['window_subdivision']
        scale = n_blocks / FULL_BLOCKS   # the distinct meshes, textures and fires follow the blocks
    else:
        n_blocks = max(1, int(round(FULL_BLOCKS * scale)))
    nx = int(math.ceil(math.sqrt(n_blocks)))
    nz = int(math.ceil(n_blocks / nx))
    pitch = BLOCK + STREET

    # textures and their materials
    n_tex = variants('texture', scale)
    tex_dir = base + '_textures'
    os.makedirs(os.path.join(folder, tex_dir), exist_ok=True)
    trng = random.Random(1)
    for k in range(n_tex):
        uri = '%s/t%03d.png' % (tex_dir, k)
        data = texture(k, trng)
        with open(os.path.join(folder, uri), 'wb') as fh:
            fh.write(data)
        d.doc['images'].append({'uri': uri})
        d.doc['textures'].append({'sampler': 0, 'source': k})
    tex_mats = [material(d, 'tex%03d' % k, tex=k, roughness=0.5 + 0.5 * trng.random(),
                         metallic=1.0 if k % 17 == 5 else 0.0) for k in range(n_tex)]
    next_mat = [0]

    def mats(n):
        out_ = []
        for _ in range(n):
            out_.append(tex_mats[next_mat[0] % n_tex])
            next_mat[0] += 1
        return out_

    emissive = set()

    def emissive_material(name, colour, strength, tex=None, double_sided=False):
        mi = material(d, name, base=(0.05, 0.05, 0.05), emissive=colour, strength=strength,
                      emissive_tex=tex, double_sided=double_sided)
        emissive.add(mi)
        return mi

    # distinct meshes
    grng = random.Random(2)
    buildings = []   # (mesh, height, [window meshes per face][pattern])
    n_pat = variants('window_pattern', scale)
    for k in range(variants('building', scale)):
        wins = [None] * 4
        bm, h = building_mesh('building%02d' % k, grng, mats(4), wins)
        bi = d.add_mesh(bm, emissive)
        warm = grng.random() < 0.7
        colour = (1.0, 0.72, 0.42) if warm else (0.75, 0.85, 1.0)
        wm = emissive_material('windows%02d' % k, colour, 2.0 + 3.0 * grng.random())
        per_face = []
        for face in range(4):
            pats = []
            for p in range(n_pat):
                pats.append(d.add_mesh(window_mesh('windows%02d_%d_%d' % (k, face, p), grng, wm, wins[face], 0.42, sub), emissive))
            per_face.append(pats)
        buildings.append((bi, h, per_face))
    trees = [d.add_mesh(tree_mesh('tree%02d' % k, grng, mats(3)), emissive) for k in range(variants('tree', scale))]
    props = [(k % 5, d.add_mesh(prop_mesh('prop%02d' % k, k % 5, grng, mats(3)), emissive))
             for k in range(variants('prop', scale))]
    grounds = [d.add_mesh(ground_mesh('ground%02d' % k, mats(2)), emissive) for k in range(variants('ground', scale))]
    signs = []
    for k in range(variants('sign', scale)):
        hue = [(1.0, 0.2, 0.5), (0.2, 0.8, 1.0), (1.0, 0.5, 0.1), (0.4, 1.0, 0.3)][k % 4]
        sm = emissive_material('neon%02d' % k, hue, 6.0, tex=k % n_tex)
        signs.append(d.add_mesh(sign_mesh('sign%02d' % k, grng, sm), emissive))
    bulb = emissive_material('bulbs', (1.0, 0.8, 0.5), 8.0, double_sided=True)
    strings = [d.add_mesh(string_mesh('string%02d' % k, grng, bulb, STREET + 2.0), emissive)
               for k in range(variants('string', scale))]
    brazier = Mesh('brazier')
    iron = mats(1)[0]
    bp = brazier.prim(iron)
    bp.cylinder((0, 0, 0), 0.05, 0.8, 12)
    bp.cylinder((0, 0.8, 0), 0.25, 0.3, 32, 0.45)
    brazier_mesh = d.add_mesh(brazier, emissive)
    haze_mat = material(d, 'haze_boundary', base=(0.5, 0.5, 0.5), extras={'candela_medium': {
        'sigma_a': [0.0005, 0.0005, 0.0005], 'sigma_s': [0.004, 0.004, 0.0045], 'anisotropy': 0.5}})
    span_x, span_z = nx * pitch, nz * pitch
    haze_half = max(span_x, span_z) / 2 + 20.0
    haze = d.add_mesh(haze_mesh('haze', haze_mat, haze_half, 90.0), emissive)

    # shared light records: 8 street-lamp spots, 8 shop spots, 8 up-lights, 16 lanterns, 8 path lights
    def light(kind, intensity, colour, inner=None, outer=None):
        lt = {'type': kind, 'color': rv(colour), 'intensity': r(intensity)}
        if kind == 'spot':
            lt['spot'] = {'innerConeAngle': r(inner), 'outerConeAngle': r(outer)}
        d.lights.append(lt)
        return len(d.lights) - 1
    lrng = random.Random(3)
    lamp = [light('spot', 4000 + 2000 * lrng.random(), (1.0, 0.82, 0.55), 0.5, 0.9) for _ in range(8)]
    shop = [light('spot', 800 + 800 * lrng.random(), (1.0, 0.9, 0.75), 0.3, 0.6) for _ in range(8)]
    uplt = [light('spot', 300 + 300 * lrng.random(), (0.7 + 0.3 * lrng.random(), 0.8, 1.0), 0.15, 0.3) for _ in range(8)]
    lantern = [light('point', 30 + 60 * lrng.random(), (1.0, 0.7 + 0.2 * lrng.random(), 0.45)) for _ in range(16)]
    path = [light('point', 20 + 20 * lrng.random(), (0.9, 0.9, 1.0)) for _ in range(8)]
    down = look_rotation((0.0, -1.0, 0.0), up_hint=(0.0, 0.0, -1.0))
    up = look_rotation((0.0, 1.0, 0.0), up_hint=(0.0, 0.0, -1.0))
    lights_nodes = []

    def light_node(li, t, q=None):
        # the node's JSON as json.dumps writes {'translation', 'rotation', 'extensions'}
        # (float repr), kept as bytes: 4.5 million of them as dicts would take ~4 GB
        n = '{"translation":[%r,%r,%r]' % tuple(rv(t, 3))
        if q is not None:
            n += ',"rotation":[%r,%r,%r,%r]' % tuple(rv(q, 6))
        lights_nodes.append((n + ',"extensions":{"KHR_lights_punctual":{"light":%d}}}' % li).encode('ascii'))

    counts = {'punctual_lights': 0, 'point_lights': 0, 'spot_lights': 0, 'emissive_instances': 0,
              'emissive_triangles': 0, 'emissive_primitive_instances': 0, 'triangles': 0,
              'instances': 0, 'volumes': 0}
    mesh_nodes = []

    def place(mesh, t, s=None, q=None):
        mesh_nodes.append(translate_node(mesh, t, s, q))
        tris, eprims, etris = d.mesh_info[mesh]
        counts['instances'] += 1
        counts['triangles'] += tris
        counts['emissive_triangles'] += etris
        counts['emissive_primitive_instances'] += eprims
        if eprims:
            counts['emissive_instances'] += 1

    brng = random.Random(4)
    x_origin = -(nx - 1) * pitch / 2
    z_origin = -(nz - 1) * pitch / 2
    block_centres = []

    def place_building(bx, bz, lot):
        """One of a block's four buildings on its 20 m lot, facing a street (both kinds of
        scene draw these numbers in this order)."""
        cx = bx + (-10.0 if lot % 2 == 0 else 10.0)
        cz = bz + (-10.0 if lot < 2 else 10.0)
        bi, h, per_face = buildings[brng.randrange(len(buildings))]
        sy = brng.uniform(0.9, 1.6)
        a = (math.pi / 2) * brng.randrange(4)
        q = yrot(a)
        place(bi, (cx, 0.15, cz), (1.0, sy, 1.0), q)
        return cx, cz, a, q, sy, h, per_face

    def blocks_to_targets(lights_target, triangles_target):
        """The blocks of a --lights/--triangles scene (plan_targets's rule): each block's
        ground and four buildings, then its emissive meshes, props and trees, each kind placed
        while the running total stays within the target's share of the blocks so far (error
        diffusion: the emissive triangles and the triangles end within half a mesh of their
        targets); then, over the blocks evenly, the punctual lights that make up the light
        count exactly (what the emissive meshes and the fires leave)."""
        n_fire = variants('fire', scale)
        lights_free = max(0, lights_target - n_fire)          # lights other than the fires
        emissive_goal = min(plan['emissive_triangles'], lights_free)
        tris_goal = (triangles_target - d.mesh_info[haze][0]
                     - n_fire * d.mesh_info[brazier_mesh][0])  # placed after the blocks
        weights = [w for _, w in PUNCTUAL_MIX]
        total_w = sum(weights)
        edge = BLOCK / 2 - 1.2
        block_lots = []

        def around(cx, cz, a, local):
            ca, sa = math.cos(a), math.sin(a)
            return cx + ca * local[0] + sa * local[1], cz - sa * local[0] + ca * local[1]

        for b in range(n_blocks):
            bx, bz = x_origin + (b % nx) * pitch, z_origin + (b // nx) * pitch
            block_centres.append((bx, bz))
            share = (b + 1) / n_blocks
            place(grounds[brng.randrange(len(grounds))], (bx, 0.0, bz))
            lots = []
            for lot in range(4):
                cx, cz, a, q, sy, h, per_face = place_building(bx, bz, lot)
                lots.append((cx, cz, a, q, sy, h, per_face, brng.sample(range(4), 4)))
            # emissive meshes, in the order they light up: two facades of each building (the
            # full scene's), the sign, the string of bulbs, the other two facades, more strings
            e_goal = emissive_goal * share
            slots = ([('facade', lot, 0) for lot in range(4)] + [('facade', lot, 1) for lot in range(4)]
                     + [('sign',), ('string',)] + [('facade', lot, 2) for lot in range(4)]
                     + [('facade', lot, 3) for lot in range(4)] + [('string',)] * 8)
            for slot in slots:
                if slot[0] == 'facade':
                    cx, cz, a, q, sy, h, per_face, faces = lots[slot[1]]
                    f = faces[slot[2]]
                    mesh = per_face[f][brng.randrange(len(per_face[f]))]
                    args = ((cx, 0.15, cz), (1.0, sy, 1.0), q)
                elif slot[0] == 'sign':
                    mesh = signs[brng.randrange(len(signs))]
                    args = ((bx + brng.uniform(-12, 12), brng.uniform(4.0, 6.0), bz + BLOCK / 2 - 1.0),)
                else:
                    mesh = strings[brng.randrange(len(strings))]
                    args = ((bx + BLOCK / 2 + STREET / 2, 6.0, bz + brng.uniform(-15, 15)), None, yrot(0.0))
                if counts['emissive_triangles'] + d.mesh_info[mesh][2] / 2 <= e_goal:
                    place(mesh, *args)
            # props (at most the full scene's 40), then trees, while the triangles fit
            t_goal = tris_goal * share
            for k in range(40):
                side = k % 4
                t = brng.uniform(-edge, edge)
                kind, pm = props[brng.randrange(len(props))]
                if counts['triangles'] + d.mesh_info[pm][0] / 2 > t_goal:
                    continue
                if kind == 4:   # cars park in the street
                    p = [(t, edge + 4.5), (t, -edge - 4.5), (edge + 4.5, t), (-edge - 4.5, t)][side]
                    place(pm, (bx + p[0], 0.0, bz + p[1]), None, yrot(0.0 if side >= 2 else math.pi / 2))
                else:
                    p = [(t, edge + 0.6), (t, -edge - 0.6), (edge + 0.6, t), (-edge - 0.6, t)][side]
                    place(pm, (bx + p[0], 0.15, bz + p[1]), None, yrot(brng.uniform(0, 6.28)))
            k = 0
            while True:
                tm = trees[brng.randrange(len(trees))]
                if counts['triangles'] + d.mesh_info[tm][0] / 2 > t_goal:
                    break
                side = k % 4
                t = brng.uniform(-edge + 1, edge - 1)
                p = [(t, edge), (t, -edge), (edge, t), (-edge, t)][side]
                place(tm, (bx + p[0], 0.15, bz + p[1]), None, yrot(brng.uniform(0, 6.28)))
                k += 1
            block_lots.append(lots)
        # punctual lights: the lights the emissive triangles and fires leave, spread evenly
        # over the blocks, each block's in the full scene's mix
        n_punctual = max(0, lights_free - counts['emissive_triangles'])
        for b in range(n_blocks):
            bx, bz = block_centres[b]
            lots = block_lots[b]
            n = n_punctual * (b + 1) // n_blocks - n_punctual * b // n_blocks
            cum = [0]
            for w in weights:
                cum.append(cum[-1] + w)
            kinds = [n * cum[i + 1] // total_w - n * cum[i] // total_w for i in range(len(weights))]
            n_lantern, n_up, n_shop, n_lamp, n_path = kinds
            def before_facade(j, half, d):
                """A point d m out from one of lot j % 4's facades, u in [-half, half] along it
                (draws the facade, then u)."""
                cx, cz, a, q, sy, h, per_face, faces = lots[j % 4]
                f = brng.randrange(4)
                u = brng.uniform(-half, half)
                wx, wz = around(cx, cz, a, [(u, d), (-u, -d), (d, -u), (-d, u)][f])
                return wx, wz, sy, h

            for j in range(n_lantern):
                wx, wz, sy, h = before_facade(j, 7.5, 8.5)
                y = 0.15 + sy * brng.uniform(1.5, h - 1.0)
                light_node(lantern[brng.randrange(16)], (wx, y, wz))
                counts['point_lights'] += 1
            for j in range(n_up):
                wx, wz, _, _ = before_facade(j, 7.5, 9.0)
                light_node(uplt[brng.randrange(8)], (wx, 0.4, wz), up)
                counts['spot_lights'] += 1
            for j in range(n_shop):
                wx, wz, _, _ = before_facade(j, 7.0, 8.8)
                light_node(shop[brng.randrange(8)], (wx, 3.2, wz), down)
                counts['spot_lights'] += 1
            per_side = max(1, (n_lamp + 3) // 4)
            for j in range(n_lamp):
                side = j % 4
                t = -edge + 2 * edge * (j // 4 + 0.5) / per_side
                p = [(t, edge + 2.0), (t, -edge - 2.0), (edge + 2.0, t), (-edge - 2.0, t)][side]
                light_node(lamp[brng.randrange(8)], (bx + p[0], 6.8, bz + p[1]), down)
                counts['spot_lights'] += 1
            for j in range(n_path):
                side = j % 4
                t = brng.uniform(-edge, edge)
                p = [(t, edge - 0.3), (t, -edge + 0.3), (edge - 0.3, t), (-edge + 0.3, t)][side]
                light_node(path[brng.randrange(8)], (bx + p[0], 0.65, bz + p[1]))
                counts['point_lights'] += 1

    if targets:
        blocks_to_targets(*targets)
    # (with targets, the loop below makes no block)
    for b in range(0 if targets else n_blocks):
        bx, bz = x_origin + (b % nx) * pitch, z_origin + (b // nx) * pitch
        block_centres.append((bx, bz))
        place(grounds[brng.randrange(len(grounds))], (bx, 0.0, bz))
        # 4 buildings on 2x2 lots of 20 m, facing the streets; windows on two facades each
        for lot in range(4):
            cx, cz, a, q, sy, h, per_face = place_building(bx, bz, lot)
            faces = brng.sample(range(4), 2)
            for f in faces:
                place(per_face[f][brng.randrange(len(per_face[f]))], (cx, 0.15, cz), (1.0, sy, 1.0), q)
            # lanterns in front of the facades and facade up-lights
            for k in range(175):
                f = brng.randrange(4)
                u = brng.uniform(-7.5, 7.5)
                y = 0.15 + sy * brng.uniform(1.5, h - 1.0)
                local = [(u, 8.5), (-u, -8.5), (8.5, -u), (-8.5, u)][f]
                ca, sa = math.cos(a), math.sin(a)
                wx, wz = cx + ca * local[0] + sa * local[1], cz - sa * local[0] + ca * local[1]
                light_node(lantern[brng.randrange(16)], (wx, y, wz))
                counts['point_lights'] += 1
            for k in range(36):
                f = brng.randrange(4)
                u = brng.uniform(-7.5, 7.5)
                local = [(u, 9.0), (-u, -9.0), (9.0, -u), (-9.0, u)][f]
                ca, sa = math.cos(a), math.sin(a)
                wx, wz = cx + ca * local[0] + sa * local[1], cz - sa * local[0] + ca * local[1]
                light_node(uplt[brng.randrange(8)], (wx, 0.4, wz), up)
                counts['spot_lights'] += 1
            for k in range(10):
                f = brng.randrange(4)
                u = brng.uniform(-7.0, 7.0)
                local = [(u, 8.8), (-u, -8.8), (8.8, -u), (-8.8, u)][f]
                ca, sa = math.cos(a), math.sin(a)
                wx, wz = cx + ca * local[0] + sa * local[1], cz - sa * local[0] + ca * local[1]
                light_node(shop[brng.randrange(8)], (wx, 3.2, wz), down)
                counts['spot_lights'] += 1
        # street trees and props along the block's edge (on the sidewalk), street lamps, path lights
        edge = BLOCK / 2 - 1.2
        for k in range(14):
            side = k % 4
            t = brng.uniform(-edge + 1, edge - 1)
            p = [(t, edge), (t, -edge), (edge, t), (-edge, t)][side]
            place(trees[brng.randrange(len(trees))], (bx + p[0], 0.15, bz + p[1]), None, yrot(brng.uniform(0, 6.28)))
        for k in range(40):
            side = k % 4
            t = brng.uniform(-edge, edge)
            p = [(t, edge + 0.6), (t, -edge - 0.6), (edge + 0.6, t), (-edge - 0.6, t)][side]
            kind, pm = props[brng.randrange(len(props))]
            if kind == 4:   # cars park in the street
                p = [(t, edge + 4.5), (t, -edge - 4.5), (edge + 4.5, t), (-edge - 4.5, t)][side]
                place(pm, (bx + p[0], 0.0, bz + p[1]), None, yrot(0.0 if side >= 2 else math.pi / 2))
            else:
                place(pm, (bx + p[0], 0.15, bz + p[1]), None, yrot(brng.uniform(0, 6.28)))
        for k in range(16):
            side = k % 4
            t = -edge + 2 * edge * (k // 4 + 0.5) / 4
            p = [(t, edge + 2.0), (t, -edge - 2.0), (edge + 2.0, t), (-edge - 2.0, t)][side]
            light_node(lamp[brng.randrange(8)], (bx + p[0], 6.8, bz + p[1]), down)
            counts['spot_lights'] += 1
        for k in range(300):
            side = k % 4
            t = brng.uniform(-edge, edge)
            p = [(t, edge - 0.3), (t, -edge + 0.3), (edge - 0.3, t), (-edge + 0.3, t)][side]
            light_node(path[brng.randrange(8)], (bx + p[0], 0.65, bz + p[1]))
            counts['point_lights'] += 1
        # a neon sign on a facade and a string of bulbs across the street beside the block
        sx = bx + brng.uniform(-12, 12)
        place(signs[brng.randrange(len(signs))], (sx, brng.uniform(4.0, 6.0), bz + BLOCK / 2 - 1.0))
        place(strings[brng.randrange(len(strings))], (bx + BLOCK / 2 + STREET / 2, 6.0, bz + brng.uniform(-15, 15)),
              None, yrot(0.0))
    place(haze, (0.0, 0.0, 0.0))

    # the camera: in the street east of the block nearest the centre, looking along it (-z)
    cb = min(block_centres, key=lambda c: (c[0] ** 2 + c[1] ** 2, c))
    cam_x = cb[0] + BLOCK / 2 + STREET / 2 - 2.0
    cam = (cam_x, 1.7, cb[1] + BLOCK / 2 + STREET / 2)
    target = (cam_x - 1.0, 5.0, cb[1] - 40.0)
    d.doc['cameras'].append({'name': 'street', 'type': 'perspective', 'perspective': {
        'yfov': r(math.radians(55.0)), 'aspectRatio': r(16 / 9), 'znear': 0.05, 'zfar': 2000.0}})
    fwd = (target[0] - cam[0], target[1] - cam[1], target[2] - cam[2])
    d.node({'name': 'street_camera', 'camera': 0, 'translation': rv(cam, 4), 'rotation': rv(look_rotation(fwd), 7)})

    # fires on braziers: one in view of the camera, the rest along the streets
    frng = random.Random(5)
    fire_uri = base + '_fire.vdb'
    n_fire = variants('fire', scale)
    for k in range(n_fire):
        if k == 0:
            p = (cam_x - 4.0, cb[1] + BLOCK / 2 - 6.0)
        else:
            bx, bz = block_centres[frng.randrange(len(block_centres))]
            p = (bx + BLOCK / 2 + 2.0, bz + frng.uniform(-18, 18))
        place(brazier_mesh, (p[0], 0.0, p[1]))
        d.node({'name': 'fire%02d' % k, 'translation': rv((p[0], 1.05, p[1]), 4), 'scale': [0.6, 0.9, 0.6],
                'extras': {'candela_volume': {'uri': fire_uri, 'density_grid': 'density', 'density_scale': 6.0,
                                              'albedo': [0.3, 0.3, 0.3], 'anisotropy': 0.0,
                                              'emission_grid': 'emission', 'emission_scale': 400.0,
                                              'emission_color': [1.0, 0.5, 0.18]}}})
        counts['volumes'] += 1

    for n in mesh_nodes:
        d.node(n)
    d.light_nodes = lights_nodes
    counts['punctual_lights'] = len(lights_nodes)

    sky_uri = base + '_sky.exr'
    d.doc['scenes'][0]['extras'] = {'candela_environment': {'uri': sky_uri, 'strength': 1.0}}
    with contextlib.redirect_stdout(sys.stderr):   # stdout is the counts' JSON
        write_exr(os.path.join(folder, sky_uri), 16, 8,
                  lambda x, y: (0.004 + 0.004 * y / 7, 0.006 + 0.004 * y / 7, 0.012 + 0.004 * y / 7))
    write_fire_vdb(os.path.join(folder, fire_uri))
    d.write(out)

    if targets:
        counts.update({'lights_target': targets[0], 'triangles_target': targets[1],
                       'emissive_capped': plan['emissive_capped'], 'window_subdivision': sub})
    distinct = sum(t for t, _, _ in d.mesh_info)
    counts.update({
        'scale': scale, 'blocks': n_blocks, 'distinct_meshes': len(d.mesh_info), 'distinct_triangles': distinct,
        'textures': n_tex, 'environment': 1,
        'lights_paper': counts['punctual_lights'] + counts['emissive_triangles'] + counts['volumes'],
        'renderer_lights': (counts['punctual_lights'] + counts['emissive_primitive_instances']
                            + counts['volumes'] + 1),
        'glb_bytes': os.path.getsize(out)})
    with open(stem + '.counts.json', 'w') as fh:
        json.dump(counts, fh, indent=1, sort_keys=True)
        fh.write('\n')
    return counts


def count_arg(text):
    """10000, 10k, 1.5M, 5e6: a count."""
    t = text.strip().lower()
    mult = {'k': 10 ** 3, 'm': 10 ** 6}.get(t[-1:], 1)
    try:
        v = float(t[:-1] if mult > 1 else t) * mult
    except ValueError:
        raise argparse.ArgumentTypeError('not a count: %r (e.g. 100000, 100k, 5M)' % text)
    if not (v >= 1 and v == v and v < 1e12):
        raise argparse.ArgumentTypeError('not a count: %r' % text)
    return int(round(v))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('-o', '--output', default=os.path.join(ROOT, 'build', 'scenes', 'production.glb'))
    ap.add_argument('--scale', type=float, default=None, help='1: the full scene (the default); 0.01: the 1%% version')
    ap.add_argument('--lights', type=count_arg, default=None,
                    help='target lights as the paper counts them (punctual + emissive triangles + volumes), e.g. 100k')
    ap.add_argument('--triangles', type=count_arg, default=None, help='target triangles after instancing, e.g. 10M')
    a = ap.parse_args()
    targets = None
    if a.lights is not None or a.triangles is not None:
        if a.scale is not None:
            sys.exit('make_production.py: --scale or --lights/--triangles, not both')
        lights = a.lights if a.lights is not None else int(round(a.triangles / TRIANGLES_PER_LIGHT))
        tris = a.triangles if a.triangles is not None else int(round(a.lights * TRIANGLES_PER_LIGHT))
        if not (100 <= lights <= 20000000):
            sys.exit('make_production.py: --lights must be in [100, 20M] (got %d)' % lights)
        if not (100000 <= tris <= 250000000):
            sys.exit('make_production.py: --triangles must be in [100k, 250M] (got %d; a block\'s ground and '
                     'buildings alone are ~50k)' % tris)
        targets = (lights, tris)
    elif a.scale is None:
        a.scale = 1.0
    if targets is None and not (0.0 < a.scale <= 4.0):
        sys.exit('make_production.py: --scale must be in (0, 4] (got %g)' % a.scale)
    c = build(a.output, a.scale, targets)
    sys.stderr.write('wrote %s (%d bytes): %d lights as the paper counts them (%d punctual: %d points, %d spots; '
                     '%d emissive triangles in %d emissive mesh instances; %d emissive volumes), %d renderer lights, '
                     '%d triangles after instancing (%d distinct), %d instances, %d textures\n'
                     % (a.output, c['glb_bytes'], c['lights_paper'], c['punctual_lights'], c['point_lights'],
                        c['spot_lights'], c['emissive_triangles'], c['emissive_instances'], c['volumes'],
                        c['renderer_lights'], c['triangles'], c['distinct_triangles'], c['instances'], c['textures']))
    if targets:
        for what, got, want in (('lights', c['lights_paper'], targets[0]), ('triangles', c['triangles'], targets[1])):
            if abs(got - want) > 0.03 * want:
                sys.stderr.write('make_production.py: warning: %d %s, %.1f%% from the target %d\n'
                                 % (got, what, 100.0 * (got - want) / want, want))
    # stdout: what was written, one JSON line (the counts file's content and the output's path)
    print(json.dumps(dict(c, output=os.path.abspath(a.output)), sort_keys=True))


if __name__ == '__main__':
    main()
