#!/usr/bin/env python3
"""scenes/make_scenes.py: generates Candela's demo scene and the analytic test scenes.

Python 3 standard library only, deterministic: running it twice writes byte-identical files.
Every .gltf is self-contained (geometry in a base64 data: URI buffer). glTF 2.0, Y-up, metres.

Outputs (paths relative to the repository root):
  scenes/default.gltf                 the demo room (Blender light units: cd, /683)
  scenes/guiding_interior.gltf        a room lit through a small window (path-guiding benchmark)
  tests/scenes/furnace_sphere.gltf     closed emissive Lambert sphere, camera at the centre
  tests/scenes/point_plane.gltf        Lambert plane + point light (RAW units)
  tests/scenes/spot_plane.gltf         Lambert plane + spot light, all pixels in the inner cone
  tests/scenes/spot_blend_plane.gltf   Lambert plane + spot (outer 0.9, inner 0.45 rad), the whole cone in view
  tests/scenes/directional_plane.gltf  Lambert plane + directional light at 30 degrees
  tests/scenes/area_plane.gltf         Lambert plane + one-sided emissive square (+ a back-facing one)
  tests/scenes/env_constant.gltf       nothing visible, constant environment (env_constant.exr)
  tests/scenes/env_plane.gltf          Lambert plane under the constant environment
  tests/scenes/coat_plane.gltf         env_plane with a smooth clearcoat (KHR_materials_clearcoat)
  tests/scenes/plastic_plane.gltf      a smooth plastic plane under the environment (--material-model)
  tests/scenes/env_directions.gltf     orthographic cameras looking at texel centres of env_grid.exr
  tests/scenes/env_directions_rot.gltf the same with the environment rotated (extras rotation 75)
  tests/scenes/env_marked.gltf         a camera looking down -Z under env_marked.exr
  tests/scenes/normalmap_grazing.gltf  normal-mapped planes (normalmap_stripes.exr) seen at 85 degrees
  tests/scenes/two_lights.gltf         floor + wall, 1 emissive quad, 3 point lights of very different power
  tests/scenes/glossy_lights.gltf      glossy floor, polished metal wall, a clear-coated sphere, 40 point
                                       lights, 2 emissive panels, a sun (BSDF-aware cache point selection)
  tests/scenes/env_constant.exr        16x8 FLOAT EXR, every pixel (0.5, 0.75, 1.0)
  tests/scenes/env_grid.exr            8x4 FLOAT EXR, texel (i, j) = ((i+1)/8, (j+1)/4, 0.25 + 0.5*((i+j)%2))
  tests/scenes/env_marked.exr          64x32 FLOAT EXR, 0 but texel (18, 14) = 1

The expected values the tests use are documented next to each scene below and in
tests/test_analytic.c.
"""

import base64
import json
import math
import random
import os
import struct

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# ----------------------------------------------------------------------------------------------
# small vector helpers


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def normalize(a):
    n = math.sqrt(dot(a, a))
    return (a[0] / n, a[1] / n, a[2] / n)


