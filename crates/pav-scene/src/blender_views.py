# Renders the views of one job with Blender Cycles; run by `pav views render` as
#   blender -b --factory-startup -P blender_views.py -- JOB.json
# The Rust side computes every camera and writes the mesh already in pav's world frame (+Y up),
# so this script does no camera math of its own: it maps pav's frame to Blender's (+Z up) with
# one rotation applied to the mesh and the cameras alike. One line per finished view goes to
# stdout: "pav-view <name> <seconds>".
import json
import math
import sys
import time

import bpy
from mathutils import Matrix

job = json.load(open(sys.argv[sys.argv.index("--") + 1]))

# pav's world (x, y, z) with +Y up → Blender's (x, -z, y) with +Z up.
PAV_TO_BLENDER = Matrix(((1, 0, 0, 0), (0, 0, -1, 0), (0, 1, 0, 0), (0, 0, 0, 1)))

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = job["samples"]
scene.cycles.use_denoising = False  # Debian's build has no OpenImageDenoise
scene.cycles.seed = job.get("seed", 0)
scene.render.resolution_x = job["size"]
scene.render.resolution_y = job["size"]
scene.render.resolution_percentage = 100
if job.get("rows") is not None:
    # A landscape frame: only its rows, the centre of the square, are rendered and written.
    side, rows = job["size"], job["rows"]
    y0 = (side - rows) // 2
    scene.render.use_border = True
    scene.render.use_crop_to_border = True
    scene.render.border_min_x, scene.render.border_max_x = 0.0, 1.0
    # Half a pixel inside each edge, so Blender's rounding lands on whole rows.
    scene.render.border_min_y = (y0 + 0.5) / side - 0.5 / side
    scene.render.border_max_y = (y0 + rows) / side
scene.render.dither_intensity = 0.0
scene.render.image_settings.file_format = "PNG"
RAW = job["mode"] == "uv" or job.get("raw", False)
scene.render.image_settings.color_mode = "RGBA" if RAW else "RGB"
scene.render.image_settings.color_depth = "16" if RAW else "8"
if RAW:
    # Raw values out: a UV or texel code must not pass through a view transform, and every
    # sample lands on its pixel's centre so the comparison is with pav's centre-sampled
    # rasterizer.
    scene.view_settings.view_transform = "Raw"
    scene.render.film_transparent = True
    scene.cycles.filter_type = "BOX"
    scene.cycles.filter_width = 0.01
    scene.cycles.max_bounces = 0
else:
    scene.view_settings.view_transform = "Standard"
    if job.get("transparent"):
        # The car and its caught shadow over nothing: pav lays them over a background plate.
        scene.render.film_transparent = True
        scene.render.image_settings.color_mode = "RGBA"
    scene.cycles.max_bounces = job.get("max_bounces", 4)
    scene.cycles.caustics_reflective = False
    scene.cycles.caustics_refractive = False

# The mesh, in pav's frame, imported without any axis change of the importer's own.
bpy.ops.import_scene.obj(
    filepath=job["mesh"], axis_forward="Y", axis_up="Z", split_mode="OFF", use_image_search=False
)
car = [o for o in bpy.context.selected_objects if o.type == "MESH"]
if not car:
    raise SystemExit("pav: the OBJ importer made no mesh object from " + job["mesh"])
for o in car:
    o.matrix_world = PAV_TO_BLENDER @ o.matrix_world


def srgb_to_linear(rgb):
    # Blender's colour sockets are scene-linear; configs give colours as they look (sRGB).
    return tuple(c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgb)


def uv_node(nt):
    uv = nt.nodes.new("ShaderNodeUVMap")
    return uv.outputs["UV"]


