#!/usr/bin/env python3
"""scenes/make_volumes.py: generates Candela's participating-media test volumes and scenes.

usage: python3 scenes/make_volumes.py [OUTDIR]      (default: build/scenes/volumes)

Needs Debian's python3-openvdb (module pyopenvdb) and python3-numpy (.ci/setup installs
both). They are installed for /usr/bin/python3: when the python3 on PATH cannot import them
(a pyenv or venv interpreter), the script re-runs itself with /usr/bin/python3.

Deterministic: the noise is value noise on an integer-hashed lattice, written here in numpy
(fixed seeds, no random generator, nothing downloaded), so running it twice gives identical
voxel data, and byte-identical .gltf and .exr files. The .vdb files differ between runs only
in the 36-byte UUID that OpenVDB writes into every file header (tests/test_volume_scenes.sh
checks exactly that). Total output is about 4 MB.

Conventions: glTF 2.0, Y-up, metres, Blender light units (cd, /683) as in make_scenes.py, whose
glTF writer and geometry this reuses. Volumes are the node extras "candela_volume" and media
the material extras "candela_medium" (README.md, "Participating media"). Each VDB's own
index-to-world transform is a uniform voxel size plus a translation (documented per file
below); the glTF node places it in the scene.

VDBs (float grids, class FOG_VOLUME, zero voxels inactive):
  smoke_plume.vdb  "density": a rising, widening, wavering plume, 64 x 128 x 64 voxels of
                   1/48 m (1.33 x 2.67 x 1.33 m, x and z centred, y from 0 up), values 0..1
  fireball.vdb     "density", "emission", "temperature": 64^3 voxels of 1/64 m (1 m box
                   centred on the origin); a hot core (temperature up to ~2500 K, emission up
                   to 1) of low density (~0.05) inside a denser smoky shell (up to ~0.6)
  mist.vdb         "density": thin heterogeneous mist filling the whole box, 96 x 48 x 96
                   voxels of 1/8 m (12 x 6 x 12 m, x and z centred, y from 0 up), 0.02..0.1
  dense_cloud.vdb  "density": a cumulus-like cloud, 128^3 voxels of 1/64 m (2 m box centred
                   on the origin), values up to 1 (meant for density_scale ~20)

Scenes (each with a ground plane, a camera and KHR_lights_punctual lights unless said):
  fig9_thin.gltf / fig9_thick.gltf  a small bright point light inside the smoke plume at
                   density_scale 1 / 20, plus one dim point light outside (the cache points
                   paper's Fig. 9 case: a light inside a heterogeneous medium of low / high
                   extinction)
  torch_mist.gltf  fireball.vdb (emission_grid "emission") on a torch pole inside mist.vdb
                   (anisotropy 0.7); a faint moonlight (Fig. 11)
  spots_atmosphere.gltf  four narrow spot lights (outer cone half-angles 2, 3, 4 and 6 degrees)
                   in mist.vdb stretched to 24 x 9 x 24 m at density_scale 0.5 (Fig. 12)
  cloud_point_env.gltf  the dense cloud (density_scale 20) lit by a point light, under a
                   constant sky (scene extras candela_environment -> sky_constant.exr)
  glass_absorb.gltf  a glass sphere (KHR_materials_transmission + candela_medium absorption)
                   and a glass cube (KHR_materials_volume) on a plane under a point light
  camera_in_fog.gltf  the camera inside a closed 30 x 10 x 30 m box whose (non-transmissive)
                   material has candela_medium: homogeneous fog with an invisible boundary;
                   pillars and four point lights inside
  cornell_cloud.gltf  the dense cloud (4.4 m, density_scale 8, albedo 0.9, g = 0.3) in the
                   Lambert Cornell box without its boxes, lit by the box's one area light
                   (the sample-quality benchmark's volume scene)
  sky_constant.exr  16 x 8 FLOAT EXR, every pixel (0.35, 0.45, 0.65)
"""

import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DEBIAN_PYTHON = '/usr/bin/python3'

try:
    import numpy as np
    import pyopenvdb as vdb
except ImportError as e:
    if (os.path.exists(DEBIAN_PYTHON)
            and os.path.realpath(sys.executable) != os.path.realpath(DEBIAN_PYTHON)):
        os.execv(DEBIAN_PYTHON, [DEBIAN_PYTHON] + sys.argv)
    sys.exit('make_volumes.py: %s (apt-get install python3-openvdb python3-numpy)' % e)