def quat_from_basis(x, y, z):
    """Unit quaternion (x, y, z, w) of the rotation whose matrix has columns x, y, z."""
    m00, m10, m20 = x
    m01, m11, m21 = y
    m02, m12, m22 = z
    tr = m00 + m11 + m22
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = ((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s)
    elif m00 > m11 and m00 > m22:
        s = math.sqrt(1.0 + m00 - m11 - m22) * 2
        q = (0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    elif m11 > m22:
        s = math.sqrt(1.0 + m11 - m00 - m22) * 2
        q = ((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)
    else:
        s = math.sqrt(1.0 + m22 - m00 - m11) * 2
        q = ((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)
    n = math.sqrt(sum(c * c for c in q))
    q = tuple(c / n for c in q)
    if q[3] < 0:
        q = tuple(-c for c in q)
    return q


def look_rotation(forward, up_hint=(0.0, 1.0, 0.0)):
    """Quaternion turning a glTF camera/light (looks down local -Z, +Y up) to look along forward."""
    f = normalize(forward)
    if abs(dot(f, normalize(up_hint))) > 0.999:
        up_hint = (0.0, 0.0, -1.0)
    right = normalize(cross(f, up_hint))
    up = cross(right, f)
    back = scale(f, -1.0)
    return quat_from_basis(right, up, back)


def quat_axis_angle(axis, angle):
    a = normalize(axis)
    s = math.sin(angle / 2)
    q = (a[0] * s, a[1] * s, a[2] * s, math.cos(angle / 2))
    if q[3] < 0:
        q = tuple(-c for c in q)
    return q


def rotate(q, v):
    x, y, z, w = q
    u = (x, y, z)
    t = scale(cross(u, v), 2.0)
    return add(add(v, scale(t, w)), cross(u, t))


def r(x, digits=7):
    """Round a float for the JSON so the file is tidy and stable."""
    v = round(float(x), digits)
    return 0.0 if v == 0 else v


def rv(v, digits=7):
    return [r(c, digits) for c in v]


# ----------------------------------------------------------------------------------------------
# geometry: every builder returns (positions, normals, indices) with counter-clockwise front faces


def quad(p0, p1, p2, p3):
    """Planar quad p0 p1 p2 p3, counter-clockwise seen from its front; flat normal."""
    n = normalize(cross(sub(p1, p0), sub(p2, p0)))
    return [p0, p1, p2, p3], [n] * 4, [0, 1, 2, 0, 2, 3]


def merge(*parts):
    pos, nrm, idx = [], [], []
    for p, n, i in parts:
        base = len(pos)
        pos += p
        nrm += n
        idx += [base + k for k in i]
    return pos, nrm, idx


def box(sx, sy, sz, center=(0.0, 0.0, 0.0), inward=False):
    """Axis-aligned box with flat normals (24 vertices), outward-facing unless inward."""
    hx, hy, hz = sx / 2, sy / 2, sz / 2
    cx, cy, cz = center
    faces = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = [0.0, 0.0, 0.0]
            n[axis] = sign
            # two tangent axes so that t1 x t2 = n
            a1, a2 = (axis + 1) % 3, (axis + 2) % 3
            corners = []
            for s1, s2 in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis] = sign
                p[a1] = s1 * sign
                p[a2] = s2
                corners.append(p)
            pts = [(cx + c[0] * hx, cy + c[1] * hy, cz + c[2] * hz) for c in corners]
            if inward:
                pts = pts[::-1]
            faces.append(quad(*pts))
    return merge(*faces)


def uv_sphere(radius, segments=32, rings=16, inward=False, flat=False):
    """UV sphere: smooth (shared, radial) normals, or flat per-triangle normals (unshared
    vertices, normal = geometric normal) when flat."""
    grid = []
    for j in range(rings + 1):
        theta = math.pi * j / rings          # 0 at the north pole (+y)
        st, ct = math.sin(theta), math.cos(theta)
        if j == 0 or j == rings:
            st = 0.0
        row = []
        for i in range(segments + 1):
            phi = 2 * math.pi * (i % segments) / segments
            d = (st * math.cos(phi), ct, -st * math.sin(phi))
            row.append(d)
        grid.append(row)
    tris = []
    for j in range(rings):
        for i in range(segments):
            a = (j, i)
            b = (j + 1, i)
            c = (j + 1, i + 1)
            d = (j, i + 1)
            # outward CCW: a (top) -> b (below) -> c (below, next) ; phi grows counter-clockwise
            # seen from +y with d = (cos, ., -sin), so this order faces outward.
            if j != 0:
                tris.append((a, b, d))
            if j != rings - 1:
                tris.append((b, c, d))
    if inward:
        tris = [(t[0], t[2], t[1]) for t in tris]
    if flat:
        pos, nrm, idx = [], [], []
        for t in tris:
            ps = [scale(grid[j][i], radius) for (j, i) in t]
            n = normalize(cross(sub(ps[1], ps[0]), sub(ps[2], ps[0])))
            for p in ps:
                idx.append(len(pos))
                pos.append(p)
                nrm.append(n)
        return pos, nrm, idx
    pos, nrm = [], []
    for j in range(rings + 1):
        for i in range(segments + 1):
            d = grid[j][i]
            pos.append(scale(d, radius))
            nrm.append(scale(d, -1.0) if inward else d)
    idx = [j * (segments + 1) + i for t in tris for (j, i) in t]
    return pos, nrm, idx


# ----------------------------------------------------------------------------------------------
# glTF writer


def f32(x):
    return struct.unpack('<f', struct.pack('<f', x))[0]


class Gltf:
    def __init__(self, generator='candela scenes/make_scenes.py'):
        self.buf = bytearray()
        self.doc = {
            'asset': {'version': '2.0', 'generator': generator},
            'extensionsUsed': [],
            'scene': 0,
            'scenes': [{'name': 'Scene', 'nodes': []}],
            'nodes': [],
            'meshes': [],
            'materials': [],
            'accessors': [],
            'bufferViews': [],
            'buffers': [],
        }
        self.lights = []
        self.cameras = []
        self.geom_cache = {}

    def use(self, ext):
        if ext not in self.doc['extensionsUsed']:
            self.doc['extensionsUsed'].append(ext)

    def _view(self, data, target):
        while len(self.buf) % 4:
            self.buf.append(0)
        view = {'buffer': 0, 'byteOffset': len(self.buf), 'byteLength': len(data), 'target': target}
        self.buf += data
        self.doc['bufferViews'].append(view)
        return len(self.doc['bufferViews']) - 1

    def _vec_accessor(self, vecs, with_bounds):
        flat = [f32(c) for v in vecs for c in v]
        data = struct.pack('<%df' % len(flat), *flat)
        acc = {'bufferView': self._view(data, 34962), 'componentType': 5126,
               'count': len(vecs), 'type': 'VEC3'}
        if with_bounds:
            acc['min'] = [min(flat[k::3]) for k in range(3)]
            acc['max'] = [max(flat[k::3]) for k in range(3)]
        self.doc['accessors'].append(acc)
        return len(self.doc['accessors']) - 1

    def geometry(self, key, geom):
        """Adds positions/normals/indices once per key; returns the primitive attributes."""
        if key in self.geom_cache:
            return self.geom_cache[key]
        pos, nrm, idx = geom
        assert len(idx) % 3 == 0 and max(idx) < len(pos)
        p = self._vec_accessor(pos, True)
        n = self._vec_accessor(nrm, False)
        if len(pos) < 65536:
            data, ctype = struct.pack('<%dH' % len(idx), *idx), 5123
        else:
            data, ctype = struct.pack('<%dI' % len(idx), *idx), 5125
        self.doc['accessors'].append({'bufferView': self._view(data, 34963), 'componentType': ctype,
                                      'count': len(idx), 'type': 'SCALAR'})
        prim = {'attributes': {'POSITION': p, 'NORMAL': n}, 'indices': len(self.doc['accessors']) - 1}
        self.geom_cache[key] = prim
        return prim

    def material(self, name, base=(0.8, 0.8, 0.8), metallic=0.0, roughness=1.0, lambert=False,
                 emissive=None, strength=1.0, transmission=0.0, ior=None, double_sided=False):
        m = {'name': name,
             'pbrMetallicRoughness': {'baseColorFactor': rv(list(base) + [1.0]),
                                      'metallicFactor': r(metallic), 'roughnessFactor': r(roughness)}}
        ext = {}
        if lambert:
            self.use('KHR_materials_specular')
            ext['KHR_materials_specular'] = {'specularFactor': 0.0}
        if emissive is not None:
            m['emissiveFactor'] = rv(emissive)
            if strength != 1.0:
                self.use('KHR_materials_emissive_strength')
                ext['KHR_materials_emissive_strength'] = {'emissiveStrength': r(strength)}
        if transmission:
            self.use('KHR_materials_transmission')
            ext['KHR_materials_transmission'] = {'transmissionFactor': r(transmission)}
        if ior is not None:
            self.use('KHR_materials_ior')
            ext['KHR_materials_ior'] = {'ior': r(ior)}
        if ext:
            m['extensions'] = ext
        if double_sided:
            m['doubleSided'] = True
        self.doc['materials'].append(m)
        return len(self.doc['materials']) - 1

    def node(self, name, translation=None, rotation=None, scale_=None, **kw):
        n = {'name': name}
        if translation is not None:
            n['translation'] = rv(translation)
        if rotation is not None:
            n['rotation'] = rv(rotation, 8)
        if scale_ is not None:
            n['scale'] = rv(scale_)
        n.update(kw)
        self.doc['nodes'].append(n)
        self.doc['scenes'][0]['nodes'].append(len(self.doc['nodes']) - 1)
        return len(self.doc['nodes']) - 1

    def mesh(self, name, key, geom, material, translation=None, rotation=None):
        prim = dict(self.geometry(key, geom))
        prim['material'] = material
        self.doc['meshes'].append({'name': name, 'primitives': [prim]})
        return self.node(name, translation, rotation, mesh=len(self.doc['meshes']) - 1)

    def light(self, name, kind, intensity, color=(1.0, 1.0, 1.0), translation=None, rotation=None,
              inner=None, outer=None):
        self.use('KHR_lights_punctual')
        lt = {'name': name, 'type': kind, 'color': rv(color), 'intensity': r(intensity)}
        if kind == 'spot':
            lt['spot'] = {'innerConeAngle': r(inner), 'outerConeAngle': r(outer)}
        self.lights.append(lt)
        return self.node(name, translation, rotation,
                         extensions={'KHR_lights_punctual': {'light': len(self.lights) - 1}})

    def perspective(self, name, translation, target, yfov_deg, aspect=None, up=(0.0, 1.0, 0.0)):
        cam = {'name': name, 'type': 'perspective',
               'perspective': {'yfov': r(math.radians(yfov_deg)), 'znear': 0.01, 'zfar': 1000.0}}
        if aspect:
            cam['perspective']['aspectRatio'] = r(aspect)
        self.cameras.append(cam)
        rot = look_rotation(sub(target, translation), up)
        return self.node(name, translation, rot, camera=len(self.cameras) - 1)

    def orthographic(self, name, translation, forward, xmag, ymag, up=(0.0, 1.0, 0.0)):
        self.cameras.append({'name': name, 'type': 'orthographic',
                             'orthographic': {'xmag': r(xmag), 'ymag': r(ymag),
                                              'znear': 0.001, 'zfar': 1000.0}})
        return self.node(name, translation, look_rotation(forward, up),
                         camera=len(self.cameras) - 1)

    def environment(self, uri, strength=1.0):
        self.doc['scenes'][0]['extras'] = {'candela_environment': {'uri': uri, 'strength': r(strength)}}

    def write(self, path):
        doc = dict(self.doc)
        if not doc['extensionsUsed']:
            del doc['extensionsUsed']
        if self.lights:
            doc['extensions'] = {'KHR_lights_punctual': {'lights': self.lights}}
        if self.cameras:
            doc['cameras'] = self.cameras
        doc['buffers'] = [{'byteLength': len(self.buf),
                           'uri': 'data:application/octet-stream;base64,'
                                  + base64.b64encode(bytes(self.buf)).decode('ascii')}]
        text = json.dumps(doc, indent=1) + '\n'
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, 'w', newline='\n') as fh:
            fh.write(text)
        print('wrote %s (%d bytes)' % (os.path.relpath(path, ROOT), len(text)))


# ----------------------------------------------------------------------------------------------
# images


def write_exr(path, width, height, pixel):
    """Minimal single-part scanline OpenEXR: channels B, G, R (FLOAT), compression NONE,
    one scanline per block. pixel(x, y) -> (r, g, b), y = 0 is the top row."""

    def attr(name, typ, data):
        return name.encode() + b'\0' + typ.encode() + b'\0' + struct.pack('<i', len(data)) + data

    chlist = b''
    for ch in ('B', 'G', 'R'):  # alphabetical, as OpenEXR stores them
        chlist += ch.encode() + b'\0' + struct.pack('<iB3xii', 2, 0, 1, 1)
    chlist += b'\0'
    box = struct.pack('<iiii', 0, 0, width - 1, height - 1)
    header = (attr('channels', 'chlist', chlist)
              + attr('compression', 'compression', b'\0')
              + attr('dataWindow', 'box2i', box)
              + attr('displayWindow', 'box2i', box)
              + attr('lineOrder', 'lineOrder', b'\0')
              + attr('pixelAspectRatio', 'float', struct.pack('<f', 1.0))
              + attr('screenWindowCenter', 'v2f', struct.pack('<ff', 0.0, 0.0))
              + attr('screenWindowWidth', 'float', struct.pack('<f', 1.0))
              + b'\0')
    magic = struct.pack('<ii', 20000630, 2)
    table_size = 8 * height
    first = len(magic) + len(header) + table_size
    block_size = 8 + 3 * 4 * width
    offsets = struct.pack('<%dQ' % height, *[first + y * block_size for y in range(height)])
    blocks = b''
    for y in range(height):
        px = [pixel(x, y) for x in range(width)]
        data = b''
        for c in (2, 1, 0):  # B, G, R
            data += struct.pack('<%df' % width, *[p[c] for p in px])
        blocks += struct.pack('<ii', y, len(data)) + data
    with open(path, 'wb') as fh:
        fh.write(magic + header + offsets + blocks)
    print('wrote %s (%d bytes)' % (os.path.relpath(path, ROOT), len(magic + header + offsets + blocks)))


# ----------------------------------------------------------------------------------------------
# scenes

LAMBERT_WHITE = dict(base=(0.5, 0.5, 0.5), lambert=True)
PLANE_HALF = 50.0
PLANE = quad((-PLANE_HALF, 0.0, -PLANE_HALF), (-PLANE_HALF, 0.0, PLANE_HALF),
             (PLANE_HALF, 0.0, PLANE_HALF), (PLANE_HALF, 0.0, -PLANE_HALF))  # faces +y
DOWN = (0.0, -1.0, 0.0)


def default_scene():
    """The demo room, 4 x 3 x 4 m (x, z in [-2, 2], y in [0, 3]), Blender light units.

    Point light 2500 cd at (0, 2.6, 0): 2500/683 = 3.66 W/sr, irradiance on the floor below
    3.66 / 2.6^2 = 0.54 W/m^2 (the closed white room roughly triples it by interreflection).
    A 900 cd warm fill light near the back-left corner. Spot 4000 cd (5.9 W/sr) from a ceiling
    corner at the diffuse box/metal sphere, cone 0.35/0.55 rad. Emissive cube: radiance
    (1, 0.55, 0.2) x 3. The metal is roughness 0.5: at 0.2 (and still at 0.35) its reflection of the point light
    onto the walls (a glossy caustic, reachable only by a diffuse bounce then NEE) showed as
    fireflies at hundreds of samples per pixel."""
    g = Gltf()
    white = g.material('white_wall', base=(0.8, 0.8, 0.8), lambert=True)
    red = g.material('red_wall', base=(0.7, 0.08, 0.06), lambert=True)
    green = g.material('green_wall', base=(0.1, 0.6, 0.12), lambert=True)
    floor_m = g.material('floor', base=(0.75, 0.72, 0.65), roughness=0.9)
    box_m = g.material('diffuse_box', base=(0.75, 0.55, 0.3), lambert=True)
    metal = g.material('gold_metal', base=(1.0, 0.78, 0.34), metallic=1.0, roughness=0.5)
    glass = g.material('glass', base=(1.0, 1.0, 1.0), roughness=0.0, transmission=1.0, ior=1.5)
    glow = g.material('glow', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 0.55, 0.2),
                      strength=3.0)

    X, Y, Z = 2.0, 3.0, 2.0
    # inward-facing room surfaces (CCW seen from inside)
    g.mesh('floor', 'floor', quad((-X, 0, -Z), (-X, 0, Z), (X, 0, Z), (X, 0, -Z)), floor_m)
    g.mesh('ceiling', 'ceiling', quad((-X, Y, -Z), (X, Y, -Z), (X, Y, Z), (-X, Y, Z)), white)
    g.mesh('back_wall', 'back', quad((-X, 0, -Z), (X, 0, -Z), (X, Y, -Z), (-X, Y, -Z)), white)
    g.mesh('front_wall', 'front', quad((-X, 0, Z), (-X, Y, Z), (X, Y, Z), (X, 0, Z)), white)
    g.mesh('left_wall_red', 'left', quad((-X, 0, -Z), (-X, Y, -Z), (-X, Y, Z), (-X, 0, Z)), red)
    g.mesh('right_wall_green', 'right', quad((X, 0, -Z), (X, 0, Z), (X, Y, Z), (X, Y, -Z)), green)

    g.mesh('diffuse_box', 'tallbox', box(0.6, 1.0, 0.6), box_m, translation=(-1.0, 0.5, -1.0),
           rotation=quat_axis_angle((0, 1, 0), math.radians(20)))
    sphere = uv_sphere(1.0)
    g.mesh('metal_sphere', 'sphere', sphere, metal, translation=(0.85, 0.45, -0.85))
    g.doc['nodes'][-1]['scale'] = [0.45, 0.45, 0.45]
    g.mesh('glass_sphere', 'sphere', sphere, glass, translation=(-0.3, 0.4, -0.25))
    g.doc['nodes'][-1]['scale'] = [0.4, 0.4, 0.4]
    g.mesh('glow_cube', 'cube', box(0.25, 0.25, 0.25), glow, translation=(0.5, 0.125, 0.2),
           rotation=quat_axis_angle((0, 1, 0), math.radians(-30)))

    g.light('ceiling_point', 'point', 2500.0, color=(1.0, 0.95, 0.88), translation=(0.0, 2.6, 0.0))
    g.light('fill_point', 'point', 900.0, color=(1.0, 0.8, 0.6), translation=(-0.9, 2.5, -1.2))
    spot_pos = (1.7, 2.85, 1.6)
    spot_target = (0.0, 0.4, -0.9)
    g.light('corner_spot', 'spot', 4000.0, color=(0.9, 0.95, 1.0), translation=spot_pos,
            rotation=look_rotation(sub(spot_target, spot_pos)), inner=0.35, outer=0.55)

    g.perspective('camera', (0.0, 1.5, 1.9), (0.0, 0.65, -0.6), 58.0, aspect=4 / 3)
    g.write(os.path.join(ROOT, 'scenes', 'default.gltf'))


def guiding_interior():
    """The path-guiding benchmark (issue 10): a closed 6 x 3 x 6 m room (x, z in [-3, 3], y in
    [0, 3]) lit only through a 0.6 x 0.6 m window in the right wall (x = 3, y in [1.8, 2.4], z in
    [-0.3, 0.3]) by a 200000 cd point light outside at (4.5, 3.5, 0), which puts a bright patch
    on the floor around x = 0.75. Everything else is lit indirectly, mostly from that patch, which
    a BSDF sample from a wall or the ceiling rarely finds: indirect-dominated, where guiding
    should help. A rough metal panel and two boxes; the camera in the far corner."""
    g = Gltf()
    white = g.material('white_wall', base=(0.5, 0.5, 0.5), lambert=True)
    floor_m = g.material('floor', base=(0.6, 0.55, 0.45), roughness=0.8)
    box_m = g.material('box', base=(0.35, 0.45, 0.7), lambert=True)
    metal = g.material('rough_metal', base=(0.9, 0.9, 0.92), metallic=1.0, roughness=0.35)
    X, Y, Z = 3.0, 3.0, 3.0
    wy0, wy1, wz0, wz1 = 1.9, 2.3, -0.2, 0.2
    g.mesh('floor', 'floor', quad((-X, 0, -Z), (-X, 0, Z), (X, 0, Z), (X, 0, -Z)), floor_m)
    g.mesh('ceiling', 'ceiling', quad((-X, Y, -Z), (X, Y, -Z), (X, Y, Z), (-X, Y, Z)), white)
    g.mesh('back_wall', 'back', quad((-X, 0, -Z), (X, 0, -Z), (X, Y, -Z), (-X, Y, -Z)), white)
    g.mesh('front_wall', 'front', quad((-X, 0, Z), (-X, Y, Z), (X, Y, Z), (X, 0, Z)), white)
    g.mesh('left_wall', 'left', quad((-X, 0, -Z), (-X, Y, -Z), (-X, Y, Z), (-X, 0, Z)), white)
    # the right wall (x = X, seen from -x) around the window: four quads
    right = merge(quad((X, 0, -Z), (X, 0, Z), (X, wy0, Z), (X, wy0, -Z)),
                  quad((X, wy1, -Z), (X, wy1, Z), (X, Y, Z), (X, Y, -Z)),
                  quad((X, wy0, -Z), (X, wy0, wz0), (X, wy1, wz0), (X, wy1, -Z)),
                  quad((X, wy0, wz1), (X, wy0, Z), (X, wy1, Z), (X, wy1, wz1)))
    g.mesh('right_wall_window', 'right', right, white)
    g.mesh('box_a', 'box_a', box(0.8, 0.8, 0.8), box_m, translation=(-1.2, 0.4, -1.5),
           rotation=quat_axis_angle((0, 1, 0), math.radians(25)))
    g.mesh('box_b', 'box_b', box(0.5, 1.4, 0.5), box_m, translation=(1.6, 0.7, -2.2))
    g.mesh('metal_panel', 'panel', box(1.6, 1.2, 0.05), metal, translation=(-0.5, 1.2, -2.9))
    g.light('sun_through_window', 'point', 200000.0, color=(1.0, 0.93, 0.82), translation=(4.5, 3.5, 0.0))
    g.perspective('camera', (-2.6, 1.6, 2.6), (0.6, 0.9, -1.2), 70.0, aspect=4 / 3)
    g.write(os.path.join(ROOT, 'scenes', 'guiding_interior.gltf'))


def cornell_room(g, boxes=True, facing_down=True):
    """The Lambert Cornell box (5.5 m cube: x, z in [-2.75, 2.75], y in [0, 5.5]; white 0.73, red
    and green walls, optionally a tall and a short white box), its one-sided 1.3 x 1.05 m
    emissive quad (radiance (17, 12, 4)) just below the ceiling facing down, or 0.75 m below it
    facing up, and the camera, into g (also used by make_volumes.py's cornell_cloud)."""
    white = g.material('white', base=(0.73, 0.73, 0.73), lambert=True)
    red = g.material('red', base=(0.63, 0.065, 0.05), lambert=True)
    green = g.material('green', base=(0.14, 0.45, 0.091), lambert=True)
    glow = g.material('light', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 12.0 / 17.0, 4.0 / 17.0),
                      strength=17.0)
    X, Y, Z = 2.75, 5.5, 2.75
    g.mesh('floor', 'floor', quad((-X, 0, -Z), (-X, 0, Z), (X, 0, Z), (X, 0, -Z)), white)
    g.mesh('ceiling', 'ceiling', quad((-X, Y, -Z), (X, Y, -Z), (X, Y, Z), (-X, Y, Z)), white)
    g.mesh('back_wall', 'back', quad((-X, 0, -Z), (X, 0, -Z), (X, Y, -Z), (-X, Y, -Z)), white)
    g.mesh('left_wall_red', 'left', quad((-X, 0, -Z), (-X, Y, -Z), (-X, Y, Z), (-X, 0, Z)), red)
    g.mesh('right_wall_green', 'right', quad((X, 0, -Z), (X, 0, Z), (X, Y, Z), (X, Y, -Z)), green)
    if boxes:
        g.mesh('tall_box', 'tall', box(1.65, 3.3, 1.65), white, translation=(-0.9, 1.65, -0.9),
               rotation=quat_axis_angle((0, 1, 0), math.radians(17)))
        g.mesh('short_box', 'short', box(1.65, 1.65, 1.65), white, translation=(0.95, 0.825, 0.7),
               rotation=quat_axis_angle((0, 1, 0), math.radians(-17)))
    # facing up, it hangs 0.75 m below the ceiling, so its patch there is broad
    lx, lz, ly = 0.65, 0.525, Y - (0.02 if facing_down else 0.75)
    down = quad((-lx, ly, -lz), (lx, ly, -lz), (lx, ly, lz), (-lx, ly, lz))
    up = quad((-lx, ly, -lz), (-lx, ly, lz), (lx, ly, lz), (lx, ly, -lz))
    g.mesh('light', 'light_down' if facing_down else 'light_up', down if facing_down else up, glow)
    g.perspective('camera', (0.0, 2.75, 10.5), (0.0, 2.75, 0.0), 39.3, aspect=1.0)


