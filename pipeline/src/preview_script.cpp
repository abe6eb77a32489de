#include "preview_script.h"

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "rime/core/atomic_file.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace rime::bake {
namespace {

// Runs inside `blender --background --python render_preview.py -- ARGS`. Blender 3.4+: imports the
// cleaned ice mesh (and the water mesh when present) in Rime's z-up metres, rebuilds the colliders,
// frames the scene bounds with a fixed camera and renders one PNG (written under a temporary name,
// then renamed, like every Rime output).
constexpr const char* kRenderScript = R"PY(
import json, math, os, sys
import bpy
from mathutils import Vector, Euler, Matrix

argv = sys.argv[sys.argv.index("--") + 1:]
opts = dict(zip(argv[0::2], argv[1::2]))
setup = json.load(open(opts["--setup"]))

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene

def material(name, rgba, roughness):
    m = bpy.data.materials.new(name)
    m.diffuse_color = rgba          # Workbench uses the viewport colour
    m.use_nodes = True
    bsdf = m.node_tree.nodes.get("Principled BSDF")
    if bsdf:
        bsdf.inputs["Base Color"].default_value = rgba
        bsdf.inputs["Roughness"].default_value = roughness
    return m

ICE = material("ice", (0.75, 0.9, 1.0, 1.0), 0.1)
WATER = material("water", (0.15, 0.4, 0.9, 1.0), 0.05)
SOLID = material("collider", (0.55, 0.5, 0.45, 1.0), 0.6)

def import_obj(path, up):
    before = set(bpy.data.objects)
    if hasattr(bpy.ops.wm, "obj_import"):
        if up == "z":
            bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
        else:
            bpy.ops.wm.obj_import(filepath=path)
    else:
        bpy.ops.import_scene.obj(filepath=path, axis_forward="Y" if up == "z" else "-Z", axis_up="Z" if up == "z" else "Y")
    return [o for o in bpy.data.objects if o not in before]

def assign(objects, mat):
    for o in objects:
        if o.type == "MESH":
            o.data.materials.clear()
            o.data.materials.append(mat)

def transform_of(t):
    scale = Matrix.Diagonal(Vector(t["scale"] + [1.0]))
    rotation = Euler([math.radians(a) for a in t["rotate_deg"]], "XYZ").to_matrix().to_4x4()
    return Matrix.Translation(Vector(t["translate"])) @ rotation @ scale

for s in setup["solids"]:
    shape = s["shape"]
    objects = []
    if shape == "mesh":
        objects = import_obj(s["mesh"], s["transform"]["up_axis"])
    elif shape == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(radius=s["radius"], segments=48, ring_count=24)
    elif shape == "torus":
        bpy.ops.mesh.primitive_torus_add(major_radius=s["radius"], minor_radius=s["minor_radius"])
    elif shape == "cylinder":
        bpy.ops.mesh.primitive_cylinder_add(radius=s["radius"], depth=s["height"])
    elif shape == "plane":
        bpy.ops.mesh.primitive_plane_add(size=1.0)
    else:
        bpy.ops.mesh.primitive_cube_add(size=1.0)
    if shape != "mesh":
        objects = [bpy.context.object]
    # Extents go into the matrix itself: an object's .scale reaches matrix_world only after a
    # depsgraph update, so a box set by .scale rendered as a 1 m cube.
    size = Matrix.Identity(4)
    if shape == "plane":
        size = Matrix.Diagonal(Vector((s["size"][0], s["size"][1], 1.0, 1.0)))
    elif shape == "box":
        size = Matrix.Diagonal(Vector(list(s["size"]) + [1.0]))
    for o in objects:
        o.matrix_world = transform_of(s["transform"]) @ o.matrix_world @ size
    assign(objects, SOLID)

if os.path.exists(opts["--ice"]):  # frames without ice have no cleaned mesh
    assign(import_obj(opts["--ice"], "z"), ICE)
if os.path.exists(opts.get("--water", "")):
    assign(import_obj(opts["--water"], "z"), WATER)

lo, hi = Vector(setup["bounds"]["min"]), Vector(setup["bounds"]["max"])
center, radius = (lo + hi) / 2, max((hi - lo).length / 2, 1e-3)
camera_data = bpy.data.cameras.new("camera")
camera = bpy.data.objects.new("camera", camera_data)
scene.collection.objects.link(camera)
direction = Vector(setup["view"]).normalized()
camera.location = center + direction * (1.15 * radius / math.sin(camera_data.angle / 2))
camera.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
camera_data.clip_end = 100 * radius
scene.camera = camera
sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
sun.rotation_euler = (math.radians(40), 0, math.radians(30))
scene.collection.objects.link(sun)

scene.render.resolution_x, scene.render.resolution_y = setup["width"], setup["height"]
scene.render.resolution_percentage = 100
scene.render.image_settings.file_format = "PNG"
if setup["engine"] == "cycles":
    scene.render.engine = "CYCLES"
    scene.cycles.samples = setup["samples"]
    world = bpy.data.worlds.new("world")
    world.color = (0.8, 0.85, 0.9)
    scene.world = world
else:
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "STUDIO"
    scene.display.shading.color_type = "MATERIAL"
    scene.display.shading.show_shadows = True

final = opts["--output"]
os.makedirs(os.path.dirname(final), exist_ok=True)
temporary = final + ".tmp.png"
scene.render.filepath = temporary
bpy.ops.render.render(write_still=True)
os.replace(temporary, final)
)PY";