sys.path.insert(0, HERE)
import make_scenes as ms  # noqa: E402  (glTF writer, geometry, EXR writer)

# ----------------------------------------------------------------------------------------------
# noise: value noise on a hashed integer lattice, fBm


def _hash01(ix, iy, iz, seed):
    """Uniform [0, 1) per integer lattice point (int64 arrays, broadcast): murmur3's finaliser."""
    m = np.uint64(0xFFFFFFFF)
    h = ((ix.astype(np.uint64) * np.uint64(0x8DA6B343)) ^ (iy.astype(np.uint64) * np.uint64(0xD8163841))
         ^ (iz.astype(np.uint64) * np.uint64(0xCB1AB31F)) ^ np.uint64((seed * 0x9E3779B9) & 0xFFFFFFFF)) & m
    h ^= h >> np.uint64(16)
    h = (h * np.uint64(0x85EBCA6B)) & m
    h ^= h >> np.uint64(13)
    h = (h * np.uint64(0xC2B2AE35)) & m
    h ^= h >> np.uint64(16)
    return h.astype(np.float64) * (1.0 / 4294967296.0)


def value_noise(xs, ys, zs, seed):
    """Smooth (quintic-interpolated) value noise in [0, 1), lattice spacing 1, on the grid
    xs x ys x zs (1-D coordinate arrays; the result has shape (len(xs), len(ys), len(zs))).
    The lattice values under the grid are hashed once, then interpolated one axis at a time."""
    def axis(t):
        f = np.floor(t)
        u = t - f
        return f.astype(np.int64), u * u * u * (u * (u * 6 - 15) + 10)
    (ix, ux), (iy, uy), (iz, uz) = axis(xs), axis(ys), axis(zs)
    lx, ly, lz = [np.arange(i.min(), i.max() + 2, dtype=np.int64) for i in (ix, iy, iz)]
    lattice = _hash01(lx[:, None, None], ly[None, :, None], lz[None, None, :], seed)
    ix, iy, iz = ix - lx[0], iy - ly[0], iz - lz[0]
    a = lattice[ix] + (lattice[ix + 1] - lattice[ix]) * ux[:, None, None]
    b = a[:, iy] + (a[:, iy + 1] - a[:, iy]) * uy[None, :, None]
    return b[:, :, iz] + (b[:, :, iz + 1] - b[:, :, iz]) * uz[None, None, :]


def fbm(xs, ys, zs, seed, octaves=5, freq=1.0, gain=0.5):
    """Fractal sum of value noise on the grid xs x ys x zs (1-D arrays), normalised to [0, 1)."""
    total, amp, norm = 0.0, 1.0, 0.0
    for o in range(octaves):
        total = total + amp * value_noise(xs * freq, ys * freq, zs * freq, seed + 101 * o)
        norm += amp
        amp *= gain
        freq *= 2.0
    return total / norm


def smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


# ----------------------------------------------------------------------------------------------
# VDB writing


class Box:
    """A dense voxel box: dims (nx, ny, nz), voxel size vs, world position of voxel (0,0,0)."""

    def __init__(self, dims, vs, origin):
        self.dims, self.vs, self.origin = dims, vs, origin

    def axes(self):
        """Voxel-centre coordinates along x, y and z (three 1-D arrays)."""
        return [self.origin[a] + self.vs * np.arange(self.dims[a], dtype=np.float64) for a in range(3)]

    def coords(self):
        """World-space voxel centres as three (nx, ny, nz) arrays (x, y, z)."""
        return np.meshgrid(*self.axes(), indexing='ij')

    def transform(self):
        vs, (ox, oy, oz) = self.vs, self.origin
        return vdb.createLinearTransform([[vs, 0, 0, 0], [0, vs, 0, 0], [0, 0, vs, 0], [ox, oy, oz, 1]])


def make_grid(name, values, box, cutoff=0.0):
    """A float grid from values[i, j, k] at index (i, j, k); values <= cutoff become 0 (inactive)."""
    v = np.where(values > cutoff, values, 0.0).astype(np.float32)
    g = vdb.FloatGrid(0.0)
    g.copyFromArray(v, ijk=(0, 0, 0), tolerance=0)
    g.name = name
    g.gridClass = vdb.GridClass.FOG_VOLUME
    g.transform = box.transform()
    return g, v