def cornell_boxes():
    """Two Lambert Cornell boxes (cornell_room), the sample-quality and guiding benchmarks'
    scenes (issues 25 and 26):
    - cornell_box.gltf: the classic one, lit by the quad facing down: direct light dominates;
    - cornell_indirect.gltf: the quad 0.75 m below the ceiling, facing it, so that everything the
      camera sees but the ceiling's bright patch is lit indirectly by that patch (the
      canonical case for path guiding)."""
    for name, facing_down in (('cornell_box', True), ('cornell_indirect', False)):
        g = Gltf()
        cornell_room(g, facing_down=facing_down)
        g.write(os.path.join(ROOT, 'scenes', name + '.gltf'))

def top_ortho(g, height=3.0, mag=1.0):
    """Orthographic camera above the origin looking straight down (image right = +x, up = -z),
    covering x, z in [-mag, mag]."""
    g.orthographic('top', (0.0, height, 0.0), DOWN, mag, mag, up=(0.0, 0.0, -1.0))


def furnace_sphere():
    """Closed flat-shaded UV sphere (radius 1, 32x16, front faces inward, doubleSided),
    Lambert albedo a = 0.5, emission Le = 1. Any closed Lambert enclosure with uniform Le and
    albedo a has radiance Le / (1 - a) = 2 everywhere (truncated: Le * sum_{k<D} a^k)."""
    g = Gltf()
    m = g.material('furnace', base=(0.5, 0.5, 0.5), lambert=True, emissive=(1.0, 1.0, 1.0),
                   double_sided=True)
    g.mesh('sphere', 'sphere', uv_sphere(1.0, inward=True, flat=True), m)
    g.perspective('centre', (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), 90.0, aspect=1.0)
    g.write(os.path.join(ROOT, 'tests', 'scenes', 'furnace_sphere.gltf'))