def material():
    m = bpy.data.materials.new("pav")
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    if job["mode"] == "uv":
        # The interpolated UV itself, exactly: R = u, G = v.
        em = nt.nodes.new("ShaderNodeEmission")
        nt.links.new(uv_node(nt), em.inputs["Color"])
        nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
        return m
    # pav samples textures with align_corners = True (u = 0 and 1 are the centres of the first
    # and last columns); Blender's u = 0 is the left edge. Map u → (u·(W−1) + ½)/W, same for v.
    w, h = job["tex_size"]
    mp = nt.nodes.new("ShaderNodeMapping")
    mp.inputs["Scale"].default_value = ((w - 1) / w, (h - 1) / h, 1.0)
    mp.inputs["Location"].default_value = (0.5 / w, 0.5 / h, 0.0)
    nt.links.new(uv_node(nt), mp.inputs["Vector"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(job["texture"])
    if RAW:
        tex.image.colorspace_settings.name = "Non-Color"
    tex.interpolation = job.get("interpolation", "Linear")
    tex.extension = "EXTEND"
    nt.links.new(mp.outputs["Vector"], tex.inputs["Vector"])
    if job["mode"] == "emission":
        em = nt.nodes.new("ShaderNodeEmission")
        nt.links.new(tex.outputs["Color"], em.inputs["Color"])
        nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    else:
        # Car paint: the texture as base colour under a clear coat.
        bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
        nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
        bsdf.inputs["Metallic"].default_value = job.get("metallic", 0.3)
        bsdf.inputs["Roughness"].default_value = job.get("roughness", 0.35)
        bsdf.inputs["Clearcoat"].default_value = job.get("clearcoat", 0.5)
        bsdf.inputs["Specular"].default_value = job.get("specular", 0.5)
        nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return m


mat = material()
for o in car:
    o.data.materials.clear()
    o.data.materials.append(mat)

world = bpy.data.worlds.new("pav")
scene.world = world
world.use_nodes = True
bg = world.node_tree.nodes["Background"]
env_turn = None
if job["mode"] == "uv" or job.get("environment") is None:
    bg.inputs["Strength"].default_value = 0.0
else:
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(job["environment"])
    world.node_tree.links.new(env.outputs["Color"], bg.inputs["Color"])
    # Turning the environment with the camera (per view, below) turns the car in a fixed room.
    env_turn = world.node_tree.nodes.new("ShaderNodeMapping")
    coords = world.node_tree.nodes.new("ShaderNodeTexCoord")
    world.node_tree.links.new(coords.outputs["Generated"], env_turn.inputs["Vector"])
    world.node_tree.links.new(env_turn.outputs["Vector"], env.inputs["Vector"])
    bg.inputs["Strength"].default_value = job.get("env_strength", 1.0)
    if job.get("backdrop") is not None:
        # A rig's room: the map lights the scene, but camera rays see a plain backdrop (as a
        # studio sweep behind a turntable), so nothing in the map can be filmed or detected.
        seen = world.node_tree.nodes.new("ShaderNodeBackground")
        seen.inputs["Color"].default_value = srgb_to_linear(job["backdrop"]) + (1.0,)
        seen.inputs["Strength"].default_value = 1.0
        path = world.node_tree.nodes.new("ShaderNodeLightPath")
        mix = world.node_tree.nodes.new("ShaderNodeMixShader")
        world.node_tree.links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
        world.node_tree.links.new(bg.outputs["Background"], mix.inputs[1])
        world.node_tree.links.new(seen.outputs["Background"], mix.inputs[2])
        world.node_tree.links.new(mix.outputs["Shader"], world.node_tree.nodes["World Output"].inputs["Surface"])

if job.get("shadows") and job["mode"] == "pbr":
    # A shadow-catcher ground under the wheels (pav's lowest y, i.e. Blender's lowest z).
    bpy.ops.mesh.primitive_plane_add(size=job["ground_size"], location=(0, 0, job["ground_y"]))
    ground = bpy.context.active_object
    ground.is_shadow_catcher = True

if job.get("table") is not None and job["mode"] == "pbr":
    # The turntable's top: a matte disc whose surface is at the ground height. It is round and
    # plain, so turning the camera round it is the same picture as turning it.
    t = job["table"]
    bpy.ops.mesh.primitive_cylinder_add(
        vertices=128, radius=t["radius"], depth=t["radius"] * 0.1, location=(0, 0, job["ground_y"] - t["radius"] * 0.05)
    )
    top = bpy.context.active_object
    tm = bpy.data.materials.new("pav-table")
    tm.use_nodes = True
    tb = tm.node_tree.nodes["Principled BSDF"]
    tb.inputs["Base Color"].default_value = srgb_to_linear(t["colour"]) + (1.0,)
    tb.inputs["Roughness"].default_value = 0.8
    tb.inputs["Specular"].default_value = 0.3
    top.data.materials.append(tm)

cam_data = bpy.data.cameras.new("pav")
cam_data.sensor_fit = "HORIZONTAL"
cam_data.clip_start = job.get("znear", 1e-3)
cam_data.clip_end = 1e4
cam = bpy.data.objects.new("pav", cam_data)
scene.collection.objects.link(cam)
scene.camera = cam

for v in job["views"]:
    t0 = time.time()
    x, y, z = v["axes"]  # pav's view axes in its world: +X left, +Y up, +Z forward
    e = v["eye"]
    # Blender's camera: local +X right (= −pav X), +Y up, looks down local −Z (= +pav Z).
    m = Matrix(
        (
            (-x[0], y[0], -z[0], e[0]),
            (-x[1], y[1], -z[1], e[1]),
            (-x[2], y[2], -z[2], e[2]),
            (0, 0, 0, 1),
        )
    )
    cam.matrix_world = PAV_TO_BLENDER @ m
    if env_turn is not None:
        # The camera went round pav's +Y (Blender's +Z) by env_turn_deg; the lookup vector turns
        # back by as much, so the map appears turned with the camera.
        env_turn.inputs["Rotation"].default_value = (0.0, 0.0, -math.radians(v.get("env_turn_deg", 0.0)))
    cam_data.angle = math.radians(v["fov_deg"])
    scene.render.filepath = v["out"]
    bpy.ops.render.render(write_still=True)
    print("pav-view %s %.3f" % (v["name"], time.time() - t0), flush=True)