std::array<double, 3> ToArray(const Vec3d& v) { return {v.x, v.y, v.z}; }

// Scene bounds for the fixed camera: the domain when set, otherwise the water and the finite solids.
json SceneBounds(const io::Scene& scene) {
  if (scene.domain.set) return {{"min", ToArray(scene.domain.min)}, {"max", ToArray(scene.domain.max)}};
  Vec3d lo{1e30, 1e30, 1e30}, hi{-1e30, -1e30, -1e30};
  const auto grow = [&](const Vec3d& c, const Vec3d& half) {
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a] - half[a]), hi[a] = std::max(hi[a], c[a] + half[a]);
  };
  for (const auto& b : scene.fluid_blocks) {
    if (b.shape == io::BlockShape::kBox) grow((b.min + b.max) * 0.5, (b.max - b.min) * 0.5);
    else grow(b.center, {b.radius, b.radius, b.radius});
  }
  for (const auto& e : scene.emitters) grow(e.center, {0.1, 0.1, 0.1});
  for (const auto& s : scene.solids) {
    const double k = std::max({s.transform.scale.x, s.transform.scale.y, s.transform.scale.z});
    double r = 0;
    if (s.shape == io::SolidShape::kSphere) r = s.radius;
    else if (s.shape == io::SolidShape::kTorus) r = s.radius + s.minor_radius;
    else if (s.shape == io::SolidShape::kCylinder) r = std::max(s.radius, s.height / 2);
    else if (s.shape == io::SolidShape::kBox) r = Norm(s.size) / 2;
    else continue;  // planes are unbounded ground; meshes are framed by the water around them
    grow(s.transform.translate, {k * r, k * r, k * r});
  }
  if (lo.x > hi.x) lo = {-1, -1, -1}, hi = {1, 1, 1};
  return {{"min", ToArray(lo)}, {"max", ToArray(hi)}};
}

void WriteIfChanged(const fs::path& path, const std::string& text) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream old;
  old << in.rdbuf();
  if (in && old.str() == text) return;  // keep the mtime: the cheap check stays cheap
  WriteFileAtomically(path, text);
}

}  // namespace

void WritePreviewFiles(const SceneDocument& doc, const BakeLayout& layout) {
  const io::Scene& scene = doc.scene();
  json solids = json::array();
  for (const auto& s : scene.solids) {
    solids.push_back({{"name", s.name},
                      {"shape", std::string(io::EnumName(s.shape))},
                      {"mesh", s.shape == io::SolidShape::kMesh ? fs::absolute(scene.Resolve(s.mesh)).string() : ""},
                      {"size", ToArray(s.size)},
                      {"radius", s.radius},
                      {"minor_radius", s.minor_radius},
                      {"height", s.height},
                      {"transform",
                       {{"translate", ToArray(s.transform.translate)},
                        {"rotate_deg", ToArray(s.transform.rotate_deg)},
                        {"scale", ToArray(s.transform.scale)},
                        {"up_axis", std::string(io::EnumName(s.transform.up_axis))}}}});
  }
  const BakeSettings& b = doc.bake();
  const json setup = {
      {"solids", solids},
      {"bounds", b.FramesABox() ? json{{"min", ToArray(b.preview_frame_min)}, {"max", ToArray(b.preview_frame_max)}} : SceneBounds(scene)},
      {"width", b.preview_width},
      {"height", b.preview_height},
      {"engine", std::string(io::EnumName(b.preview_engine))},
      {"samples", b.preview_samples},
      {"view", ToArray(b.preview_view)}};
  const fs::path folder = layout.cache() / "preview";
  fs::create_directories(folder);
  WriteIfChanged(folder / "render_preview.py", std::string(kRenderScript).substr(1));
  WriteIfChanged(folder / "preview_scene.json", setup.dump(1) + "\n");
}

}  // namespace rime::bake