def point_plane():
    """Plane y = 0 (100 x 100 m, Lambert rho = 0.5, faces +y), point light I = 2*pi at height
    h = 1 (RAW: W/sr). L(x) = rho/pi * I * h / r^3, r^2 = h^2 + |x|^2; L(0) = 1."""
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    g.light('point', 'point', 2 * math.pi, translation=(0.0, 1.0, 0.0))
    top_ortho(g)
    g.write(os.path.join(ROOT, 'tests', 'scenes', 'point_plane.gltf'))


def masked_planes():
    """point_plane plus an occluder quad at y = 0.5 over [-2, 2]^2 with alphaMode MASK:
    alpha 0.2 < cutoff 0.5 (masked_plane.gltf: invisible to camera and shadow rays, so the
    image equals point_plane's exactly) and alpha 0.8 (masked_plane_opaque.gltf: the control,
    which must differ)."""
    for name, alpha in (('masked_plane', 0.2), ('masked_plane_opaque', 0.8)):
        g = Gltf()
        g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
        m = g.material('cutout', **LAMBERT_WHITE)
        g.doc['materials'][m]['pbrMetallicRoughness']['baseColorFactor'][3] = alpha
        g.doc['materials'][m]['alphaMode'] = 'MASK'
        g.doc['materials'][m]['alphaCutoff'] = 0.5
        g.mesh('occluder', 'occluder', quad((-2.0, 0.5, -2.0), (-2.0, 0.5, 2.0), (2.0, 0.5, 2.0),
                                            (2.0, 0.5, -2.0)), m)
        g.light('point', 'point', 2 * math.pi, translation=(0.0, 1.0, 0.0))
        top_ortho(g)
        g.write(os.path.join(ROOT, 'tests', 'scenes', name + '.gltf'))


def spot_plane():
    """As point_plane but a spot light pointing down, inner cone 1.2 rad (68.8 deg), outer 1.4 rad.
    The camera's corners are at 54.7 deg from the axis, so every pixel is inside the inner cone
    and sees exactly the point-light value."""
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    g.light('spot', 'spot', 2 * math.pi, translation=(0.0, 1.0, 0.0),
            rotation=look_rotation(DOWN, (0.0, 0.0, -1.0)), inner=1.2, outer=1.4)
    top_ortho(g)
    g.write(os.path.join(ROOT, 'tests', 'scenes', 'spot_plane.gltf'))


# spot_blend_plane: Blender spot size 2 * SPOT_BLEND_OUTER, blend 0.5 (exported inner = outer (1 - blend))
SPOT_BLEND_OUTER = 0.9
SPOT_BLEND_INNER = 0.45


def spot_blend_plane():
    """Lambert plane + a spot 1 m above it pointing down, outer cone 0.9 rad, inner 0.45 rad (what
    Blender's glTF exporter writes for spot size 1.8 rad, blend 0.5), intensity 2 pi W/sr (RAW).
    The camera sees the whole cone (radius tan 0.9 = 1.26 m): the falloff's closed forms (glTF's
    ramp by default, Cycles 3.4's smoothstep and cosine with --light-model blender3) are in
    tests/test_analytic.c."""
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    g.light('spot', 'spot', 2 * math.pi, translation=(0.0, 1.0, 0.0),
            rotation=look_rotation(DOWN, (0.0, 0.0, -1.0)), inner=SPOT_BLEND_INNER, outer=SPOT_BLEND_OUTER)
    top_ortho(g, mag=1.5)
    g.write(os.path.join(ROOT, 'tests', 'scenes', 'spot_blend_plane.gltf'))


def directional_plane():
    """Plane + directional light 30 deg from the normal (travelling along
    -(sin 30, cos 30, 0)), E = 2*pi W/m^2 (RAW). L = rho/pi * E * cos 30 = cos 30 = 0.8660254."""
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    th = math.radians(30.0)
    travel = (-math.sin(th), -math.cos(th), 0.0)
    g.light('sun', 'directional', 2 * math.pi, translation=(0.0, 10.0, 0.0),
            rotation=look_rotation(travel))
    top_ortho(g)
    g.write(os.path.join(ROOT, 'tests', 'scenes', 'directional_plane.gltf'))


def area_plane():
    """Plane + one-sided emissive square (side 1, y = 1, centred, facing -y, Le = 2 via
    emissive_strength 2, black base colour). The camera is orthographic at y = 0.5 (below the
    square) looking down. L(x) = rho/pi * E(x), E from Lambert's polygon formula (see the test).
    A second emissive square at (3, 2, 0) faces +y: its back faces the plane, so it must add
    nothing (one-sided emission)."""
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    emit = g.material('emitter', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 1.0, 1.0),
                      strength=2.0)
    s = 0.5
    g.mesh('light_down', 'light_down',
           quad((-s, 1.0, -s), (s, 1.0, -s), (s, 1.0, s), (-s, 1.0, s)), emit)  # faces -y
    g.mesh('light_up_backfacing', 'light_up',
           quad((3 - s, 2.0, -s), (3 - s, 2.0, s), (3 + s, 2.0, s), (3 + s, 2.0, -s)), emit)  # +y
    top_ortho(g, height=0.5)
    g.write(os.path.join(ROOT, 'tests', 'scenes', 'area_plane.gltf'))


def tiny_far_box(g):
    """A 1 cm diffuse box 100 m below the origin, so the scene is not empty but nothing sees it."""
    g.mesh('tiny_far_box', 'tiny', box(0.01, 0.01, 0.01), g.material('black', base=(0, 0, 0), lambert=True),
           translation=(0.0, -100.0, 0.0))


ENV_CONSTANT = (0.5, 0.75, 1.0)


def env_grid_texel(i, j):
    return ((i + 1) / 8.0, (j + 1) / 4.0, 0.25 + 0.5 * ((i + j) % 2))


# texels (i, j) the env_directions cameras look at (centres of an 8x4 lat-long image)
ENV_DIR_TEXELS = [(0, 1), (1, 2), (2, 1), (3, 0), (4, 2), (5, 3), (6, 1), (7, 2)]


def latlong_dir(u, v, rotation_deg=0.0):
    """The world direction (glTF axes) whose environment lookup lands at (u, v) (v from the
    image's top row), written from Cycles' convention, not from the renderer's code: Cycles'
    equirectangular_to_direction (Blender's Z-up axes, its v = 1 - ours) is phi = pi - 2 pi u,
    theta = pi v, d_b = (sin theta cos phi, sin theta sin phi, cos theta). A world Mapping node of
    type Point with Z rotation rho looks up Rz(rho) d, so the world direction is Rz(-rho) d_b.
    Blender to glTF: (x, y, z)_gltf = (x_b, z_b, -y_b)."""
    phi = math.pi - 2.0 * math.pi * u - math.radians(rotation_deg)
    theta = math.pi * v
    xb, yb, zb = math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)
    return (xb, zb, -yb)


# the rotation of env_directions_rot.gltf (extras) and of the rot_* cameras: not a multiple of
# the 45-degree texel width, so a wrong sign or a missing rotation lands on another texel
ENV_DIR_ROTATION = 75.0

# env_marked.exr: 64x32, zero but one texel (ENV_MARK) of radiance 1; env_marked.gltf's
# camera looks down -Z (yfov 90 degrees), where Cycles puts that texel for rotations -20, 0 and
# +20 degrees (tests/test_analytic.c projects it)
ENV_MARK = (18, 14)


