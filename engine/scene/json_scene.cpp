#include "specula/scene/json_scene.h"

#include "specula/core/error.h"
#include "specula/core/file_io.h"
#include "specula/scene/animation_sampling.h"
#include "specula/scene/components.h"
#include "specula/scene/gltf_loader.h"
#include "specula/scene/kinematics_rules.h"
#include "specula/scene/mesh_io.h"
#include "specula/scene/mesh_library.h"
#include "specula/scene/strict_json.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace specula {
namespace {

using namespace strict_json;
namespace fs = std::filesystem;

constexpr std::string_view kFormatName = "specula-scene";
constexpr int kFormatVersion = 1;
/// Tessellation limits of make_primitive (geometry/primitives.h), checked here too so the message
/// names the JSON field.
constexpr std::uint32_t kMaxTessellation = 4096;
constexpr std::uint32_t kMaxRayCacheResolution = 4096;

// ---------------------------------------------------------------------------------------------
// Degrees in the file, radians in components. The writer searches for the shortest decimal that
// this exact conversion maps back to the stored float, so both directions must use it.

constexpr double kPi = 3.14159265358979323846;
float radians_from_degrees(double degrees) { return static_cast<float>(degrees * (kPi / 180.0)); }
double degrees_from_radians(float radians) { return static_cast<double>(radians) * (180.0 / kPi); }

double parse_double(const std::string& text) {
  double v = 0.0;
  std::from_chars(text.data(), text.data() + text.size(), v);
  return v;
}

// ---------------------------------------------------------------------------------------------
// Reading: scene values on top of the strict JSON readers

vec3 read_color(const Reader& r, const json& j, const std::string& path) {
  const vec3 c = read_vec<3>(r, j, path);
  r.check(c.x >= 0.0f && c.y >= 0.0f && c.z >= 0.0f, path,
          "colour components must be >= 0 (linear RGB)");
  return c;
}

/// A float bound as messages print it: its shortest spelling ("1e+20").
std::string format_bound(float v) {
  char buf[32];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

/// A radiance (emission, background): a colour no component of which exceeds kMaxEmission.
vec3 read_radiance(const Reader& r, const json& j, const std::string& path) {
  const vec3 c = read_color(r, j, path);
  const float largest = std::max(c.x, std::max(c.y, c.z));
  r.check(largest <= kMaxEmission, path,
          "components must be <= " + format_bound(kMaxEmission) + ", got " +
              format_double(largest));
  return c;
}

/// A position [x, y, z] in double (Transform::translation, Camera, keys), each coordinate within
/// the representable range (core/math.h kMaxCoordinate), so that `info` refuses what `render`
/// could not trace.
dvec3 read_position(const Reader& r, const json& j, const std::string& path) {
  if (!j.is_array() || j.size() != 3)
    r.fail(path, "expected an array of 3 numbers [x, y, z], got " + describe(j));
  dvec3 p;
  for (int i = 0; i < 3; ++i) {
    const std::string at = element_path(path, static_cast<std::size_t>(i));
    p[i] = read_number(r, j[static_cast<std::size_t>(i)], at);
    r.check(in_range(p[i]), at,
            "coordinate " + format_double(p[i]) + " is outside " + kCoordinateRangeText);
  }
  return p;
}

/// A primitive's length (radius, height, edge): > 0 and at most kMaxCoordinate.
float check_length(const Reader& r, float v, const std::string& path) {
  if (in_range(double(v))) return v;
  char text[32];
  const auto shortest = std::to_chars(text, text + sizeof text, v);
  r.fail(path, "length " + std::string(text, shortest.ptr) + " is outside " + kCoordinateRangeText);
}

/// Unit quaternions pass through untouched and others are normalized, so a written rotation
/// reads back bit-identical (normalizing twice could move the last bit).
quat unit_or_normalized(const quat& q) {
  const double length =
      std::sqrt(double(q.x) * q.x + double(q.y) * q.y + double(q.z) * q.z + double(q.w) * q.w);
  if (std::abs(length - 1.0) <= 1e-6) return q;
  return quat(static_cast<float>(q.w / length), static_cast<float>(q.x / length),
              static_cast<float>(q.y / length), static_cast<float>(q.z / length));
}

/// [x, y, z, w] in the file (the glTF order); glm's constructor takes w first.
quat read_quat(const Reader& r, const json& j, const std::string& path) {
  const vec4 v = read_vec<4>(r, j, path);
  const double length2 =
      double(v.x) * v.x + double(v.y) * v.y + double(v.z) * v.z + double(v.w) * v.w;
  r.check(length2 > 1e-12, path,
          "rotation quaternion [x, y, z, w] has zero length (identity is [0, 0, 0, 1])");
  return unit_or_normalized(quat(v.w, v.x, v.y, v.z));
}

/// A non-zero scale: a number (uniform) or [x, y, z]. Negative components mirror; zero would
/// flatten the object into a non-invertible transform.
vec3 read_scale(const Reader& r, const json& j, const std::string& path) {
  const vec3 s = j.is_number() ? vec3(read_float(r, j, path)) : read_vec<3>(r, j, path);
  r.check(s.x != 0.0f && s.y != 0.0f && s.z != 0.0f, path,
          "scale components must be non-zero (negative mirrors; zero makes the transform "
          "non-invertible)");
  return s;
}

/// Box size: a number (cube) or [x, y, z], all > 0.
vec3 read_box_size(const Reader& r, const json& j, const std::string& path) {
  const vec3 s = j.is_number() ? vec3(read_float(r, j, path)) : read_vec<3>(r, j, path);
  r.check(s.x > 0.0f && s.y > 0.0f && s.z > 0.0f, path, "box edge lengths must be > 0");
  for (int i = 0; i < 3; ++i) check_length(r, s[i], path);
  return s;
}

/// Plane size: a number (square) or [x, z], both > 0. The y component keeps MeshSource's default.
vec3 read_plane_size(const Reader& r, const json& j, const std::string& path) {
  const vec2 s = j.is_number() ? vec2(read_float(r, j, path)) : read_vec<2>(r, j, path);
  r.check(s.x > 0.0f && s.y > 0.0f, path, "plane side lengths [x, z] must be > 0");
  check_length(r, s.x, path);
  check_length(r, s.y, path);
  return vec3(s.x, MeshSource{}.size.y, s.y);
}

// --- Settings --------------------------------------------------------------------------------

RenderSettings read_settings(const Reader& r, const json& j, const std::string& path) {
  RenderSettings s;
  const Object o(r, j, path, {"width", "height", "max_depth", "background", "animation"},
                 "render settings");
  if (const json* v = o.find("width")) s.width = read_u32(r, *v, o.path("width"), 1, kMaxImageSide);
  if (const json* v = o.find("height"))
    s.height = read_u32(r, *v, o.path("height"), 1, kMaxImageSide);
  if (const json* v = o.find("max_depth"))
    s.max_depth = read_u32(r, *v, o.path("max_depth"), 0, kMaxTraceDepth);
  if (const json* v = o.find("background"))
    s.background = read_radiance(r, *v, o.path("background"));
  if (const json* v = o.find("animation")) {
    const std::string at = o.path("animation");
    const Object a(r, *v, at, {"start", "end", "frames"}, "animation frames");
    s.anim_start = read_number(r, a.require("start"), a.path("start"));
    s.anim_end = read_number(r, a.require("end"), a.path("end"));
    s.anim_frames = read_u32(r, a.require("frames"), a.path("frames"), 1, kMaxAnimationFrames);
    r.check(s.anim_end >= s.anim_start, a.path("end"), "the end is before the start");
  }
  return s;
}

// --- Transform -------------------------------------------------------------------------------

Transform read_transform(const Reader& r, const json& j, const std::string& path) {
  Transform t;
  const Object o(r, j, path, {"translation", "rotation", "look_at", "scale"}, "transform");
  if (const json* v = o.find("translation"))
    t.translation = read_position(r, *v, o.path("translation"));
  if (o.has("rotation") && o.has("look_at"))
    r.fail(o.path("look_at"), "give either \"rotation\" or \"look_at\", not both");
  if (const json* v = o.find("rotation")) t.rotation = read_quat(r, *v, o.path("rotation"));
  if (const json* v = o.find("look_at")) {
    const dvec3 target = read_position(r, *v, o.path("look_at"));
    const dvec3 direction = target - t.translation; // in double: exact for nearby points far out
    r.check(glm::length(direction) > 0.0, o.path("look_at"),
            "look_at point equals the translation, so there is no direction to face");
    t.rotation = unit_or_normalized(rotation_looking_along(vec3(glm::normalize(direction))));
  }
  if (const json* v = o.find("scale")) t.scale = read_scale(r, *v, o.path("scale"));
  return t;
}

// --- Mesh ------------------------------------------------------------------------------------

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

MeshSource read_primitive(const Reader& r, const json& j, const std::string& path) {
  MeshSource s;
  s.kind = MeshSource::Kind::Primitive;
  s.primitive = read_string(r, j.at("primitive"), member_path(path, "primitive"));
  if (s.primitive == "sphere") {
    const Object o(r, j, path, {"primitive", "radius", "segments", "rings"}, "sphere");
    if (const json* v = o.find("radius"))
      s.radius = check_length(r, read_positive(r, *v, o.path("radius")), o.path("radius"));
    if (const json* v = o.find("segments"))
      s.segments = read_u32(r, *v, o.path("segments"), 3, kMaxTessellation);
    if (const json* v = o.find("rings"))
      s.rings = read_u32(r, *v, o.path("rings"), 2, kMaxTessellation);
  } else if (s.primitive == "box") {
    const Object o(r, j, path, {"primitive", "size"}, "box");
    if (const json* v = o.find("size")) s.size = read_box_size(r, *v, o.path("size"));
  } else if (s.primitive == "plane") {
    const Object o(r, j, path, {"primitive", "size", "subdivisions"}, "plane");
    if (const json* v = o.find("size")) s.size = read_plane_size(r, *v, o.path("size"));
    // MeshSource keeps plane subdivisions in `rings`; a flat plane needs only one by default.
    s.rings = 1;
    if (const json* v = o.find("subdivisions"))
      s.rings = read_u32(r, *v, o.path("subdivisions"), 1, kMaxTessellation);
  } else if (s.primitive == "cylinder" || s.primitive == "cone") {
    const bool cone = s.primitive == "cone";
    const Object o =
        cone ? Object(r, j, path, {"primitive", "radius", "height", "segments", "top_radius"},
                      s.primitive)
             : Object(r, j, path, {"primitive", "radius", "height", "segments"}, s.primitive);
    if (const json* v = o.find("radius"))
      s.radius = check_length(r, read_positive(r, *v, o.path("radius")), o.path("radius"));
    if (const json* v = o.find("height"))
      s.height = check_length(r, read_positive(r, *v, o.path("height")), o.path("height"));
    if (const json* v = o.find("segments"))
      s.segments = read_u32(r, *v, o.path("segments"), 3, kMaxTessellation);
    if (const json* v = o.find("top_radius")) {
      s.top_radius = float(read_number(r, *v, o.path("top_radius")));
      r.check(s.top_radius >= 0.0f && s.top_radius < s.radius, o.path("top_radius"),
              "a cone's top_radius must be in [0, radius), got " + format_double(s.top_radius));
    }
  } else {
    r.fail(member_path(path, "primitive"),
           "unknown primitive \"" + s.primitive +
               "\" (expected sphere, box, plane, cylinder or cone)");
  }
  return s;
}

MeshSource read_file_mesh(const Reader& r, const json& j, const std::string& path,
                          const fs::path& base_dir) {
  MeshSource s;
  s.kind = MeshSource::Kind::File;
  const Object o(r, j, path, {"file", "gltf_mesh"}, "file mesh");
  s.path = read_string(r, o.require("file"), o.path("file"));
  r.check(!s.path.empty(), o.path("file"), "mesh file path is empty");
  const std::string ext = lower(fs::path(s.path).extension().string());
  const bool gltf = ext == ".gltf" || ext == ".glb";
  if (!gltf && !is_mesh_file_extension(ext))
    r.fail(o.path("file"), "mesh file \"" + printable(s.path) +
                               "\" has an unsupported extension (expected "
                               ".obj, .ply, .off, .stl, .gltf or .glb)");
  if (const json* v = o.find("gltf_mesh")) {
    if (!gltf)
      r.fail(o.path("gltf_mesh"), "\"gltf_mesh\" selects a mesh inside a .gltf/.glb file, but \"" +
                                      printable(s.path) + "\" is not one");
    s.gltf_mesh = static_cast<int>(read_unsigned(r, *v, o.path("gltf_mesh"), 0,
                                                 std::uint64_t(std::numeric_limits<int>::max())));
  }
  const fs::path resolved = fs::path(s.path).is_absolute() ? fs::path(s.path) : base_dir / s.path;
  // Only whether it is there and what it is: the mesh library reads it (and checks its size).
  std::error_code ec;
  const fs::file_status status = fs::status(resolved, ec);
  const std::string looked =
      " (looked for " + printable(resolved.lexically_normal().string()) + ")";
  if (!fs::exists(status))
    r.fail(o.path("file"), "mesh file \"" + printable(s.path) + "\" not found" + looked);
  if (!fs::is_regular_file(status))
    r.fail(o.path("file"), "mesh file \"" + printable(s.path) + "\" is not a regular file" +
                               (fs::is_directory(status) ? " (a directory)" : "") + looked);
  return s;
}

std::shared_ptr<const TriangleMesh> read_inline_mesh(const Reader& r, const json& j,
                                                     const std::string& path) {
  TriangleMesh mesh;
  const Object o(r, j, path, {"positions", "normals", "uvs", "triangles"}, "inline mesh");
  const auto read_vectors = [&]<int N>(std::string_view key, std::vector<glm::vec<N, float>>& out) {
    const json* v = o.find(key);
    if (!v) return;
    const std::string at = o.path(key);
    read_array(r, *v, at, "one entry per vertex");
    if (v->size() > kMaxVertices)
      r.fail(at, "more than " + std::to_string(kMaxVertices) + " vertices (docs/limits.md)");
    out.reserve(v->size());
    for (std::size_t i = 0; i < v->size(); ++i)
      out.push_back(read_vec<N>(r, (*v)[i], element_path(at, i)));
  };
  (void)o.require("positions");
  read_vectors("positions", mesh.positions);
  read_vectors("normals", mesh.normals);
  read_vectors("uvs", mesh.uvs);

  const json& triangles = read_array(r, o.require("triangles"), o.path("triangles"),
                                     "one [i, j, k] vertex-index triple per triangle");
  if (triangles.size() > kMaxTriangles)
    r.fail(o.path("triangles"), "more than " + std::to_string(kMaxTriangles) + " triangles");
  mesh.triangles.reserve(triangles.size());
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    const std::string at = element_path(o.path("triangles"), t);
    const json& tri = triangles[t];
    if (!tri.is_array() || tri.size() != 3)
      r.fail(at, "expected an array of 3 vertex indices [i, j, k], got " + describe(tri));
    uvec3 indices;
    for (std::size_t k = 0; k < 3; ++k)
      indices[static_cast<int>(k)] =
          read_u32(r, tri[k], element_path(at, k), 0, std::numeric_limits<std::uint32_t>::max());
    mesh.triangles.push_back(indices);
  }
  try {
    mesh.validate(r.file());
  } catch (const Error& e) {
    r.fail(path, e.message());
  }
  return std::make_shared<const TriangleMesh>(std::move(mesh));
}

Mesh read_mesh(const Reader& r, ecs::Registry& registry, const json& j, const std::string& path,
               const fs::path& base_dir) {
  if (!j.is_object()) r.fail(path, "expected an object (mesh), got " + describe(j));
  const int kinds =
      int(j.contains("primitive")) + int(j.contains("file")) + int(j.contains("inline"));
  if (kinds != 1) r.fail(path, "a mesh needs exactly one of \"primitive\", \"file\" or \"inline\"");
  Mesh mesh;
  if (j.contains("inline")) {
    const Object o(r, j, path, {"inline"}, "inline mesh");
    mesh.source.kind = MeshSource::Kind::Inline;
    mesh.geometry = read_inline_mesh(r, o.require("inline"), o.path("inline"));
    return mesh;
  }
  mesh.source =
      j.contains("file") ? read_file_mesh(r, j, path, base_dir) : read_primitive(r, j, path);
  try {
    mesh.geometry = registry.resource_or_default<MeshLibrary>().get(mesh.source, base_dir);
  } catch (const Error& e) {
    r.fail(path, e.what());
  } catch (const std::exception& e) {
    // Loaders should throw specula::Error; anything else still becomes a message, not a crash.
    r.fail(path, std::string("cannot load mesh: ") + e.what());
  }
  if (!mesh.geometry) r.fail(path, "mesh could not be loaded");
  return mesh;
}

// --- Material, light, camera -----------------------------------------------------------------

Material read_material(const Reader& r, const json& j, const std::string& path) {
  Material m;
  const Object o(r, j, path,
                 {"base_color", "emission", "reflectivity", "transmission", "ior", "roughness"},
                 "material");
  if (const json* v = o.find("base_color")) m.base_color = read_color(r, *v, o.path("base_color"));
  if (const json* v = o.find("emission")) m.emission = read_radiance(r, *v, o.path("emission"));
  if (const json* v = o.find("reflectivity"))
    m.reflectivity = read_float_in(r, *v, o.path("reflectivity"), 0.0f, 1.0f);
  if (const json* v = o.find("transmission"))
    m.transmission = read_float_in(r, *v, o.path("transmission"), 0.0f, 1.0f);
  if (const json* v = o.find("ior")) {
    m.ior = read_float(r, *v, o.path("ior"));
    r.check(m.ior >= 1.0f, o.path("ior"),
            "index of refraction must be >= 1, got " + format_double(m.ior));
  }
  if (const json* v = o.find("roughness"))
    m.roughness = read_float_in(r, *v, o.path("roughness"), 0.0f, 1.0f);
  r.check(m.reflectivity + m.transmission <= 1.0f, o.path("transmission"),
          "reflectivity + transmission must be <= 1 (the rest is diffuse), got " +
              format_double(m.reflectivity) + " + " + format_double(m.transmission));
  return m;
}

Light read_light(const Reader& r, const json& j, const std::string& path) {
  Light l;
  const Object o(r, j, path,
                 {"type", "color", "intensity", "range", "inner_cone_deg", "outer_cone_deg"},
                 "light");
  const std::string type = read_string(r, o.require("type"), o.path("type"));
  if (type == "point") {
    l.type = Light::Type::Point;
  } else if (type == "directional") {
    l.type = Light::Type::Directional;
  } else if (type == "spot") {
    l.type = Light::Type::Spot;
  } else {
    r.fail(o.path("type"),
           "unknown light type \"" + type + "\" (expected point, directional or spot)");
  }
  if (const json* v = o.find("color")) l.color = read_color(r, *v, o.path("color"));
  if (const json* v = o.find("intensity"))
    l.intensity = read_non_negative(r, *v, o.path("intensity"));
  const double brightest =
      double(std::max(l.color.x, std::max(l.color.y, l.color.z))) * l.intensity;
  r.check(brightest <= kMaxLightIntensity, o.path(o.has("intensity") ? "intensity" : "color"),
          "color * intensity must be <= " + format_bound(kMaxLightIntensity) +
              " per component, got " + format_double(brightest));
  if (const json* v = o.find("range")) {
    r.check(l.type != Light::Type::Directional, o.path("range"),
            "a directional light has no position, so no range");
    l.range = read_non_negative(r, *v, o.path("range"));
  }
  for (const char* key : {"inner_cone_deg", "outer_cone_deg"})
    if (o.has(key) && l.type != Light::Type::Spot)
      r.fail(o.path(key), "cone angles apply only to spot lights");
  double inner = degrees_from_radians(l.inner_cone);
  double outer = degrees_from_radians(l.outer_cone);
  if (const json* v = o.find("inner_cone_deg")) {
    inner = read_number(r, *v, o.path("inner_cone_deg"));
    l.inner_cone = radians_from_degrees(inner);
  }
  if (const json* v = o.find("outer_cone_deg")) {
    outer = read_number(r, *v, o.path("outer_cone_deg"));
    l.outer_cone = radians_from_degrees(outer);
  }
  if (l.type == Light::Type::Spot) {
    r.check(outer > 0.0 && outer <= 90.0, o.path("outer_cone_deg"),
            "outer cone angle must be in (0, 90] degrees, got " + format_double(outer));
    r.check(inner >= 0.0 && inner < outer, o.path("inner_cone_deg"),
            "inner cone angle must be in [0, outer_cone_deg) degrees, got " + format_double(inner));
  }
  return l;
}

Camera read_camera(const Reader& r, const json& j, const std::string& path,
                   const RenderSettings& settings) {
  Camera c;
  const Object o(r, j, path, {"position", "look_at", "up", "vertical_fov_deg", "aspect"}, "camera");
  c.position = read_position(r, o.require("position"), o.path("position"));
  c.look_at = read_position(r, o.require("look_at"), o.path("look_at"));
  const dvec3 to_target = c.look_at - c.position;
  r.check(glm::length(to_target) > 0.0, o.path("look_at"),
          "camera position and look_at are the same point, so there is no view direction");
  const vec3 forward(glm::normalize(to_target));
  if (const json* v = o.find("up")) {
    c.up = read_vec<3>(r, *v, o.path("up"));
    r.check(glm::length(c.up) > 0.0f, o.path("up"), "up vector has zero length");
  }
  r.check(glm::length(glm::cross(forward, glm::normalize(c.up))) > 1e-4f, o.path("up"),
          "up vector is parallel to the view direction, so the camera roll is undefined");
  if (const json* v = o.find("vertical_fov_deg")) {
    const double degrees = read_number(r, *v, o.path("vertical_fov_deg"));
    r.check(degrees > 0.0 && degrees < 180.0, o.path("vertical_fov_deg"),
            "vertical field of view must be in (0, 180) degrees, got " + format_double(degrees));
    c.vertical_fov = radians_from_degrees(degrees);
  }
  // Without an explicit aspect, the image's own keeps pixels square.
  c.aspect = float(settings.width) / float(settings.height);
  if (const json* v = o.find("aspect")) c.aspect = read_positive(r, *v, o.path("aspect"));
  return c;
}

/// `default_up`: the camera's own up, for keys that give none.
CameraPath read_camera_path(const Reader& r, const json& j, const std::string& path,
                            const vec3& default_up) {
  CameraPath p;
  const Object o(r, j, path, {"loop", "time", "keys"}, "camera path");
  if (const json* v = o.find("loop")) p.loop = read_bool(r, *v, o.path("loop"));
  if (const json* v = o.find("time")) p.time = read_float(r, *v, o.path("time"));
  const json& keys = read_array(r, o.require("keys"), o.path("keys"), "camera path keys");
  for (std::size_t i = 0; i < keys.size(); ++i) {
    const std::string at = element_path(o.path("keys"), i);
    const Object k(r, keys[i], at, {"time", "position", "look_at", "up"}, "camera path key");
    CameraPath::Key key;
    key.time = read_float(r, k.require("time"), k.path("time"));
    key.position = read_position(r, k.require("position"), k.path("position"));
    key.look_at = read_position(r, k.require("look_at"), k.path("look_at"));
    key.up = default_up;
    if (const json* v = k.find("up")) {
      key.up = read_vec<3>(r, *v, k.path("up"));
      r.check(glm::length(key.up) > 0.0f, k.path("up"), "up vector has zero length");
    }
    p.keys.push_back(key);
  }
  validate_camera_path(p, r.file(), path);
  return p;
}

// --- Animation -------------------------------------------------------------------------------

template <typename V, typename ReadValue>
Keyframes<V> read_track(const Reader& r, const json& j, const std::string& path,
                        ReadValue read_value, bool splines = true) {
  Keyframes<V> track;
  // Vertex tracks take no spline (validate_animation), so no "tcb" either.
  const Object o =
      splines ? Object(r, j, path, {"interpolation", "times", "values", "tcb"}, "keyframe track")
              : Object(r, j, path, {"interpolation", "times", "values"}, "keyframe track");
  if (const json* v = o.find("interpolation")) {
    const std::string mode = read_string(r, *v, o.path("interpolation"));
    if (mode == "linear") {
      track.interpolation = Interpolation::Linear;
    } else if (mode == "step") {
      track.interpolation = Interpolation::Step;
    } else if (mode == "kochanek-bartels") {
      track.interpolation = Interpolation::KochanekBartels;
    } else {
      r.fail(o.path("interpolation"),
             "unknown interpolation \"" + mode + "\" (expected linear, step or kochanek-bartels)");
    }
  }
  if (const json* v = o.find("tcb")) {
    const json& tcb = read_array(r, *v, o.path("tcb"), "one [tension, continuity, bias] per key");
    for (std::size_t i = 0; i < tcb.size(); ++i)
      track.tcb.push_back(read_vec<3>(r, tcb[i], element_path(o.path("tcb"), i)));
  }
  const json& times = read_array(r, o.require("times"), o.path("times"), "key times in seconds");
  const json& values =
      read_array(r, o.require("values"), o.path("values"), "one value per key time");
  r.check(!times.empty(), o.path("times"), "a track needs at least one key");
  r.check(times.size() == values.size(), o.path("values"),
          std::to_string(times.size()) + " key times but " + std::to_string(values.size()) +
              " values");
  for (std::size_t i = 0; i < times.size(); ++i)
    track.times.push_back(read_float(r, times[i], element_path(o.path("times"), i)));
  for (std::size_t i = 0; i < values.size(); ++i)
    track.values.push_back(read_value(values[i], element_path(o.path("values"), i)));
  return track;
}

Animation read_animation(const Reader& r, const json& j, const std::string& path,
                         const Mesh* mesh) {
  Animation a;
  const Object o(r, j, path,
                 {"loop", "speed", "time", "translation", "rotation", "scale", "vertices",
                  "normals", "visibility"},
                 "animation");
  if (const json* v = o.find("loop")) a.loop = read_bool(r, *v, o.path("loop"));
  if (const json* v = o.find("speed")) a.speed = read_float(r, *v, o.path("speed"));
  if (const json* v = o.find("time")) a.time = read_float(r, *v, o.path("time"));
  if (const json* v = o.find("translation"))
    a.translation =
        read_track<dvec3>(r, *v, o.path("translation"), [&](const json& x, const std::string& at) {
          return read_position(r, x, at);
        });
  if (const json* v = o.find("rotation"))
    a.rotation =
        read_track<quat>(r, *v, o.path("rotation"),
                         [&](const json& x, const std::string& at) { return read_quat(r, x, at); });
  if (const json* v = o.find("scale"))
    a.scale = read_track<vec3>(r, *v, o.path("scale"), [&](const json& x, const std::string& at) {
      return read_scale(r, x, at);
    });
  const auto vertex_track = [&](const char* name, const char* what) {
    const json* v = o.find(name);
    if (v == nullptr) return Keyframes<std::vector<vec3>>{};
    if (!mesh) r.fail(o.path(name), "vertex animation needs a mesh on the same entity");
    return read_track<std::vector<vec3>>(
        r, *v, o.path(name),
        [&](const json& x, const std::string& at) {
          read_array(r, x, at, what);
          std::vector<vec3> key;
          key.reserve(x.size());
          for (std::size_t i = 0; i < x.size(); ++i)
            key.push_back(read_vec<3>(r, x[i], element_path(at, i)));
          return key;
        },
        false);
  };
  a.vertices = vertex_track("vertices", "one position per mesh vertex");
  a.normals = vertex_track("normals", "one normal per mesh vertex");
  if (const json* v = o.find("visibility")) {
    // Switches, not a curve: no interpolation, the values booleans.
    const Object k(r, *v, o.path("visibility"), {"times", "values"}, "visibility keys");
    const json& times =
        read_array(r, k.require("times"), k.path("times"), "key times in seconds");
    const json& values = read_array(r, k.require("values"), k.path("values"),
                                    "one true (shown) or false (hidden) per key time");
    r.check(!times.empty(), k.path("times"), "visibility needs at least one key");
    r.check(times.size() == values.size(), k.path("values"),
            std::to_string(times.size()) + " key times but " + std::to_string(values.size()) +
                " values");
    for (std::size_t i = 0; i < times.size(); ++i) {
      a.visibility.times.push_back(read_float(r, times[i], element_path(k.path("times"), i)));
      a.visibility.visible.push_back(
          read_bool(r, values[i], element_path(k.path("values"), i)) ? 1 : 0);
    }
  }
  validate_animation(a, mesh && mesh->geometry ? mesh->geometry->vertex_count() : 0, r.file(),
                     path);
  return a;
}

// --- Entities --------------------------------------------------------------------------------

std::optional<Kinematics::Type> parse_kinematics(const std::string& name) {
  if (name == "static") return Kinematics::Type::Static;
  if (name == "hierarchical") return Kinematics::Type::Hierarchical;
  if (name == "free") return Kinematics::Type::Free;
  return std::nullopt;
}

/// What linking parents needs to know about one entity.
struct EntityInfo {
  ecs::Entity entity;
  std::string name;
  std::optional<std::string> parent_name;
  std::optional<std::size_t> parent;
};

void read_entity(const Reader& r, Scene& scene, const json& j, const std::string& path,
                 const fs::path& base_dir, EntityInfo& info) {
  ecs::Registry& reg = scene.registry;
  const Object o(r, j, path,
                 {"name", "transform", "parent", "kinematics", "mesh", "material", "ray_cache",
                  "light", "camera", "camera_path", "animation"},
                 "entity");
  const ecs::Entity e = info.entity;
  reg.emplace<Name>(e, Name{info.name});
  reg.emplace<Transform>(e, o.has("transform")
                                ? read_transform(r, o.require("transform"), o.path("transform"))
                                : Transform{});
  if (const json* v = o.find("parent")) {
    info.parent_name = read_string(r, *v, o.path("parent"));
  }
  // Only a stated kinematics is emplaced; load_scene checks it against the animations and infers
  // the others (settle_kinematics).
  if (const json* v = o.find("kinematics")) {
    const std::string name = read_string(r, *v, o.path("kinematics"));
    const std::optional<Kinematics::Type> type = parse_kinematics(name);
    if (!type)
      r.fail(o.path("kinematics"), "unknown kinematics \"" + printable(name) +
                                       "\" (expected static, hierarchical or free)");
    reg.emplace<Kinematics>(e, Kinematics{*type});
  }

  const Mesh* mesh = nullptr;
  if (const json* v = o.find("mesh")) {
    mesh = &reg.emplace<Mesh>(e, read_mesh(r, reg, *v, o.path("mesh"), base_dir));
  }
  if (const json* v = o.find("material")) {
    r.check(mesh != nullptr, o.path("material"), "a material needs a mesh on the same entity");
    reg.emplace<Material>(e, read_material(r, *v, o.path("material")));
  } else if (mesh) {
    reg.emplace<Material>(e);
  }
  if (const json* v = o.find("ray_cache")) {
    const std::string at = o.path("ray_cache");
    const Material* material = reg.try_get<Material>(e);
    r.check(material != nullptr, at,
            "a ray-cache cube needs a mesh with a reflective or refractive material");
    r.check(material->is_reflective() || material->is_refractive(), at,
            "a ray-cache cube stores rays leaving a reflective or refractive surface, but this "
            "material has reflectivity 0 and transmission 0: give it one, or remove ray_cache");
    const Object c(r, *v, at, {"resolution"}, "ray cache");
    RayCacheCube cube;
    if (const json* res = c.find("resolution")) {
      cube.resolution = read_u32(r, *res, c.path("resolution"), 1, kMaxRayCacheResolution);
      r.check((cube.resolution & (cube.resolution - 1)) == 0, c.path("resolution"),
              "cube face resolution must be a power of two, got " +
                  std::to_string(cube.resolution));
    }
    reg.emplace<RayCacheCube>(e, cube);
  }
  if (const json* v = o.find("light")) reg.emplace<Light>(e, read_light(r, *v, o.path("light")));
  if (const json* v = o.find("camera"))
    reg.emplace<Camera>(e, read_camera(r, *v, o.path("camera"), scene.settings));
  if (const json* v = o.find("camera_path")) {
    r.check(o.has("camera"), o.path("camera_path"),
            "a camera path moves a camera: add \"camera\" to this entity");
    reg.emplace<CameraPath>(
        e, read_camera_path(r, *v, o.path("camera_path"), reg.get<Camera>(e).up));
  }
  if (const json* v = o.find("animation"))
    reg.emplace<Animation>(e, read_animation(r, *v, o.path("animation"), mesh));
}

/// Resolves parent names: each must belong to exactly one entity of the file. Cycles are left to
/// update_world_transforms, which load_scene runs for every format.
void link_entities(const Reader& r, Scene& scene, std::vector<EntityInfo>& infos) {
  std::map<std::string, std::vector<std::size_t>> by_name;
  for (std::size_t i = 0; i < infos.size(); ++i) by_name[infos[i].name].push_back(i);

  for (std::size_t i = 0; i < infos.size(); ++i) {
    if (!infos[i].parent_name) continue;
    const std::string at = member_path(element_path("entities", i), "parent");
    const auto it = by_name.find(*infos[i].parent_name);
    if (it == by_name.end()) r.fail(at, "no entity is named \"" + *infos[i].parent_name + "\"");
    if (it->second.size() > 1)
      r.fail(at, "parent name \"" + *infos[i].parent_name + "\" is ambiguous: " +
                     std::to_string(it->second.size()) + " entities have it (entities[" +
                     std::to_string(it->second[0]) + "] and entities[" +
                     std::to_string(it->second[1]) + "]); parents must have unique names");
    infos[i].parent = it->second[0];
  }

  ecs::Registry& reg = scene.registry;
  for (const EntityInfo& info : infos)
    if (info.parent) reg.emplace<Parent>(info.entity, Parent{infos[*info.parent].entity});
}

Scene read_document(const Reader& r, const json& root, const fs::path& base_dir) {
  const Object top(r, root, "", {"format", "version", "settings", "entities"}, "a Specula scene");
  const json& format = top.require("format");
  if (!format.is_string() || format.get<std::string>() != kFormatName)
    r.fail("format", "expected \"" + std::string(kFormatName) + "\", got " + describe(format));
  const json& version = top.require("version");
  if (!version.is_number_integer() || version.get<std::int64_t>() != kFormatVersion)
    r.fail("version", "unsupported version " + printable(version.dump()) +
                          " (this build reads version " + std::to_string(kFormatVersion) + ")");

  Scene scene;
  if (const json* v = top.find("settings")) scene.settings = read_settings(r, *v, "settings");

  const json& entities = read_array(r, top.require("entities"), "entities", "the scene's entities");
  if (entities.size() > kMaxEntities)
    r.fail("entities", "more than " + std::to_string(kMaxEntities) + " entities");

  // Names first: parents may be declared after their children.
  std::vector<EntityInfo> infos(entities.size());
  for (std::size_t i = 0; i < entities.size(); ++i) {
    const std::string at = element_path("entities", i);
    const json& e = entities[i];
    if (!e.is_object()) r.fail(at, "expected an object (entity), got " + describe(e));
    const auto name = e.find("name");
    if (name == e.end()) r.fail(at, "missing required key \"name\"");
    infos[i].name = read_string(r, *name, member_path(at, "name"));
    r.check(!infos[i].name.empty(), member_path(at, "name"), "entity name is empty");
    infos[i].entity = scene.registry.create();
  }
  for (std::size_t i = 0; i < entities.size(); ++i)
    read_entity(r, scene, entities[i], element_path("entities", i), base_dir, infos[i]);
  link_entities(r, scene, infos);
  return scene;
}

// ---------------------------------------------------------------------------------------------
// Writing

/// Output tree that keeps member order and carries each number's text, chosen as the shortest
/// decimal the reader maps back to the identical float.
struct OutMember;
struct Out {
  enum class Kind { Scalar, Array, Object };
  Kind kind = Kind::Object;
  std::string text;
  // A struct completed after Out, not std::pair<std::string, Out>, and the functions that
  // construct an Out defined after both: Clang (with libstdc++) instantiates the vector's
  // members, and the pair's default-constructibility check, while Out is still incomplete.
  std::vector<OutMember> members;
  std::vector<Out> items;

