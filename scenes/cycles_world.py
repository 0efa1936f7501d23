"""scenes/cycles_world.py: runs ../shared/tools/cycles_render.py inside Blender with a constant
world (the shared tool renders with no world: a black background). MANUAL VALIDATION ONLY
(Blender is never installed in CI).

    blender -b --factory-startup -noaudio --python scenes/cycles_world.py -- \
        --world-strength S [--world-env FILE.exr [--world-rotation DEG]] [--cycles-tool PATH]
        [every option of cycles_render.py]

The tool starts from empty factory settings, so the world is added by a persistent
render_pre handler, just before Cycles syncs the scene: a Background shader of colour
(1, 1, 1) and strength S, i.e. a constant environment radiance of S (Cycles' world units are
radiance; Candela's `--env` with a constant EXR of 1 and `--env-strength S` is the same sky).
scenes/cycles_volume_compare.py --world S uses this.

With --world-env the Background's colour is an Environment Texture of FILE (equirectangular,
Closest interpolation: Candela's lookup is piecewise constant) behind a Mapping node (type
Point) of Z rotation DEG fed by Texture Coordinate > Generated, the usual Blender world: the
Candela render to compare is `--env FILE --env-strength S --env-rotation DEG` (issue 14; checked
on tests/scenes/env_marked.gltf, README "Scene support").
"""
import math
import os
import runpy
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
strength = 0.0
if "--world-strength" in argv:
    i = argv.index("--world-strength")
    strength = float(argv[i + 1])
    del argv[i:i + 2]
env, rotation = None, 0.0
if "--world-env" in argv:
    i = argv.index("--world-env")
    env = os.path.abspath(argv[i + 1])
    del argv[i:i + 2]
if "--world-rotation" in argv:
    i = argv.index("--world-rotation")
    rotation = float(argv[i + 1])
    del argv[i:i + 2]
here = os.path.dirname(os.path.abspath(__file__))
tool = os.path.join(os.path.dirname(os.path.dirname(here)), "shared", "tools", "cycles_render.py")
if "--cycles-tool" in argv:
    i = argv.index("--cycles-tool")
    tool = argv[i + 1]
    del argv[i:i + 2]


@bpy.app.handlers.persistent
def add_world(scene, *unused):
    world = scene.world or bpy.data.worlds.new("candela_world")
    scene.world = world
    world.use_nodes = True
    bg = world.node_tree.nodes.get("Background") or world.node_tree.nodes.new("ShaderNodeBackground")
    out = world.node_tree.nodes.get("World Output") or world.node_tree.nodes.new("ShaderNodeOutputWorld")
    if not bg.outputs[0].links:
        world.node_tree.links.new(bg.outputs[0], out.inputs[0])
    bg.inputs[0].default_value = (1.0, 1.0, 1.0, 1.0)
    bg.inputs[1].default_value = strength
    if env and not bg.inputs[0].links:
        nt = world.node_tree
        tex = nt.nodes.new("ShaderNodeTexEnvironment")
        tex.image = bpy.data.images.load(env)
        tex.interpolation = "Closest"
        coords = nt.nodes.new("ShaderNodeTexCoord")
        mapping = nt.nodes.new("ShaderNodeMapping")
        mapping.vector_type = "POINT"
        mapping.inputs["Rotation"].default_value[2] = math.radians(rotation)
        nt.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], bg.inputs[0])
        print("cycles_world: environment %s, Z rotation %g degrees, strength %g" % (env, rotation, strength))
    else:
        print("cycles_world: constant world of strength %g" % strength)


bpy.app.handlers.render_pre.append(add_world)
sys.argv = [sys.argv[0], "--"] + argv
runpy.run_path(tool, run_name="__main__")