def env_scenes():
    d = os.path.join(ROOT, 'tests', 'scenes')
    os.makedirs(d, exist_ok=True)
    write_exr(os.path.join(d, 'env_constant.exr'), 16, 8, lambda x, y: ENV_CONSTANT)
    write_exr(os.path.join(d, 'env_grid.exr'), 8, 4, env_grid_texel)
    write_exr(os.path.join(d, 'env_marked.exr'), 64, 32,
              lambda x, y: (1.0, 1.0, 1.0) if (x, y) == ENV_MARK else (0.0, 0.0, 0.0))

    # every camera ray misses: pixel = Lenv = (0.5, 0.75, 1.0)
    g = Gltf()
    tiny_far_box(g)
    g.perspective('camera', (0.0, 0.0, 0.0), (0.0, 0.3, -1.0), 60.0, aspect=1.0)
    g.environment('env_constant.exr', 1.0)
    g.write(os.path.join(d, 'env_constant.gltf'))

    # Lambert plane rho = 0.5 under the constant environment: L = rho * Lenv = (0.25, 0.375, 0.5)
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    top_ortho(g)
    g.environment('env_constant.exr', 1.0)
    g.write(os.path.join(d, 'env_plane.gltf'))

    # the same plane with a smooth KHR_materials_clearcoat (factor 1, roughness 0): seen from
    # straight above, fresnel_coat gives L = (Fc(1) + (1 - Fc(1)) rho) Lenv with Fc(1) = 0.04
    # (tests/test_analytic.c)
    g = Gltf()
    m = g.material('lambert_half_coated', **LAMBERT_WHITE)
    g.use('KHR_materials_clearcoat')
    g.doc['materials'][m]['extensions']['KHR_materials_clearcoat'] = {'clearcoatFactor': 1.0,
                                                                      'clearcoatRoughnessFactor': 0.0}
    g.mesh('plane', 'plane', PLANE, m)
    top_ortho(g)
    g.environment('env_constant.exr', 1.0)
    g.write(os.path.join(d, 'coat_plane.gltf'))

    # a smooth plastic plane (base 0.5, roughness 0, glTF's default specular: F0 0.04) under the
    # same environment, seen from straight above (wo = n): --material-model gltf gives
    # L = (F(1) + rho int (1 - F(h.n)) cos / pi) Lenv, blender3 (Principled v1, Specular 0.5)
    # L = (Fr(1, 1.5) + rho (1 - 1/42)) Lenv (tests/test_analytic.c test_material_models)
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('plastic_half_smooth', base=(0.5, 0.5, 0.5), roughness=0.0))
    top_ortho(g)
    g.environment('env_constant.exr', 1.0)
    g.write(os.path.join(d, 'plastic_plane.gltf'))

    # orthographic cameras (all rays parallel) looking at texel centres of env_grid.exr: each
    # pixel = that texel exactly (with nearest or bilinear lookup). Camera "texel_i_j" for the
    # environment unrotated, "rot_texel_i_j" for it rotated by ENV_DIR_ROTATION; the same
    # cameras in env_directions.gltf (no rotation) and env_directions_rot.gltf (extras rotation).
    for name, rotation in (('env_directions.gltf', None), ('env_directions_rot.gltf', ENV_DIR_ROTATION)):
        g = Gltf()
        tiny_far_box(g)
        for prefix, rho in (('texel', 0.0), ('rot_texel', ENV_DIR_ROTATION)):
            for (i, j) in ENV_DIR_TEXELS:
                fwd = latlong_dir((i + 0.5) / 8.0, (j + 0.5) / 4.0, rho)
                g.orthographic('%s_%d_%d' % (prefix, i, j), (0.0, 0.0, 0.0), fwd, 0.01, 0.01)
        g.environment('env_grid.exr', 1.0)
        if rotation is not None:
            g.doc['scenes'][0]['extras']['candela_environment']['rotation'] = rotation
        g.write(os.path.join(d, name))

    # one camera at the origin looking down -Z (glTF's default orientation: no node rotation)
    g = Gltf()
    tiny_far_box(g)
    g.perspective('camera', (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), 90.0, aspect=1.0)
    g.environment('env_marked.exr', 1.0)
    g.write(os.path.join(d, 'env_marked.gltf'))


# normalmap_grazing: the tilt of the normal map's stripes and the camera's angle from the plane's normal
NORMALMAP_TILT_DEG = 10.0
NORMALMAP_VIEW_DEG = 85.0


def normalmap_grazing():
    """Two 2 x 2 m planes (y = 0, facing +y) under the constant environment env_constant.exr, each
    with a tangent-space normal map of stripes along x (normalmap_stripes.exr, 16 x 2 texels,
    pairs of texels tilted +-NORMALMAP_TILT_DEG about the tangent's normal plane), seen by an
    orthographic camera NORMALMAP_VIEW_DEG from the normal (grazing, looking along +x): every other
    stripe tilts away from the view by more than the 5 degrees the view has left, so the view is
    below its shading hemisphere. 'lambert' (rho 0.5, z in [-1, 1]): L between
    rho Lenv (1 + cos tilt) / 2 (the tilted cosine lobe cut by the geometric plane) and rho Lenv
    (the flat plane), never 0. 'metal' (white GGX metal, roughness 0.3, z in [3, 5]): in (0, Lenv]."""
    d = os.path.join(ROOT, 'tests', 'scenes')
    th = math.radians(NORMALMAP_TILT_DEG)

    def texel(x, y):
        sgn = 1.0 if (x // 2) % 2 == 0 else -1.0
        n = (sgn * math.sin(th), 0.0, math.cos(th))
        return tuple(0.5 * c + 0.5 for c in n)

    write_exr(os.path.join(d, 'normalmap_stripes.exr'), 16, 2, texel)
    g = Gltf()
    g.doc['images'] = [{'uri': 'normalmap_stripes.exr'}]
    g.doc['samplers'] = [{'magFilter': 9729, 'minFilter': 9729, 'wrapS': 10497, 'wrapT': 10497}]
    g.doc['textures'] = [{'source': 0, 'sampler': 0}]
    uvs = [(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)]
    flat = [f32(c) for v in uvs for c in v]
    g.doc['accessors'].append({'bufferView': g._view(struct.pack('<%df' % len(flat), *flat), 34962),
                               'componentType': 5126, 'count': len(uvs), 'type': 'VEC2'})
    uv_accessor = len(g.doc['accessors']) - 1
    lambert = g.material('lambert_half', **LAMBERT_WHITE)
    metal = g.material('metal', base=(1.0, 1.0, 1.0), metallic=1.0, roughness=0.3)
    view = math.radians(NORMALMAP_VIEW_DEG)
    forward = (math.sin(view), -math.cos(view), 0.0)
    for name, mat, z0 in (('lambert', lambert, 0.0), ('metal', metal, 4.0)):
        g.doc['materials'][mat]['normalTexture'] = {'index': 0}
        # u along +x (the tangent), v along +z
        geom = quad((-1.0, 0.0, z0 - 1.0), (-1.0, 0.0, z0 + 1.0), (1.0, 0.0, z0 + 1.0), (1.0, 0.0, z0 - 1.0))
        node = g.mesh(name, name, geom, mat)
        g.doc['meshes'][g.doc['nodes'][node]['mesh']]['primitives'][0]['attributes']['TEXCOORD_0'] = uv_accessor
        g.orthographic(name, (-forward[0], -forward[1], z0), forward, 0.05, 0.05)
    g.environment('env_constant.exr', 1.0)
    g.write(os.path.join(d, 'normalmap_grazing.gltf'))


def two_lights():
    """Floor (4 x 4 m) + back wall, Lambert 0.5; a one-sided emissive quad (0.5 x 0.5 m at
    y = 1.8, facing down, Le = 5) and 3 point lights of 0.05, 1 and 20 W/sr (RAW units).
    No analytic value: rendered with the uniform and the power light sampler, which must agree."""
    g = Gltf()
    m = g.material('lambert_half', **LAMBERT_WHITE)
    g.mesh('floor', 'floor', quad((-2, 0, -2), (-2, 0, 2), (2, 0, 2), (2, 0, -2)), m)
    g.mesh('back_wall', 'back', quad((-2, 0, -2), (2, 0, -2), (2, 2.5, -2), (-2, 2.5, -2)), m)
    emit = g.material('emitter', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 1.0, 1.0),
                      strength=5.0)
    s = 0.25
    g.mesh('area_light', 'area', quad((0.6 - s, 1.8, -0.5 - s), (0.6 + s, 1.8, -0.5 - s),
                                      (0.6 + s, 1.8, -0.5 + s), (0.6 - s, 1.8, -0.5 + s)), emit)
    g.light('weak', 'point', 0.05, translation=(-1.2, 0.5, -1.0))
    g.light('medium', 'point', 1.0, color=(1.0, 0.8, 0.6), translation=(-0.5, 1.2, 0.5))
    g.light('strong', 'point', 20.0, color=(0.6, 0.8, 1.0), translation=(1.5, 2.2, -1.5))
    g.perspective('camera', (0.0, 1.6, 2.5), (0.0, 0.5, -1.0), 60.0, aspect=1.0)
    g.write(os.path.join(ROOT, 'tests', 'scenes', 'two_lights.gltf'))