def write_vdb(out, filename, grids):
    path = os.path.join(out, filename)
    vdb.write(path, grids=[g for g, _ in grids])
    desc = ', '.join('%s %d active, %.3g..%.3g' % (g.name, g.activeVoxelCount(), v[v > 0].min(), v.max())
                     for g, v in grids)
    print('wrote %s (%d bytes): %s' % (os.path.relpath(path, ROOT), os.path.getsize(path), desc))


PLUME_HEIGHT = 128 / 48


def plume_centre(y):
    """The plume's axis at height y (local metres): it wavers and drifts as it rises."""
    h = y / PLUME_HEIGHT
    return 0.10 * np.sin(2.3 * y) * h + 0.12 * h * h, 0.07 * np.cos(1.7 * y + 0.5) * h


def smoke_plume(out):
    box = Box((64, 128, 64), 1.0 / 48, (-31.5 / 48, 0.5 / 48, -31.5 / 48))
    x, y, z = box.coords()
    ax, ay, az = box.axes()
    h = y / PLUME_HEIGHT                                 # 0 at the source, 1 at the top
    cx, cz = plume_centre(y)
    radius = 0.06 + 0.38 * h ** 0.85
    d = np.sqrt((x - cx) ** 2 + (z - cz) ** 2) / radius
    n = fbm(ax * 3.0, (ay - 0.15) * 2.2, az * 3.0, seed=11, octaves=5)   # stretched upward
    shape = np.exp(-2.5 * d * d) * (1.0 - smoothstep(0.65, 1.0, h)) * smoothstep(0.0, 0.04, h)
    dens = np.clip(shape * (0.35 + 1.1 * n) * (1.15 - 0.6 * h), 0.0, 1.0)
    write_vdb(out, 'smoke_plume.vdb', [make_grid('density', dens, box, cutoff=0.01)])


def fireball(out):
    box = Box((64, 64, 64), 1.0 / 64, (-31.5 / 64,) * 3)
    x, y, z = box.coords()
    ax, ay, az = box.axes()
    n1 = fbm(ax * 4.0, ay * 4.0 - 0.7, az * 4.0, seed=23, octaves=4)
    n2 = fbm(ax * 7.0 + 3.1, ay * 7.0, az * 7.0, seed=29, octaves=3)
    # radius 0.36 m, stretched upward, surface displaced by noise (stays inside the box): r < 1 inside
    r = np.sqrt(x * x + (y / 1.1) ** 2 + z * z) / 0.36 + 0.35 * (n1 - 0.5)
    inside = r < 1.0
    heat = np.clip(1.0 - r, 0.0, 1.0)                    # 1 at the centre, 0 at the surface
    temperature = np.where(inside, 600.0 + 1900.0 * heat ** 1.2 * (0.85 + 0.3 * n2), 0.0)
    emission = np.where(inside, np.clip((temperature - 900.0) / 1600.0, 0.0, 1.0) ** 2 * (0.6 + 0.8 * n2), 0.0)
    emission = np.clip(emission, 0.0, 1.0)
    # low extinction in the hot core, a denser smoky shell
    density = np.where(inside, 0.05 + 0.55 * smoothstep(0.35, 0.9, r) * (0.6 + 0.8 * n1) * (1.0 - smoothstep(0.9, 1.0, r)), 0.0)
    density = np.clip(density, 0.0, 1.0)
    write_vdb(out, 'fireball.vdb', [make_grid('density', density, box, cutoff=0.005),
                                    make_grid('emission', emission, box, cutoff=0.001),
                                    make_grid('temperature', temperature, box, cutoff=1.0)])


def mist(out):
    box = Box((96, 48, 96), 1.0 / 8, (-47.5 / 8, 0.5 / 8, -47.5 / 8))
    x, y, z = box.coords()
    ax, ay, az = box.axes()
    n = fbm(ax * 0.35, ay * 0.5, az * 0.35, seed=37, octaves=4)
    ground = 1.0 - 0.45 * (y / 6.0)                     # a little thicker near the ground
    dens = 0.02 + 0.08 * np.clip((n - 0.25) * 2.0 * ground, 0.0, 1.0)
    write_vdb(out, 'mist.vdb', [make_grid('density', dens, box)])