  static Out object();
  static Out array();
  static Out scalar(std::string text);
  Out& add(std::string key, Out value);
  Out& push(Out value);
  [[nodiscard]] bool empty() const {
    return kind != Kind::Scalar && members.empty() && items.empty();
  }
};

struct OutMember {
  std::string key;
  Out value;
};

Out Out::object() { return Out{}; }
Out Out::array() { return Out{Kind::Array, {}, {}, {}}; }
Out Out::scalar(std::string text) { return Out{Kind::Scalar, std::move(text), {}, {}}; }
Out& Out::add(std::string key, Out value) {
  members.push_back(OutMember{std::move(key), std::move(value)});
  return members.back().value;
}
Out& Out::push(Out value) {
  items.push_back(std::move(value));
  return items.back();
}

std::string quoted(const std::string& s) {
  return json(s).dump(-1, ' ', false, json::error_handler_t::replace);
}

constexpr std::size_t kLineWidth = 100;

/// Nesting depth: 0 for a scalar, 1 for a container of scalars, and so on.
std::size_t depth(const Out& v) {
  std::size_t d = 0;
  for (const auto& [key, child] : v.members) d = std::max(d, depth(child));
  for (const Out& child : v.items) d = std::max(d, depth(child));
  return v.kind == Out::Kind::Scalar ? 0 : d + 1;
}

std::string one_line(const Out& v) {
  if (v.kind == Out::Kind::Scalar) return v.text;
  const bool is_object = v.kind == Out::Kind::Object;
  std::string line(1, is_object ? '{' : '[');
  for (std::size_t i = 0; i < v.members.size(); ++i)
    line += (i ? ", " : "") + quoted(v.members[i].key) + ": " + one_line(v.members[i].value);
  for (std::size_t i = 0; i < v.items.size(); ++i) line += (i ? ", " : "") + one_line(v.items[i]);
  return line + (is_object ? '}' : ']');
}

/// Pretty-prints with two-space indents. Small values (vectors, colours, parameter sets, short
/// lists of vectors: nesting depth <= 2) stay on one line when they fit; `column` is where v
/// starts on its line.
void print(const Out& v, std::size_t indent, std::size_t column, std::string& out) {
  if (v.kind == Out::Kind::Scalar || v.empty() || depth(v) <= 2) {
    const std::string line = one_line(v);
    if (v.kind == Out::Kind::Scalar || v.empty() || column + line.size() <= kLineWidth) {
      out += line;
      return;
    }
  }
  const bool is_object = v.kind == Out::Kind::Object;
  const std::size_t n = is_object ? v.members.size() : v.items.size();
  out += is_object ? '{' : '[';
  for (std::size_t i = 0; i < n; ++i) {
    out += i ? ",\n" : "\n";
    out.append(indent + 2, ' ');
    const std::string key = is_object ? quoted(v.members[i].key) + ": " : std::string();
    out += key;
    print(is_object ? v.members[i].value : v.items[i], indent + 2, indent + 2 + key.size(), out);
  }
  out += '\n';
  out.append(indent, ' ');
  out += is_object ? '}' : ']';
}

class Writer {
public:
  explicit Writer(std::string context) : context_(std::move(context)) {}
  void set_context(std::string context) { context_ = std::move(context); }