def occluded_lights():
    """The occlusion case in miniature (RAW units): a 6 x 3 x 4 m room split by a wall with a
    1 m doorway; 24 point lights (0.5-2 W/sr) in the far half, 8 in the camera's half, a
    double-sided emissive panel behind the wall and a glass sphere. No analytic value: every
    light sampler must agree with uniform (tests/test_strategies.c)."""
    import random
    rng = random.Random(7)
    g = Gltf()
    m = g.material('lambert_half', **LAMBERT_WHITE)
    g.mesh('floor', 'floor', quad((-3, 0, -2), (-3, 0, 2), (3, 0, 2), (3, 0, -2)), m)
    g.mesh('ceiling', 'ceiling', quad((-3, 3, -2), (3, 3, -2), (3, 3, 2), (-3, 3, 2)), m)
    g.mesh('back', 'back', quad((-3, 0, -2), (3, 0, -2), (3, 3, -2), (-3, 3, -2)), m)
    # dividing wall at x = 0 with a doorway for z in [-0.5, 0.5], y < 2 (double-sided)
    wall = g.material('wall', base=(0.5, 0.5, 0.5), lambert=True, double_sided=True)
    g.mesh('wall_a', 'wall_a', quad((0, 0, -2), (0, 0, -0.5), (0, 3, -0.5), (0, 3, -2)), wall)
    g.mesh('wall_b', 'wall_b', quad((0, 0, 0.5), (0, 0, 2), (0, 3, 2), (0, 3, 0.5)), wall)
    g.mesh('wall_c', 'wall_c', quad((0, 2, -0.5), (0, 2, 0.5), (0, 3, 0.5), (0, 3, -0.5)), wall)
    emit = g.material('panel', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 0.9, 0.7),
                      strength=3.0, double_sided=True)
    g.mesh('panel', 'panel', quad((1.5, 0.5, -1.9), (2.5, 0.5, -1.9), (2.5, 1.5, -1.9), (1.5, 1.5, -1.9)), emit)
    glass = g.material('glass', base=(1.0, 1.0, 1.0), roughness=0.0, transmission=1.0, ior=1.5)
    g.mesh('glass', 'sphere', uv_sphere(0.4, segments=24, rings=12), glass, translation=(-1.5, 0.4, 0.5))
    for k in range(24):
        g.light('far_%d' % k, 'point', 0.5 + 1.5 * rng.random(),
                translation=(0.3 + 2.5 * rng.random(), 0.3 + 2.5 * rng.random(), -1.8 + 3.6 * rng.random()))
    for k in range(8):
        g.light('near_%d' % k, 'point', 0.5 + 1.5 * rng.random(),
                translation=(-2.7 + 2.4 * rng.random(), 0.3 + 2.5 * rng.random(), -1.8 + 3.6 * rng.random()))
    g.perspective('camera', (-2.8, 1.5, 1.8), (0.5, 0.8, -0.8), 70.0, aspect=1.0)
    g.write(os.path.join(ROOT, 'tests', 'scenes', 'occluded_lights.gltf'))


def glossy_lights():
    """BSDF-aware cache point selection in miniature (RAW units): a 6 x 4 m floor of a dark glossy
    dielectric (roughness 0.2), a polished metal back wall (roughness 0.3), a Lambert side wall,
    a diffuse sphere under a smooth clear coat (coat roughness 0.1); 40 point lights (0.1-1
    W/sr), two one-sided emissive panels (Le 3) the floor reflects (so BSDF-sampled rays from
    glossy vertices hit emitters: MIS with the lobe-weighted pmf) and a weak sun. No analytic
    value: every light sampler must agree with uniform (tests/test_strategies.c)."""
    import random
    rng = random.Random(11)
    g = Gltf()
    floor = g.material('wet_floor', base=(0.1, 0.1, 0.1), roughness=0.2)
    metal = g.material('polished_metal', base=(0.9, 0.85, 0.8), metallic=1.0, roughness=0.3)
    side = g.material('lambert_half', **LAMBERT_WHITE)
    coated = g.material('coated', base=(0.6, 0.2, 0.2), lambert=True)
    g.use('KHR_materials_clearcoat')
    g.doc['materials'][coated]['extensions']['KHR_materials_clearcoat'] = {'clearcoatFactor': 1.0,
                                                                           'clearcoatRoughnessFactor': 0.1}
    g.mesh('floor', 'floor', quad((-3, 0, -2), (-3, 0, 2), (3, 0, 2), (3, 0, -2)), floor)
    g.mesh('back', 'back', quad((-3, 0, -2), (3, 0, -2), (3, 3, -2), (-3, 3, -2)), metal)
    g.mesh('left', 'left', quad((-3, 0, -2), (-3, 3, -2), (-3, 3, 2), (-3, 0, 2)), side)
    g.mesh('ball', 'sphere', uv_sphere(0.5, segments=24, rings=12), coated, translation=(0.8, 0.5, -0.6))
    emit = g.material('panel', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 0.9, 0.7), strength=3.0)
    g.mesh('panel_a', 'panel_a', quad((-1.5, 2.2, -1.2), (-0.9, 2.2, -1.2), (-0.9, 2.2, -0.6), (-1.5, 2.2, -0.6)), emit)
    g.mesh('panel_b', 'panel_b', quad((1.6, 1.0, -1.99), (2.2, 1.0, -1.99), (2.2, 1.6, -1.99), (1.6, 1.6, -1.99)), emit)
    for k in range(40):
        g.light('p_%d' % k, 'point', 0.1 + 0.9 * rng.random(), color=(1.0, 0.8 + 0.2 * rng.random(), 0.6 + 0.4 * rng.random()),
                translation=(-2.7 + 5.4 * rng.random(), 0.3 + 2.5 * rng.random(), -1.8 + 3.0 * rng.random()))
    g.light('sun', 'directional', 0.3, rotation=quat_axis_angle((1.0, 0.0, 0.0), -0.9))
    g.perspective('camera', (0.0, 0.9, 2.8), (0.0, 0.6, -2.0), 60.0, aspect=1.0)
    g.write(os.path.join(ROOT, 'tests', 'scenes', 'glossy_lights.gltf'))


def light_linking():
    """Light linking and shadow linking (tests/test_linking.c; RAW units). A floor in two
    objects, the left one a group node 'left' (floor and a post, so a name stands for a
    subtree), the right one 'right_floor'; a plate 'plate' 0.35 m above the right floor;
    lights: 'lamp_a' (a one-sided emissive quad facing down, so BSDF-sampled hits on it
    matter), 'point_b' (a point light) and 'lamp_c' (a smaller emissive quad). Variants, same
    geometry everywhere except where named:
      linking_both       no linking;
      linking_noA        lamp_a does not emit;
      linking_receivers  lamp_a: receivers exclude ['left']  (left as noA, right as both);
      linking_blockers   lamp_a: blockers exclude ['plate']  (= Aonly_noplate + noA off the plate);
      linking_Aonly_noplate  only lamp_a emits, no plate;
      linking_include    lamp_a: receivers include ['right_floor', 'plate'] (= linking_receivers);
      linking_both_links lamp_a: both lists at once;
      linking_many_*     noA, both, receivers with 48 more weak point lights (cache point far
                         entries and clusters); noC (lamp_c dark) and exclusive (lamp_a includes
                         the right floor and the plate, lamp_c excludes the right floor: the
                         right floor's class has an exclusive light, §3.3's add-back).
    The camera looks straight down from between the lamps (it sees their unlit backs)."""
    out = os.path.join(ROOT, 'tests', 'scenes')

    def make(name, a_emits=True, others_emit=True, plate=True, links=None, many=False, c_emits=True, c_links=None):
        g = Gltf()
        m = g.material('lambert_half', **LAMBERT_WHITE)
        emit = g.material('emitter', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 1.0, 1.0), strength=4.0)
        emit_c = g.material('emitter_c', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 0.8, 0.6),
                            strength=3.0 if others_emit and c_emits else 0.0)
        dark = g.material('dark', base=(0.0, 0.0, 0.0), lambert=True)
        # the left group: a parent node without a mesh, two children
        g.doc['meshes'].append({'name': 'left_floor',
                                'primitives': [dict(g.geometry('lf', quad((-2, 0, -2), (-2, 0, 2), (0, 0, 2), (0, 0, -2))),
                                                    material=m)]})
        g.doc['nodes'].append({'name': 'left_floor', 'mesh': len(g.doc['meshes']) - 1})
        lf = len(g.doc['nodes']) - 1
        g.doc['meshes'].append({'name': 'left_post', 'primitives': [dict(g.geometry('post', box(0.2, 0.3, 0.2)), material=m)]})
        g.doc['nodes'].append({'name': 'left_post', 'mesh': len(g.doc['meshes']) - 1, 'translation': [-1.4, 0.15, 1.2]})
        lp = len(g.doc['nodes']) - 1
        g.node('left', children=[lf, lp])
        g.mesh('right_floor', 'rf', quad((0, 0, -2), (0, 0, 2), (2, 0, 2), (2, 0, -2)), m)
        if plate:
            g.mesh('plate', 'plate', quad((0.6, 0.35, -0.4), (0.6, 0.35, 0.4), (1.2, 0.35, 0.4), (1.2, 0.35, -0.4)), m)
        s = 0.4
        a = g.mesh('lamp_a', 'lamp_a', quad((1.4 - s, 1.2, -s), (1.4 + s, 1.2, -s), (1.4 + s, 1.2, s), (1.4 - s, 1.2, s)),
                   emit if a_emits else dark)
        if links is not None:
            g.doc['nodes'][a]['extras'] = {'candela_light_linking': links}
        g.light('point_b', 'point', 1.0 if others_emit else 0.0, translation=(-1.0, 1.0, 0.6))
        c = 0.2
        lc = g.mesh('lamp_c', 'lamp_c', quad((-0.8 - c, 1.1, -0.9 - c), (-0.8 + c, 1.1, -0.9 - c), (-0.8 + c, 1.1, -0.9 + c),
                                        (-0.8 - c, 1.1, -0.9 + c)), emit_c)
        if c_links is not None:
            g.doc['nodes'][lc]['extras'] = {'candela_light_linking': c_links}
        if many:  # 48 weak point lights: cache points get far entries and clusters (cut size 4)
            import random
            rng = random.Random(3)
            for k in range(48):
                g.light('many_%d' % k, 'point', (0.02 + 0.05 * rng.random()) if others_emit else 0.0,
                        translation=(-1.9 + 3.8 * rng.random(), 0.6 + 0.5 * rng.random(), -1.9 + 3.8 * rng.random()))
        g.orthographic('top', (0.0, 1.15, 0.0), DOWN, 2.0, 2.0, up=(0.0, 0.0, -1.0))
        g.write(os.path.join(out, name + '.gltf'))

    make('linking_both')
    make('linking_noA', a_emits=False)
    make('linking_receivers', links={'receivers': {'exclude': ['left']}})
    make('linking_blockers', links={'blockers': {'exclude': ['plate']}})
    make('linking_Aonly_noplate', others_emit=False, plate=False)
    make('linking_include', links={'receivers': {'include': ['right_floor', 'plate']}})
    make('linking_both_links', links={'receivers': {'exclude': ['left']}, 'blockers': {'exclude': ['plate']}})
    make('linking_many_noA', a_emits=False, many=True)
    make('linking_many_both', many=True)
    make('linking_many_receivers', links={'receivers': {'exclude': ['left']}}, many=True)
    make('linking_many_noC', c_emits=False, many=True)
    make('linking_many_exclusive', links={'receivers': {'include': ['right_floor', 'plate']}},
         c_links={'receivers': {'exclude': ['right_floor']}}, many=True)