def dense_cloud(out):
    box = Box((128, 128, 128), 1.0 / 64, (-63.5 / 64,) * 3)
    x, y, z = box.coords()
    # union of blobs (centre, radius) in metres: a cumulus with a flattened base
    blobs = [((0.0, -0.1, 0.0), 0.55), ((0.42, -0.25, 0.1), 0.38), ((-0.45, -0.22, -0.05), 0.40),
             ((0.1, 0.28, -0.05), 0.42), ((-0.15, 0.05, 0.38), 0.36), ((0.2, -0.2, -0.4), 0.34)]
    sdf = np.full(x.shape, 1e9)
    for (bx, by, bz), br in blobs:
        sdf = np.minimum(sdf, np.sqrt((x - bx) ** 2 + (y - by) ** 2 + (z - bz) ** 2) - br)
    sdf = np.maximum(sdf, -(y + 0.45))                  # flat base at y = -0.45
    ax, ay, az = box.axes()
    n = fbm(ax * 3.0, ay * 3.0, az * 3.0, seed=53, octaves=5)
    d = sdf + 0.22 * (n - 0.5)                           # billowy surface
    dens = smoothstep(0.0, 0.12, -d) * (0.75 + 0.25 * fbm(ax * 8.0, ay * 8.0, az * 8.0, seed=59, octaves=3))
    dens = np.clip(dens, 0.0, 1.0)
    write_vdb(out, 'dense_cloud.vdb', [make_grid('density', dens, box, cutoff=0.002)])


# ----------------------------------------------------------------------------------------------
# scenes


def volume_node(g, name, uri, translation=None, scale=None, rotation=None, **params):
    vol = {'uri': uri}
    for k, v in params.items():
        vol[k] = ms.rv(v) if isinstance(v, (list, tuple)) else (ms.r(v) if isinstance(v, float) else v)
    return g.node(name, translation, rotation, scale, extras={'candela_volume': vol})


def medium_extras(g, material, sigma_a, sigma_s, anisotropy=0.0):
    g.doc['materials'][material]['extras'] = {'candela_medium': {
        'sigma_a': ms.rv(sigma_a), 'sigma_s': ms.rv(sigma_s), 'anisotropy': ms.r(anisotropy)}}


def ground(g, half=ms.PLANE_HALF, albedo=0.5):
    m = g.material('ground', base=(albedo, albedo, albedo), lambert=True)
    g.mesh('ground', 'ground_%g' % half, ms.quad((-half, 0.0, -half), (-half, 0.0, half),
                                                  (half, 0.0, half), (half, 0.0, -half)), m)


def new_gltf():
    return ms.Gltf(generator='candela scenes/make_volumes.py')


def fig9(out, thick):
    """A small bright point light on the axis of the smoke plume (scaled 1.5x: 2 m wide, 4 m
    tall), 1.5 m up, seen from outside; a dim light outside. Thin: density_scale 1 (optical
    depth across the plume ~0.3, the light shines through); thick: 20 (~6: the light is
    buried and lights the smoke around it)."""
    g = new_gltf()
    ground(g)
    s = 1.5
    volume_node(g, 'plume', 'smoke_plume.vdb', scale=(s, s, s),
                density_scale=20.0 if thick else 1.0, albedo=(0.9, 0.9, 0.9), anisotropy=0.3)
    cx, cz = plume_centre(1.5 / s)
    g.light('inner_light', 'point', 3000.0, color=(1.0, 0.85, 0.6), translation=(s * cx, 1.5, s * cz))
    g.light('outer_light', 'point', 400.0, color=(0.7, 0.8, 1.0), translation=(3.0, 3.5, 2.0))
    g.perspective('camera', (0.0, 2.0, 7.0), (0.0, 1.8, 0.0), 45.0, aspect=4 / 3)
    g.write(os.path.join(out, 'fig9_thick.gltf' if thick else 'fig9_thin.gltf'))