  /// Shortest text that reads back (as double, then float, like the reader) to exactly f.
  [[nodiscard]] Out number(float f) const {
    check_finite(f);
    if (f == 0.0f) return Out::scalar("0"); // one spelling for ±0, which compare equal
    char buf[64];
    const auto shortest = std::to_chars(buf, buf + sizeof buf, f);
    std::string text(buf, shortest.ptr);
    // Decimal → double → float rounds twice; in the rare case that differs from decimal → float,
    // the exact double value of f always reads back.
    if (static_cast<float>(parse_double(text)) != f) text = format_double(static_cast<double>(f));
    return Out::scalar(text);
  }
  /// Angle stored in radians, written in degrees: the shortest decimal that radians_from_degrees
  /// maps back to exactly `radians`.
  [[nodiscard]] Out degrees(float radians) const {
    check_finite(radians);
    const double exact = degrees_from_radians(radians);
    char buf[64];
    for (int precision = 1; precision <= 17; ++precision) {
      const auto result =
          std::to_chars(buf, buf + sizeof buf, exact, std::chars_format::general, precision);
      const double candidate = parse_double(std::string(buf, result.ptr));
      // Respelled shortest, so 100 reads "100" rather than "1e+02".
      if (radians_from_degrees(candidate) == radians)
        return Out::scalar(candidate == 0.0 ? "0" : format_double(candidate));
    }
    return Out::scalar(format_double(exact));
  }
  [[nodiscard]] static Out integer(std::uint64_t v) { return Out::scalar(std::to_string(v)); }
  [[nodiscard]] static Out string(const std::string& s) { return Out::scalar(quoted(s)); }
  [[nodiscard]] static Out boolean(bool b) { return Out::scalar(b ? "true" : "false"); }
  template <int N>
  [[nodiscard]] Out vec(const glm::vec<N, float>& v) const {
    Out a = Out::array();
    for (int i = 0; i < N; ++i) a.push(number(v[i]));
    return a;
  }
  [[nodiscard]] Out rotation(const quat& q) const { return vec<4>(vec4(q.x, q.y, q.z, q.w)); }
  /// A double position: each coordinate's shortest text that reads back to exactly it.
  [[nodiscard]] Out position(const dvec3& p) const {
    Out a = Out::array();
    for (int i = 0; i < 3; ++i) {
      if (!std::isfinite(p[i]))
        throw Error(context_, "cannot write a non-finite number (NaN or Inf)");
      a.push(Out::scalar(p[i] == 0.0 ? "0" : format_double(p[i])));
    }
    return a;
  }

private:
  void check_finite(float f) const {
    if (!std::isfinite(f)) throw Error(context_, "cannot write a non-finite number (NaN or Inf)");
  }
  std::string context_;
};

Out write_settings(const Writer& w, const RenderSettings& s) {
  Out o = Out::object();
  o.add("width", Writer::integer(s.width));
  o.add("height", Writer::integer(s.height));
  o.add("max_depth", Writer::integer(s.max_depth));
  o.add("background", w.vec<3>(s.background));
  if (s.anim_frames > 0) {
    Out& a = o.add("animation", Out::object());
    a.add("start", w.number(s.anim_start));
    a.add("end", w.number(s.anim_end));
    a.add("frames", Writer::integer(s.anim_frames));
  }
  return o;
}

Out write_transform(const Writer& w, const Transform& t) {
  const Transform identity;
  Out o = Out::object();
  if (t.translation != identity.translation) o.add("translation", w.position(t.translation));
  if (t.rotation != identity.rotation) o.add("rotation", w.rotation(t.rotation));
  if (t.scale != identity.scale)
    o.add("scale", t.scale.x == t.scale.y && t.scale.y == t.scale.z ? w.number(t.scale.x)
                                                                    : w.vec<3>(t.scale));
  return o;
}

Out write_mesh(const Writer& w, const Mesh& mesh, const std::string& context) {
  const MeshSource& s = mesh.source;
  Out o = Out::object();
  switch (s.kind) {
  case MeshSource::Kind::Primitive:
    o.add("primitive", Writer::string(s.primitive));
    if (s.primitive == "sphere") {
      o.add("radius", w.number(s.radius));
      o.add("segments", Writer::integer(s.segments));
      o.add("rings", Writer::integer(s.rings));
    } else if (s.primitive == "box") {
      o.add("size",
            s.size.x == s.size.y && s.size.y == s.size.z ? w.number(s.size.x) : w.vec<3>(s.size));
    } else if (s.primitive == "plane") {
      o.add("size", s.size.x == s.size.z ? w.number(s.size.x) : w.vec<2>(vec2(s.size.x, s.size.z)));
      o.add("subdivisions", Writer::integer(s.rings));
    } else {
      o.add("radius", w.number(s.radius));
      o.add("height", w.number(s.height));
      o.add("segments", Writer::integer(s.segments));
      if (s.top_radius != 0.0f) o.add("top_radius", w.number(s.top_radius));
    }
    break;
  case MeshSource::Kind::File:
    o.add("file", Writer::string(s.path));
    if (s.gltf_mesh >= 0) o.add("gltf_mesh", Writer::integer(std::uint64_t(s.gltf_mesh)));
    break;
  case MeshSource::Kind::Inline: {
    if (!mesh.geometry) throw Error(context, "inline mesh has no geometry to write");
    const TriangleMesh& g = *mesh.geometry;
    Out& in = o.add("inline", Out::object());
    const auto add_vectors = [&](const char* key, const auto& values) {
      if (values.empty()) return;
      Out& a = in.add(key, Out::array());
      for (const auto& v : values) a.push(w.vec<std::remove_cvref_t<decltype(v)>::length()>(v));
    };
    add_vectors("positions", g.positions);
    add_vectors("normals", g.normals);
    add_vectors("uvs", g.uvs);
    Out& tris = in.add("triangles", Out::array());
    for (const uvec3& t : g.triangles) {
      Out& tri = tris.push(Out::array());
      for (int k = 0; k < 3; ++k) tri.push(Writer::integer(t[k]));
    }
    break;
  }
  }
  return o;
}

Out write_material(const Writer& w, const Material& m) {
  const Material d;
  Out o = Out::object();
  if (m.base_color != d.base_color) o.add("base_color", w.vec<3>(m.base_color));
  if (m.emission != d.emission) o.add("emission", w.vec<3>(m.emission));
  if (m.reflectivity != d.reflectivity) o.add("reflectivity", w.number(m.reflectivity));
  if (m.transmission != d.transmission) o.add("transmission", w.number(m.transmission));
  if (m.ior != d.ior) o.add("ior", w.number(m.ior));
  if (m.roughness != d.roughness) o.add("roughness", w.number(m.roughness));
  return o;
}

Out write_light(const Writer& w, const Light& l) {
  Out o = Out::object();
  o.add("type", Writer::string(l.type == Light::Type::Point         ? "point"
                               : l.type == Light::Type::Directional ? "directional"
                                                                    : "spot"));
  o.add("color", w.vec<3>(l.color));
  o.add("intensity", w.number(l.intensity));
  if (l.type != Light::Type::Directional) o.add("range", w.number(l.range));
  if (l.type == Light::Type::Spot) {
    o.add("inner_cone_deg", w.degrees(l.inner_cone));
    o.add("outer_cone_deg", w.degrees(l.outer_cone));
  }
  return o;
}

Out write_camera(const Writer& w, const Camera& c) {
  Out o = Out::object();
  o.add("position", w.position(c.position));
  o.add("look_at", w.position(c.look_at));
  o.add("up", w.vec<3>(c.up));
  o.add("vertical_fov_deg", w.degrees(c.vertical_fov));
  o.add("aspect", w.number(c.aspect));
  return o;
}

Out write_camera_path(const Writer& w, const CameraPath& p) {
  Out o = Out::object();
  o.add("loop", Writer::boolean(p.loop));
  if (p.time != 0.0f) o.add("time", w.number(p.time));
  Out& keys = o.add("keys", Out::array());
  for (const CameraPath::Key& k : p.keys) {
    Out& key = keys.push(Out::object());
    key.add("time", w.number(k.time));
    key.add("position", w.position(k.position));
    key.add("look_at", w.position(k.look_at));
    key.add("up", w.vec<3>(k.up));
  }
  return o;
}

template <typename V, typename WriteValue>
Out write_track(const Writer& w, const Keyframes<V>& track, WriteValue write_value) {
  Out o = Out::object();
  const char* mode = track.interpolation == Interpolation::Step     ? "step"
                     : track.interpolation == Interpolation::Linear ? "linear"
                                                                    : "kochanek-bartels";
  o.add("interpolation", Writer::string(mode));
  Out& times = o.add("times", Out::array());
  for (const float t : track.times) times.push(w.number(t));
  Out& values = o.add("values", Out::array());
  for (const V& v : track.values) values.push(write_value(v));
  if (!track.tcb.empty()) {
    Out& tcb = o.add("tcb", Out::array());
    for (const vec3& k : track.tcb) tcb.push(w.vec<3>(k));
  }
  return o;
}

Out write_animation(const Writer& w, const Animation& a) {
  Out o = Out::object();
  o.add("loop", Writer::boolean(a.loop));
  o.add("speed", w.number(a.speed));
  if (a.time != 0.0f) o.add("time", w.number(a.time));
  const auto vec3_value = [&](const vec3& v) { return w.vec<3>(v); };
  if (!a.translation.empty())
    o.add("translation",
          write_track(w, a.translation, [&](const dvec3& p) { return w.position(p); }));
  if (!a.rotation.empty())
    o.add("rotation", write_track(w, a.rotation, [&](const quat& q) { return w.rotation(q); }));
  if (!a.scale.empty()) o.add("scale", write_track(w, a.scale, vec3_value));
  const auto vertex_key = [&](const std::vector<vec3>& key) {
    Out values = Out::array();
    for (const vec3& p : key) values.push(w.vec<3>(p));
    return values;
  };
  if (!a.vertices.empty()) o.add("vertices", write_track(w, a.vertices, vertex_key));
  if (!a.normals.empty()) o.add("normals", write_track(w, a.normals, vertex_key));
  if (!a.visibility.empty()) {
    Out& keys = o.add("visibility", Out::object());
    Out& times = keys.add("times", Out::array());
    for (const float t : a.visibility.times) times.push(w.number(t));
    Out& values = keys.add("values", Out::array());
    for (const std::uint8_t v : a.visibility.visible) values.push(Writer::boolean(v != 0));
  }
  return o;
}

/// Names for the written file: parents are referenced by name, so an entity that is someone's
/// parent gets a unique name, and so does every entity without one (the format requires names).
/// Everything else keeps its name, duplicates included, so a loaded scene writes back unchanged.
std::vector<std::string> written_names(const ecs::Registry& reg,
                                       const std::vector<ecs::Entity>& entities,
                                       const std::map<std::uint32_t, std::size_t>& position) {
  std::vector<std::string> names(entities.size());
  std::map<std::string, std::size_t> uses;
  std::vector<bool> is_parent(entities.size(), false);
  for (std::size_t i = 0; i < entities.size(); ++i) {
    if (const Name* n = reg.try_get<Name>(entities[i])) names[i] = n->value;
    ++uses[names[i]];
    if (const Parent* p = reg.try_get<Parent>(entities[i])) {
      const auto it = position.find(p->entity.index);
      if (it != position.end() && reg.valid(p->entity)) is_parent[it->second] = true;
    }
  }
  std::set<std::string> taken;
  for (const auto& [name, count] : uses) taken.insert(name);
  for (std::size_t i = 0; i < entities.size(); ++i) {
    if (!names[i].empty() && !(is_parent[i] && uses[names[i]] > 1)) continue;
    std::string candidate = "entity_" + std::to_string(i);
    for (int suffix = 2; taken.count(candidate); ++suffix)
      candidate = "entity_" + std::to_string(i) + "_" + std::to_string(suffix);
    taken.insert(candidate);
    names[i] = candidate;
  }
  return names;
}

} // namespace