def light_edge_cases():
    """Valid but awkward light setups that must render without a crash or a division by zero:
    no lights at all, a zero-intensity light beside a normal one, a light whose intensity
    overflows to infinity in single precision (1e39) beside a normal one, a single light."""
    out = os.path.join(ROOT, 'tests', 'scenes')
    for name, lights in (('no_lights', []),
                         ('zero_power_light', [('zero', 0.0), ('one', 1.0)]),
                         ('overflow_light', [('huge', 1e39), ('one', 1.0)]),
                         ('single_light', [('one', 1.0)])):
        g = Gltf()
        g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
        for k, (lname, intensity) in enumerate(lights):
            g.light(lname, 'point', intensity, translation=(0.3 * k, 1.0, 0.0))
        top_ortho(g)
        g.write(os.path.join(out, name + '.gltf'))


def bench_scene():
    """The benchmark scene (simple materials, heavy geometry): a 12 x 4 x 12 m Lambert room
    with 64 instances of one 32,768-triangle sphere (2.1 M triangles traced through Embree
    instancing), four point lights and an emissive ceiling panel, Blender units."""
    g = Gltf()
    wall = g.material('wall', base=(0.7, 0.7, 0.7), lambert=True)
    ball = g.material('ball', base=(0.6, 0.45, 0.3), lambert=True)
    panel = g.material('panel', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 0.95, 0.9),
                       strength=6.0)
    X, Y, Z = 6.0, 4.0, 6.0
    g.mesh('floor', 'floor', quad((-X, 0, -Z), (-X, 0, Z), (X, 0, Z), (X, 0, -Z)), wall)
    g.mesh('ceiling', 'ceiling', quad((-X, Y, -Z), (X, Y, -Z), (X, Y, Z), (-X, Y, Z)), wall)
    g.mesh('back_wall', 'back', quad((-X, 0, -Z), (X, 0, -Z), (X, Y, -Z), (-X, Y, -Z)), wall)
    g.mesh('front_wall', 'front', quad((-X, 0, Z), (-X, Y, Z), (X, Y, Z), (X, 0, Z)), wall)
    g.mesh('left_wall', 'left', quad((-X, 0, -Z), (-X, Y, -Z), (-X, Y, Z), (-X, 0, Z)), wall)
    g.mesh('right_wall', 'right', quad((X, 0, -Z), (X, 0, Z), (X, Y, Z), (X, Y, -Z)), wall)
    P = 1.0
    g.mesh('panel', 'panel', quad((-P, Y - 0.01, -P), (P, Y - 0.01, -P), (P, Y - 0.01, P), (-P, Y - 0.01, P)), panel)
    g.mesh('ball', 'ball', uv_sphere(0.5, segments=128, rings=128), ball, translation=(-4.2, 0.5, -4.2))
    ball_mesh = len(g.doc['meshes']) - 1
    for i in range(8):
        for j in range(8):
            if i == 0 and j == 0:
                continue
            g.node('ball_%d_%d' % (i, j), (-4.2 + 1.2 * i, 0.5 + 0.25 * ((i + j) % 3), -4.2 + 1.2 * j),
                   None, mesh=ball_mesh)
    for k, (x, z) in enumerate([(-3, -3), (3, -3), (-3, 3), (3, 3)]):
        g.light('point_%d' % k, 'point', 3000.0, translation=(x, 3.2, z))
    g.perspective('camera', (0.0, 3.2, 5.8), (0.0, 0.3, -0.5), 62.0, aspect=4 / 3)
    g.write(os.path.join(ROOT, 'scenes', 'bench.gltf'))


def area_light_node(g, name, shape, size, power, translation, rotation=None, color=(1.0, 1.0, 1.0)):
    """A node with extras.candela_area_light (README "Light shapes"): emits along its local -Z."""
    return g.node(name, translation, rotation, extras={'candela_area_light': {
        'shape': shape, 'size': rv(size), 'color': rv(color), 'power': r(power)}})