def torch_mist(out):
    """A torch: a pole with the fireball (0.5 m wide, emission grid) on top, inside the 12 x 6
    x 12 m mist (forward scattering, g = 0.7), a faint bluish moonlight. emission_scale 300 is
    meant for the source term sigma_a L_e: the core's sigma_a is about 0.14/m."""
    g = new_gltf()
    ground(g)
    wood = g.material('wood', base=(0.25, 0.15, 0.08), lambert=True)
    g.mesh('pole', 'pole', ms.box(0.06, 1.2, 0.06), wood, translation=(0.0, 0.6, 0.0))
    volume_node(g, 'mist', 'mist.vdb', density_scale=1.0, albedo=(0.95, 0.95, 0.95), anisotropy=0.7)
    volume_node(g, 'fire', 'fireball.vdb', translation=(0.0, 1.45, 0.0), scale=(0.5, 0.5, 0.5),
                density_scale=4.0, albedo=(0.3, 0.3, 0.3), anisotropy=0.0, emission_grid='emission',
                emission_scale=300.0, emission_color=(1.0, 0.55, 0.2))
    g.light('moon', 'directional', 30.0, color=(0.6, 0.7, 1.0),
            rotation=ms.look_rotation((0.3, -1.0, -0.5)))
    g.perspective('camera', (0.0, 1.5, 5.0), (0.0, 1.2, 0.0), 50.0, aspect=16 / 9)
    g.write(os.path.join(out, 'torch_mist.gltf'))


def spots_atmosphere(out):
    """Four narrow spot lights 8 m up, beams slightly tilted, in the mist stretched to a
    24 x 9 x 24 m atmosphere (density_scale 0.5: sigma_t 0.01..0.05/m). Outer cone half-angles
    2, 3, 4, 6 degrees, inner = 0.75 x outer."""
    g = new_gltf()
    ground(g)
    volume_node(g, 'atmosphere', 'mist.vdb', scale=(2.0, 1.5, 2.0), density_scale=0.5,
                albedo=(0.95, 0.95, 0.95), anisotropy=0.5)
    spots = [(-6.0, 2.0, (1.0, 0.9, 0.75)), (-2.0, 3.0, (0.75, 0.85, 1.0)),
             (2.0, 4.0, (1.0, 0.75, 0.6)), (6.0, 6.0, (0.8, 1.0, 0.8))]
    for i, (x, deg, color) in enumerate(spots):
        pos = (x, 8.0, -2.0)
        target = (x * 0.6, 0.0, -1.0 + 0.5 * i)
        outer = math.radians(deg)
        g.light('spot_%d_%gdeg' % (i, deg), 'spot', 50000.0, color=color, translation=pos,
                rotation=ms.look_rotation(ms.sub(target, pos)), inner=0.75 * outer, outer=outer)
    g.perspective('camera', (0.0, 3.0, 14.0), (0.0, 3.5, 0.0), 50.0, aspect=16 / 9)
    g.write(os.path.join(out, 'spots_atmosphere.gltf'))


SKY = (0.35, 0.45, 0.65)


def cloud_point_env(out):
    """The dense cloud scaled to 3 m at density_scale 20, high albedo, forward scattering; a
    point light above and to the side; a constant sky."""
    ms.write_exr(os.path.join(out, 'sky_constant.exr'), 16, 8, lambda px, py: SKY)
    g = new_gltf()
    ground(g)
    volume_node(g, 'cloud', 'dense_cloud.vdb', translation=(0.0, 2.2, 0.0), scale=(1.5, 1.5, 1.5),
                density_scale=20.0, albedo=(0.98, 0.98, 0.98), anisotropy=0.6)
    g.light('sun_point', 'point', 8000.0, color=(1.0, 0.95, 0.85), translation=(2.5, 4.5, 1.5))
    g.environment('sky_constant.exr', 1.0)
    g.perspective('camera', (0.0, 1.8, 7.0), (0.0, 2.0, 0.0), 45.0, aspect=4 / 3)
    g.write(os.path.join(out, 'cloud_point_env.gltf'))


def cornell_cloud(out):
    """The dense cloud scaled to 4.4 m at density_scale 8 (albedo 0.9, mildly forward
    scattering) in the middle of the Lambert Cornell box (make_scenes.cornell_room, without its
    two boxes), lit only by the box's area light: one light, multiple scattering and the walls'
    interreflection."""
    g = new_gltf()
    ms.cornell_room(g, boxes=False)
    volume_node(g, 'cloud', 'dense_cloud.vdb', translation=(0.0, 2.5, 0.0), scale=(2.2, 2.2, 2.2),
                density_scale=8.0, albedo=(0.9, 0.9, 0.9), anisotropy=0.3)
    g.write(os.path.join(out, 'cornell_cloud.gltf'))