Scene parse_json_scene(const std::string& text, const std::string& name, const fs::path& base_dir) {
  const Reader reader(name);
  const json root = strict_json::parse(reader, text);
  return read_document(reader, root, base_dir);
}

Scene load_json_scene(const fs::path& path) {
  const std::string text = read_file_bounded(path, kMaxSceneTextBytes, "scene file");
  Scene scene = parse_json_scene(text, path.string(), path.parent_path());
  scene.source = path;
  return scene;
}

std::string write_json_scene(Scene& scene) {
  ecs::Registry& reg = scene.registry;
  const std::string context = scene.source.empty() ? "scene" : scene.source.string();
  Writer w(context);

  std::vector<ecs::Entity> entities;
  std::map<std::uint32_t, std::size_t> position; // entity slot → index in the written list
  reg.each_entity([&](ecs::Entity e) {
    if (reg.has<DefaultTag>(e)) return;
    position[e.index] = entities.size();
    entities.push_back(e);
  });
  const std::vector<std::string> names = written_names(reg, entities, position);

  Out root = Out::object();
  root.add("format", Writer::string(std::string(kFormatName)));
  root.add("version", Writer::integer(kFormatVersion));
  root.add("settings", write_settings(w, scene.settings));
  Out& list = root.add("entities", Out::array());
  for (std::size_t i = 0; i < entities.size(); ++i) {
    const ecs::Entity e = entities[i];
    w.set_context(context + ": entity \"" + names[i] + "\"");
    Out& o = list.push(Out::object());
    o.add("name", Writer::string(names[i]));
    if (const Transform* t = reg.try_get<Transform>(e)) {
      Out transform = write_transform(w, *t);
      if (!transform.empty()) o.add("transform", std::move(transform));
    }
    if (const Parent* p = reg.try_get<Parent>(e)) {
      const auto it = position.find(p->entity.index);
      if (!reg.valid(p->entity) || it == position.end())
        throw Error(context,
                    "entity \"" + names[i] +
                        "\" has a parent that is destroyed or not part of the saved scene");
      o.add("parent", Writer::string(names[it->second]));
    }
    if (const Kinematics* k = reg.try_get<Kinematics>(e))
      o.add("kinematics", Writer::string(kinematics_name(k->type)));
    const Mesh* mesh = reg.try_get<Mesh>(e);
    if (mesh) o.add("mesh", write_mesh(w, *mesh, context + ": entity \"" + names[i] + "\""));
    if (const Material* m = reg.try_get<Material>(e); m && mesh) {
      Out material = write_material(w, *m);
      if (!material.empty()) o.add("material", std::move(material));
    }
    if (const RayCacheCube* c = reg.try_get<RayCacheCube>(e)) {
      Out& cube = o.add("ray_cache", Out::object());
      cube.add("resolution", Writer::integer(c->resolution));
    }
    if (const Light* l = reg.try_get<Light>(e)) o.add("light", write_light(w, *l));
    if (const Camera* c = reg.try_get<Camera>(e)) o.add("camera", write_camera(w, *c));
    if (const CameraPath* p = reg.try_get<CameraPath>(e))
      o.add("camera_path", write_camera_path(w, *p));
    if (const Animation* a = reg.try_get<Animation>(e)) o.add("animation", write_animation(w, *a));
  }

  std::string text;
  print(root, 0, 0, text);
  text += '\n';
  return text;
}

void save_json_scene(Scene& scene, const fs::path& path) {
  const std::string text = write_json_scene(scene);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw Error(path.string(), "cannot open file for writing");
  out << text;
  out.flush();
  if (!out) throw Error(path.string(), "cannot write file");
}

} // namespace specula
