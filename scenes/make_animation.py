#!/usr/bin/env python3
"""scenes/make_animation.py: generates scenes/animation.gltf, the animated demo for --frames.

Python 3 standard library only, deterministic (byte-identical output on every run); builds on
make_scenes.py's glTF writer. The scene is a small room (4 x 3 x 4 m, Blender light units)
with a 2-second animation, 48 frames at 24 fps (`candela render scenes/animation.gltf
--frames 1-48`; frame f is time f / 24 s, frame 0 the start):

  camera        fly-through: translation LINEAR along a curve from the front of the room to
                its right side, rotation LINEAR (slerp) keyed every 1/8 s looking at a target
                that drifts across the room
  orbit_light   a point light circling under the ceiling once: translation CUBICSPLINE (in-
                tangent, value, out-tangent per key; tangents in m/s, the exact derivative
                of the circle, so the spline stays close to it)
  bouncing_ball a sphere bouncing on the floor: translation LINEAR, keyed every 1/12 s
  step_cube     an emissive cube turning in 45 degree steps: rotation STEP, every 0.25 s
  box           a static box (an instance that never moves)
"""

import math
import os
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import make_scenes as ms  # noqa: E402

DURATION = 2.0


def accessor(g, floats, count, type_, with_bounds):
    data = struct.pack('<%df' % len(floats), *[ms.f32(x) for x in floats])
    view = g._view(data, None)
    del g.doc['bufferViews'][view]['target']  # animation data is no vertex or index buffer
    acc = {'bufferView': view, 'componentType': 5126, 'count': count, 'type': type_}
    if with_bounds:
        acc['min'] = [min(ms.f32(x) for x in floats)]
        acc['max'] = [max(ms.f32(x) for x in floats)]
    g.doc['accessors'].append(acc)
    return len(g.doc['accessors']) - 1


def animate(g, anim, node, path, times, values, interpolation='LINEAR'):
    """values: one tuple per key (three per key for CUBICSPLINE: in-tangent, value, out-tangent)."""
    ncomp = len(values[0])
    inp = accessor(g, list(times), len(times), 'SCALAR', True)
    out = accessor(g, [c for v in values for c in v], len(values), 'VEC4' if ncomp == 4 else 'VEC3', False)
    anim['samplers'].append({'input': inp, 'output': out, 'interpolation': interpolation})
    anim['channels'].append({'sampler': len(anim['samplers']) - 1, 'target': {'node': node, 'path': path}})


def camera_path(t):
    u = t / DURATION
    pos = (-1.2 + 2.6 * u, 1.3 + 0.4 * math.sin(math.pi * u), 1.9 - 0.9 * u * u)
    target = (-0.6 + 1.0 * u, 0.6, -1.0 + 0.4 * u)
    return pos, target


def main():
    g = ms.Gltf('candela scenes/make_animation.py')
    white = g.material('white_wall', base=(0.8, 0.8, 0.8), lambert=True)
    red = g.material('red_wall', base=(0.7, 0.08, 0.06), lambert=True)
    green = g.material('green_wall', base=(0.1, 0.6, 0.12), lambert=True)
    floor_m = g.material('floor', base=(0.75, 0.72, 0.65), roughness=0.9)
    box_m = g.material('diffuse_box', base=(0.75, 0.55, 0.3), lambert=True)
    ball_m = g.material('blue_ball', base=(0.15, 0.3, 0.8), roughness=0.3)
    glow = g.material('glow', base=(0.0, 0.0, 0.0), lambert=True, emissive=(1.0, 0.55, 0.2), strength=4.0)

    X, Y, Z = 2.0, 3.0, 2.0
    g.mesh('floor', 'floor', ms.quad((-X, 0, -Z), (-X, 0, Z), (X, 0, Z), (X, 0, -Z)), floor_m)
    g.mesh('ceiling', 'ceiling', ms.quad((-X, Y, -Z), (X, Y, -Z), (X, Y, Z), (-X, Y, Z)), white)
    g.mesh('back_wall', 'back', ms.quad((-X, 0, -Z), (X, 0, -Z), (X, Y, -Z), (-X, Y, -Z)), white)
    g.mesh('front_wall', 'front', ms.quad((-X, 0, Z), (-X, Y, Z), (X, Y, Z), (X, 0, Z)), white)
    g.mesh('left_wall_red', 'left', ms.quad((-X, 0, -Z), (-X, Y, -Z), (-X, Y, Z), (-X, 0, Z)), red)
    g.mesh('right_wall_green', 'right', ms.quad((X, 0, -Z), (X, 0, Z), (X, Y, Z), (X, Y, -Z)), green)
    g.mesh('box', 'tallbox', ms.box(0.6, 1.0, 0.6), box_m, translation=(-1.0, 0.5, -1.0),
           rotation=ms.quat_axis_angle((0, 1, 0), math.radians(20)))
    ball = g.mesh('bouncing_ball', 'sphere', ms.uv_sphere(0.3, 24, 12), ball_m, translation=(0.6, 0.3, -0.6))
    cube = g.mesh('step_cube', 'cube', ms.box(0.35, 0.35, 0.35), glow, translation=(0.2, 0.175, 0.4))
    light = g.light('orbit_light', 'point', 2500.0, color=(1.0, 0.95, 0.88), translation=(0.0, 2.5, 0.0))
    pos0, target0 = camera_path(0.0)
    cam = g.perspective('camera', pos0, target0, 60.0, aspect=4 / 3)

    anim = {'name': 'shot', 'channels': [], 'samplers': []}
    # camera: translation and rotation keyed every 1/8 s
    times = [DURATION * k / 16 for k in range(17)]
    animate(g, anim, cam, 'translation', times, [ms.rv(camera_path(t)[0]) for t in times])
    rots = []
    for t in times:
        pos, target = camera_path(t)
        q = ms.look_rotation(ms.sub(target, pos))
        if rots and sum(a * b for a, b in zip(q, rots[-1])) < 0:  # the same hemisphere as the previous key
            q = tuple(-c for c in q)
        rots.append(ms.rv(q, 8))
    animate(g, anim, cam, 'rotation', times, rots)
    # the light: one circle of radius 1.2 at height 2.5, CUBICSPLINE with exact tangents
    times = [DURATION * k / 8 for k in range(9)]
    keys = []
    w = 2 * math.pi / DURATION
    for t in times:
        a = w * t
        p = (1.2 * math.cos(a), 2.5, 1.2 * math.sin(a))
        v = (-1.2 * w * math.sin(a), 0.0, 1.2 * w * math.cos(a))
        keys += [ms.rv(v), ms.rv(p), ms.rv(v)]
    animate(g, anim, light, 'translation', times, keys, 'CUBICSPLINE')
    # the ball: two bounces, |sin| arcs keyed every 1/12 s
    times = [DURATION * k / 24 for k in range(25)]
    animate(g, anim, ball, 'translation', times,
            [ms.rv((0.6 - 0.4 * t, 0.3 + 1.0 * abs(math.sin(2 * math.pi * t / DURATION)), -0.6 + 0.3 * t))
             for t in times])
    # the cube: 45 degree steps about +Y every 0.25 s
    times = [DURATION * k / 8 for k in range(9)]
    animate(g, anim, cube, 'rotation', times,
            [ms.rv(ms.quat_axis_angle((0, 1, 0), math.radians(45 * k)), 8) for k in range(9)], 'STEP')
    g.doc['animations'] = [anim]
    g.write(os.path.join(ms.ROOT, 'scenes', 'animation.gltf'))


if __name__ == '__main__':
    main()