def glass_absorb(out):
    """Coloured glass: a smooth glass sphere (r 0.5 m) whose inside absorbs with candela_medium
    sigma_a (0.3, 2, 4)/m (amber: e^-sigma_a over its 1 m diameter is 0.74, 0.14, 0.02), and a
    glass cube (0.7 m) with KHR_materials_volume, attenuationColor (0.4, 0.7, 0.9) at 0.5 m
    (blue-green: sigma_a = -ln(c)/d = 1.83, 0.71, 0.21 /m), on a plane under a point light."""
    g = new_gltf()
    ground(g)
    amber = g.material('amber_glass', base=(1.0, 1.0, 1.0), roughness=0.0, transmission=1.0, ior=1.5)
    medium_extras(g, amber, (0.3, 2.0, 4.0), (0.0, 0.0, 0.0))
    teal = g.material('teal_glass', base=(1.0, 1.0, 1.0), roughness=0.0, transmission=1.0, ior=1.5)
    g.use('KHR_materials_volume')
    g.doc['materials'][teal]['extensions']['KHR_materials_volume'] = {
        'thicknessFactor': 0.7, 'attenuationDistance': 0.5, 'attenuationColor': [0.4, 0.7, 0.9]}
    g.mesh('amber_sphere', 'sphere', ms.uv_sphere(0.5, segments=48, rings=24), amber,
           translation=(-0.7, 0.5, 0.0))
    g.mesh('teal_cube', 'cube', ms.box(0.7, 0.7, 0.7), teal, translation=(0.8, 0.35, -0.1),
           rotation=ms.quat_axis_angle((0, 1, 0), math.radians(25)))
    g.light('key', 'point', 12000.0, color=(1.0, 0.97, 0.92), translation=(0.5, 3.0, 1.5))
    g.perspective('camera', (0.0, 1.3, 3.4), (0.0, 0.4, 0.0), 45.0, aspect=4 / 3)
    g.write(os.path.join(out, 'glass_absorb.gltf'))


def camera_in_fog(out):
    """The camera inside a closed 30 x 10 x 30 m box (y from -1 to 9) whose material carries
    candela_medium sigma_a 0.005, sigma_s (0.04, 0.04, 0.045)/m, g 0.3 and no transmission:
    the box is an invisible boundary around a homogeneous fog. Inside: a 28 m ground square,
    four pillars and four warm point lights in a row."""
    g = new_gltf()
    ground(g, half=14.0)
    fog = g.material('fog_boundary', base=(0.5, 0.5, 0.5), lambert=True)
    medium_extras(g, fog, (0.005, 0.005, 0.005), (0.04, 0.04, 0.045), 0.3)
    g.mesh('fog_box', 'fog_box', ms.box(30.0, 10.0, 30.0, center=(0.0, 4.0, 0.0)), fog)
    stone = g.material('stone', base=(0.6, 0.58, 0.55), lambert=True)
    for i, (x, z) in enumerate([(-2.5, -1.0), (2.5, -1.0), (-2.5, -7.0), (2.5, -7.0)]):
        g.mesh('pillar_%d' % i, 'pillar', ms.box(0.6, 5.0, 0.6), stone, translation=(x, 2.5, z))
    for i, z in enumerate((2.0, -4.0, -10.0, -13.0)):
        g.light('lamp_%d' % i, 'point', 1500.0, color=(1.0, 0.8, 0.55), translation=(0.0, 3.0, z))
    g.perspective('camera', (0.0, 1.7, 11.0), (0.0, 2.2, 0.0), 55.0, aspect=16 / 9)
    g.write(os.path.join(out, 'camera_in_fog.gltf'))


def main():
    out = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, 'build', 'scenes', 'volumes'))
    os.makedirs(out, exist_ok=True)
    smoke_plume(out)
    fireball(out)
    mist(out)
    dense_cloud(out)
    fig9(out, thick=False)
    fig9(out, thick=True)
    torch_mist(out)
    spots_atmosphere(out)
    cloud_point_env(out)
    cornell_cloud(out)
    glass_absorb(out)
    camera_in_fog(out)
    total = sum(os.path.getsize(os.path.join(out, f)) for f in os.listdir(out))
    print('total %.1f MB in %s' % (total / 1e6, out))


if __name__ == '__main__':
    main()
