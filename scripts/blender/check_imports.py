"""Imports a run's outputs into Blender the way a user would and reports what
Blender made of them (README's "which file for which tool" is checked with
this). Run headless, e.g. with Debian's Blender 3.4:

    blender -b -P scripts/blender/check_imports.py -- RUN_DIR [RENDER_PNG]

It imports every `result*.glb`, `result*.obj` and `result*.ply` in RUN_DIR
into an empty scene, one at a time, and prints one JSON line per file: the
mesh's vertex/face counts, UV layers, colour attributes, whether custom
normals were imported, and per material the image textures with the socket
they feed and their colour space. With RENDER_PNG it also renders
`result.obj` with Cycles from the preview's first camera (azimuth -35°,
elevation 20°, 35° field of view), so it can be compared with preview_0.png.
"""
import json
import math
import os
import sys

import bpy
from mathutils import Vector

try:
    # Debian's Blender 3.4 glTF importer still uses `numpy.bool`, which
    # bookworm's numpy 1.24 removed; restore the alias it meant.
    import numpy

    if not hasattr(numpy, "bool"):
        numpy.bool = bool
except ImportError:
    pass


def clear():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def import_file(path):
    ext = os.path.splitext(path)[1].lower()
    if ext == ".glb":
        bpy.ops.import_scene.gltf(filepath=path)
    elif ext == ".obj":
        bpy.ops.wm.obj_import(filepath=path)
    elif ext == ".ply":
        bpy.ops.import_mesh.ply(filepath=path)


def describe(path):
    clear()
    import_file(path)
    out = {"file": os.path.basename(path), "meshes": []}
    for ob in bpy.context.scene.objects:
        if ob.type != "MESH":
            continue
        me = ob.data
        info = {
            "vertices": len(me.vertices),
            "faces": len(me.polygons),
            "uv_layers": [uv.name for uv in me.uv_layers],
            "colour_attributes": [a.name for a in getattr(me, "color_attributes", [])],
            "custom_normals": bool(me.has_custom_normals),
            "materials": [],
        }
        for slot in ob.material_slots:
            mat = slot.material
            if mat is None or not mat.use_nodes:
                continue
            images = []
            for node in mat.node_tree.nodes:
                if node.type != "TEX_IMAGE" or node.image is None:
                    continue
                feeds = []
                for link in mat.node_tree.links:
                    if link.from_node == node:
                        feeds.append(f"{link.to_node.type}.{link.to_socket.name}")
                images.append({
                    "image": os.path.basename(node.image.filepath or node.image.name),
                    "colour_space": node.image.colorspace_settings.name,
                    "feeds": feeds,
                })
            info["materials"].append({"name": mat.name, "images": images})
        out["meshes"].append(info)
    print("CHECK " + json.dumps(out))


def render(obj_path, png):
    clear()
    import_file(obj_path)
    obs = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    lo = Vector((math.inf,) * 3)
    hi = Vector((-math.inf,) * 3)
    for o in obs:
        for v in o.data.vertices:
            p = o.matrix_world @ v.co
            lo = Vector(map(min, lo, p))
            hi = Vector(map(max, hi, p))
    centre = (lo + hi) / 2
    radius = (hi - lo).length / 2
    az, el, fov = math.radians(-35), math.radians(20), math.radians(35)
    # The preview renderer's view 0, in Blender's z-up world (the OBJ
    # importer turns the file's y-up into z-up).
    d = Vector((math.cos(el) * math.sin(az), -math.cos(el) * math.cos(az), math.sin(el)))
    dist = radius / math.sin(fov / 2) / 0.85
    cam_data = bpy.data.cameras.new("cam")
    cam_data.angle = fov
    cam = bpy.data.objects.new("cam", cam_data)
    bpy.context.scene.collection.objects.link(cam)
    cam.location = centre + d * dist
    cam.rotation_euler = (centre - cam.location).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = cam
    sun_data = bpy.data.lights.new("sun", "SUN")
    sun_data.energy = 3.0
    sun = bpy.data.objects.new("sun", sun_data)
    sun.rotation_euler = cam.rotation_euler
    bpy.context.scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("w")
    world.color = (0.6, 0.6, 0.6)
    bpy.context.scene.world = world
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 16
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = 512
    scene.render.filepath = png
    bpy.ops.render.render(write_still=True)
    print("CHECK " + json.dumps({"rendered": png}))


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    run_dir = argv[0]
    for name in sorted(os.listdir(run_dir)):
        if name.startswith("result") and name.endswith((".glb", ".obj", ".ply")):
            describe(os.path.join(run_dir, name))
    if len(argv) > 1:
        render(os.path.join(run_dir, "result.obj"), os.path.abspath(argv[1]))


main()