def light_shapes():
    """Light shapes (README "Light shapes"; closed forms in tests/test_analytic.c), RAW units:
    sphere_plane   a sphere light (radius 0.5, I = 32 pi W/sr) 4 m above the Lambert plane, above
                   the camera: every plane point sees it whole, where a uniform sphere's irradiance
                   is exactly the point light's, L(x) = rho/pi I h / r^3 (L(0) = 1).
    sun_plane      directional_plane's sun with an angular diameter of 20 degrees: the cone stays
                   above the horizon, so E = E_perp cos 30 exactly (L = 0.8660254).
    rect_plane     area_plane's square as a candela_area_light rect (side 1, y = 1, facing down,
                   power 8 W: radiance power / (4 A) = 2, Cycles' convention), plus a rect facing
                   up (must add nothing).
    disk_plane     a disk of diameter 1 at y = 1 facing down, radiance 2 (power 8 pi/4 W).
    lamp_slab      a sphere light (radius 0.1) centred inside a 4 cm slab (a lamp head, 1 m up):
                   the plane below is lit through the part of the sphere below the slab
                   (lamp_slab_point: the same with radius 0, black).
    shapes_mix     every shape (sphere, spot sphere, sun, rect, disk, ellipse) over a glossy
                   plane, for the light samplers' agreement."""
    out = os.path.join(ROOT, 'tests', 'scenes')
    down = look_rotation(DOWN, (0.0, 0.0, -1.0))
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    n = g.light('sphere', 'point', 32 * math.pi, translation=(0.0, 4.0, 0.0))
    g.doc['nodes'][n]['extras'] = {'candela_light': {'radius': 0.5}}
    top_ortho(g)
    g.write(os.path.join(out, 'sphere_plane.gltf'))

    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    th = math.radians(30.0)
    n = g.light('sun', 'directional', 2 * math.pi, translation=(0.0, 10.0, 0.0),
                rotation=look_rotation((-math.sin(th), -math.cos(th), 0.0)))
    g.doc['nodes'][n]['extras'] = {'candela_light': {'angle': 20.0}}
    top_ortho(g)
    g.write(os.path.join(out, 'sun_plane.gltf'))

    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    area_light_node(g, 'rect_down', 'rect', (1.0, 1.0), 8.0, (0.0, 1.0, 0.0), down)
    area_light_node(g, 'rect_up_backfacing', 'rect', (1.0, 1.0), 8.0, (3.0, 2.0, 0.0),
                    look_rotation((0.0, 1.0, 0.0), (0.0, 0.0, -1.0)))
    top_ortho(g, height=0.5)
    g.write(os.path.join(out, 'rect_plane.gltf'))

    # rect_plane inside an absorbing fog box (sigma_a 0.5, no scattering; camera inside too): the
    # rays that find the rect weigh it by the transmittance up to it (closed form by quadrature)
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    fog = g.material('fog', base=(1.0, 1.0, 1.0))
    g.doc['materials'][fog]['extras'] = {'candela_medium': {'sigma_a': [0.5, 0.5, 0.5], 'sigma_s': [0.0, 0.0, 0.0]}}
    g.mesh('fog', 'fog', box(8.0, 4.0, 8.0, center=(0.0, 0.5, 0.0)), fog)
    area_light_node(g, 'rect_down', 'rect', (1.0, 1.0), 8.0, (0.0, 1.0, 0.0), down)
    top_ortho(g, height=0.5)
    g.write(os.path.join(out, 'rect_fog.gltf'))

    # rect_plane with light linking: the rect's receivers exclude the plane (it must go black)
    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    n = area_light_node(g, 'rect_down', 'rect', (1.0, 1.0), 8.0, (0.0, 1.0, 0.0), down)
    g.doc['nodes'][n]['extras']['candela_light_linking'] = {'receivers': {'exclude': ['plane']}}
    top_ortho(g, height=0.5)
    g.write(os.path.join(out, 'rect_plane_unlinked.gltf'))

    g = Gltf()
    g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
    area_light_node(g, 'disk_down', 'disk', (1.0, 1.0), 2 * math.pi, (0.0, 1.0, 0.0), down)
    top_ortho(g, height=0.5)
    g.write(os.path.join(out, 'disk_plane.gltf'))

    for name, radius in (('lamp_slab', 0.1), ('lamp_slab_point', 0.0)):
        g = Gltf()
        g.mesh('plane', 'plane', PLANE, g.material('lambert_half', **LAMBERT_WHITE))
        g.mesh('slab', 'slab', box(1.0, 0.04, 1.0, center=(0.0, 1.0, 0.0)),
               g.material('black', base=(0.0, 0.0, 0.0), lambert=True))
        n = g.light('lamp', 'point', 2 * math.pi, translation=(0.0, 1.0, 0.0))
        if radius > 0:
            g.doc['nodes'][n]['extras'] = {'candela_light': {'radius': radius}}
        top_ortho(g, mag=2.0)
        g.write(os.path.join(out, name + '.gltf'))

    g = Gltf()
    # a 6 m plane: the scene's radius sets the sun's power (the power sampler's weight)
    g.mesh('plane', 'plane', quad((-3.0, 0.0, -3.0), (-3.0, 0.0, 3.0), (3.0, 0.0, 3.0), (3.0, 0.0, -3.0)),
           g.material('glossy', base=(0.6, 0.6, 0.6), metallic=0.5, roughness=0.3))
    n = g.light('sphere', 'point', 3.0, color=(1.0, 0.8, 0.6), translation=(-0.6, 0.5, 0.3))
    g.doc['nodes'][n]['extras'] = {'candela_light': {'radius': 0.15}}
    n = g.light('spot_sphere', 'spot', 6.0, translation=(0.6, 1.2, -0.4),
                rotation=look_rotation((-0.2, -1.0, 0.1), (0.0, 0.0, -1.0)), inner=0.3, outer=0.6)
    g.doc['nodes'][n]['extras'] = {'candela_light': {'radius': 0.1}}
    n = g.light('sun', 'directional', 1.0, color=(0.6, 0.7, 1.0), translation=(0.0, 10.0, 0.0),
                rotation=look_rotation((0.5, -0.8, 0.3)))
    g.doc['nodes'][n]['extras'] = {'candela_light': {'angle': 8.0}}
    area_light_node(g, 'rect', 'rect', (0.6, 0.3), 4.0, (0.2, 0.8, 0.5),
                    look_rotation((0.1, -1.0, -0.3), (0.0, 0.0, -1.0)), color=(0.5, 1.0, 0.5))
    area_light_node(g, 'disk', 'disk', (0.4, 0.4), 3.0, (-0.4, 0.6, -0.6), down, color=(1.0, 0.5, 0.5))
    area_light_node(g, 'ellipse', 'disk', (0.8, 0.2), 2.0, (0.7, 0.4, 0.6),
                    look_rotation((-0.5, -1.0, 0.0), (0.0, 0.0, -1.0)))
    g.perspective('camera', (0.0, 2.2, 2.2), (0.0, 0.2, 0.0), 60.0, aspect=1.0)
    g.write(os.path.join(out, 'shapes_mix.gltf'))

    # shapes_many: 40 shapes (above LIGHT_SHAPE_BVH_MIN: rays find them through the BVH) and a sun
    rnd = random.Random(14)
    g = Gltf()
    g.mesh('plane', 'plane', quad((-3.0, 0.0, -3.0), (-3.0, 0.0, 3.0), (3.0, 0.0, 3.0), (3.0, 0.0, -3.0)),
           g.material('glossy', base=(0.6, 0.6, 0.6), metallic=0.5, roughness=0.3))
    for i in range(40):
        pos = (rnd.uniform(-2.0, 2.0), rnd.uniform(0.2, 1.5), rnd.uniform(-2.0, 2.0))
        col = (rnd.uniform(0.3, 1.0), rnd.uniform(0.3, 1.0), rnd.uniform(0.3, 1.0))
        if i % 5 < 3:
            kind = 'spot' if i % 5 == 2 else 'point'
            n = g.light('s%d' % i, kind, rnd.uniform(0.2, 1.0), color=col, translation=pos,
                        rotation=look_rotation((rnd.uniform(-0.5, 0.5), -1.0, rnd.uniform(-0.5, 0.5)), (0.0, 0.0, -1.0)),
                        inner=0.3 if kind == 'spot' else None, outer=0.7 if kind == 'spot' else None)
            g.doc['nodes'][n]['extras'] = {'candela_light': {'radius': r(rnd.uniform(0.03, 0.2))}}
        else:
            area_light_node(g, 'a%d' % i, 'rect' if i % 5 == 3 else 'disk',
                            (rnd.uniform(0.1, 0.5), rnd.uniform(0.1, 0.5)), rnd.uniform(0.5, 2.0), pos,
                            look_rotation((rnd.uniform(-0.7, 0.7), -1.0, rnd.uniform(-0.7, 0.7)), (0.0, 0.0, -1.0)),
                            color=col)
    n = g.light('sun', 'directional', 0.5, translation=(0.0, 10.0, 0.0), rotation=look_rotation((0.3, -0.8, 0.5)))
    g.doc['nodes'][n]['extras'] = {'candela_light': {'angle': 5.0}}
    g.perspective('camera', (0.0, 3.0, 3.5), (0.0, 0.3, 0.0), 60.0, aspect=1.0)
    g.write(os.path.join(out, 'shapes_many.gltf'))


def bad_inputs():
    """Malformed scenes for tests/test_cli.sh, each wrong in exactly one way."""
    out = os.path.join(ROOT, 'tests', 'bad')
    tri = ([(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)], [(0.0, 0.0, 1.0)] * 3, [0, 1, 2])

    def base():
        g = Gltf()
        g.mesh('tri', 'tri', tri, g.material('m', **LAMBERT_WHITE))
        g.light('point', 'point', 1.0, translation=(0.0, 0.0, 2.0))
        return g

    g = base()  # a NaN in the first vertex position (bounds dropped so the JSON stays valid)
    view = g.doc['bufferViews'][g.doc['accessors'][0]['bufferView']]
    g.buf[view['byteOffset']:view['byteOffset'] + 4] = struct.pack('<f', float('nan'))
    del g.doc['accessors'][0]['min'], g.doc['accessors'][0]['max']
    g.write(os.path.join(out, 'nan_positions.gltf'))

    g = base()  # index 7 into a 3-vertex primitive
    acc = g.doc['accessors'][g.doc['meshes'][0]['primitives'][0]['indices']]
    view = g.doc['bufferViews'][acc['bufferView']]
    g.buf[view['byteOffset']:view['byteOffset'] + 2] = struct.pack('<H', 7)
    g.write(os.path.join(out, 'index_out_of_range.gltf'))

    for name, uri in (('missing_texture', 'missing.png'), ('zero_size_image', 'empty.png')):
        g = base()
        g.doc['images'] = [{'uri': uri}]
        g.doc['textures'] = [{'source': 0}]
        g.doc['materials'][0]['pbrMetallicRoughness']['baseColorTexture'] = {'index': 0}
        g.write(os.path.join(out, name + '.gltf'))
    open(os.path.join(out, 'empty.png'), 'wb').close()

    g = base()  # an accessor that reads past the end of its buffer view
    g.doc['accessors'][0]['count'] = 3000
    g.write(os.path.join(out, 'accessor_overflow.gltf'))

    # light shapes' extras (README "Light shapes"), one problem each
    for name, extras in (('light_radius_negative', {'candela_light': {'radius': -0.1}}),
                         ('light_radius_string', {'candela_light': {'radius': 'big'}})):
        g = base()
        g.doc['nodes'][1]['extras'] = extras
        g.write(os.path.join(out, name + '.gltf'))
    for name, angle in (('sun_angle_180', 180.0), ('sun_angle_negative', -1.0)):
        g = base()
        g.lights[0]['type'] = 'directional'
        g.doc['nodes'][1]['extras'] = {'candela_light': {'angle': angle}}
        g.write(os.path.join(out, name + '.gltf'))
    for name, al in (('area_light_shape', {'shape': 'triangle', 'size': [1, 1], 'power': 10}),
                     ('area_light_size', {'shape': 'rect', 'size': [1, 0], 'power': 10}),
                     ('area_light_power', {'shape': 'disk', 'size': [1, 1], 'power': -5})):
        g = base()
        g.node('panel', (0.0, 0.0, 2.0), extras={'candela_area_light': al})
        g.write(os.path.join(out, name + '.gltf'))


def main():
    bench_scene()
    bad_inputs()
    default_scene()
    guiding_interior()
    cornell_boxes()
    furnace_sphere()
    point_plane()
    masked_planes()
    spot_plane()
    spot_blend_plane()
    directional_plane()
    area_plane()
    light_shapes()
    env_scenes()
    normalmap_grazing()
    two_lights()
    occluded_lights()
    glossy_lights()
    light_edge_cases()
    light_linking()


if __name__ == '__main__':
    main()
