#include "editor/core/fields.h"

#include "specula/core/error.h"

#include <charconv>
#include <cmath>
#include <variant>

namespace specula::editor {

namespace {

/// One scalar leaf of a component: where it lives and how it is checked.
struct Leaf {
  std::variant<float*, double*, std::uint32_t*, Kinematics::Type*, Light::Type*> ptr;
  double lo = -HUGE_VAL, hi = HUGE_VAL;
  bool power_of_two = false;
};

const std::vector<std::string>& vec_names(bool quaternion) {
  static const std::vector<std::string> v{"x", "y", "z"};
  static const std::vector<std::string> q{"w", "x", "y", "z"};
  return quaternion ? q : v;
}

int component_index(std::string_view c, bool quaternion) {
  if (quaternion) {
    // glm::quat stores x, y, z, w but indexes them as [0..3] = x, y, z, w.
    if (c == "x") return 0;
    if (c == "y") return 1;
    if (c == "z") return 2;
    if (c == "w") return 3;
    return -1;
  }
  if (c == "x" || c == "r") return 0;
  if (c == "y" || c == "g") return 1;
  if (c == "z" || c == "b") return 2;
  return -1;
}

Error bad_path(std::string_view path, const std::string& why) {
  return Error("set " + std::string(path), why);
}

/// The leaf a path names in `s`, or empty when the entity lacks its component. `rest` is the
/// path after the component name ("translation.x").
std::optional<Leaf> resolve(EntitySnapshot& s, std::string_view path) {
  const std::size_t dot = path.find('.');
  if (dot == std::string_view::npos) throw bad_path(path, "expected Component.field");
  const std::string_view component = path.substr(0, dot);
  const std::string_view rest = path.substr(dot + 1);
  const std::size_t dot2 = rest.find('.');
  const std::string_view field = rest.substr(0, dot2);
  const std::string_view sub = dot2 == std::string_view::npos ? "" : rest.substr(dot2 + 1);
  const auto vec3_leaf = [&](vec3& v, double lo, double hi) -> Leaf {
    const int i = component_index(sub, false);
    if (i < 0) throw bad_path(path, "expected ." + std::string(field) + ".x, .y or .z");
    return Leaf{&v[i], lo, hi};
  };
  const auto dvec3_leaf = [&](dvec3& v) -> Leaf {
    const int i = component_index(sub, false);
    if (i < 0) throw bad_path(path, "expected ." + std::string(field) + ".x, .y or .z");
    return Leaf{&v[i], -kMaxCoordinate, kMaxCoordinate};
  };
  const auto scalar = [&](auto* p, double lo, double hi) -> Leaf {
    if (!sub.empty()) throw bad_path(path, "'" + std::string(field) + "' has no components");
    return Leaf{p, lo, hi};
  };
  const auto unknown = [&]() -> Error {
    return bad_path(path,
                    "unknown field '" + std::string(field) + "' of " + std::string(component));
  };
  if (component == "Transform") {
    if (!s.transform) return std::nullopt;
    Transform& t = *s.transform;
    if (field == "translation") return dvec3_leaf(t.translation);
    if (field == "scale") return vec3_leaf(t.scale, -1e6, 1e6);
    if (field == "rotation") {
      const int i = component_index(sub, true);
      if (i < 0) throw bad_path(path, "expected .rotation.w, .x, .y or .z");
      return Leaf{&t.rotation[i], -1.0, 1.0};
    }
    throw unknown();
  }
  if (component == "Material") {
    if (!s.material) return std::nullopt;
    Material& m = *s.material;
    if (field == "base_color") return vec3_leaf(m.base_color, 0.0, 1e6);
    if (field == "emission") return vec3_leaf(m.emission, 0.0, kMaxEmission);
    if (field == "reflectivity") return scalar(&m.reflectivity, 0.0, 1.0);
    if (field == "transmission") return scalar(&m.transmission, 0.0, 1.0);
    if (field == "ior") return scalar(&m.ior, 1.0, 1e6);
    if (field == "roughness") return scalar(&m.roughness, 0.0, 1.0);
    throw unknown();
  }
  if (component == "Kinematics") {
    if (!s.kinematics) return std::nullopt;
    if (field == "type") return scalar(&s.kinematics->type, 0, 0);
    throw unknown();
  }
  if (component == "Light") {
    if (!s.light) return std::nullopt;
    Light& l = *s.light;
    if (field == "type") return scalar(&l.type, 0, 0);
    if (field == "color") return vec3_leaf(l.color, 0.0, 1e6);
    if (field == "intensity") return scalar(&l.intensity, 0.0, kMaxLightIntensity);
    if (field == "range") return scalar(&l.range, 0.0, kMaxCoordinate);
    if (field == "inner_cone") return scalar(&l.inner_cone, 0.0, glm::pi<double>() / 2);
    if (field == "outer_cone") return scalar(&l.outer_cone, 0.0, glm::pi<double>() / 2);
    throw unknown();
  }
  if (component == "Camera") {
    if (!s.camera) return std::nullopt;
    Camera& c = *s.camera;
    if (field == "position") return dvec3_leaf(c.position);
    if (field == "look_at") return dvec3_leaf(c.look_at);
    if (field == "up") return vec3_leaf(c.up, -1e6, 1e6);
    if (field == "vertical_fov") return scalar(&c.vertical_fov, 1e-3, glm::pi<double>() - 1e-3);
    if (field == "aspect") return scalar(&c.aspect, 1e-3, 1e3);
    throw unknown();
  }
  if (component == "RayCacheCube") {
    if (field == "resolution") {
      if (!s.ray_cache_cube) return std::nullopt;
      Leaf leaf = scalar(&s.ray_cache_cube->resolution, 1, 4096);
      leaf.power_of_two = true;
      return leaf;
    }
    throw unknown(); // "enabled" is handled by the callers
  }
  throw bad_path(path, "unknown component '" + std::string(component) +
                           "' (Transform, Material, Kinematics, Light, Camera, RayCacheCube)");
}

double parse_number(std::string_view path, std::string_view text) {
  double v = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc{} || end != text.data() + text.size() || !std::isfinite(v))
    throw bad_path(path, "expected a finite number, got '" + std::string(text) + "'");
  return v;
}

template <typename T>
std::string number_text(T v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

} // namespace

const std::vector<std::string>& field_paths() {
  static const std::vector<std::string> paths = [] {
    std::vector<std::string> p;
    const auto add_vec = [&](const std::string& base, bool quaternion = false) {
      for (const std::string& c : vec_names(quaternion)) p.push_back(base + "." + c);
    };
    add_vec("Transform.translation");
    add_vec("Transform.rotation", true);
    add_vec("Transform.scale");
    add_vec("Material.base_color");
    add_vec("Material.emission");
    for (const char* f : {"reflectivity", "transmission", "ior", "roughness"})
      p.push_back(std::string("Material.") + f);
    p.push_back("Kinematics.type");
    p.push_back("Light.type");
    add_vec("Light.color");
    for (const char* f : {"intensity", "range", "inner_cone", "outer_cone"})
      p.push_back(std::string("Light.") + f);
    add_vec("Camera.position");
    add_vec("Camera.look_at");
    add_vec("Camera.up");
    p.push_back("Camera.vertical_fov");
    p.push_back("Camera.aspect");
    p.push_back("RayCacheCube.enabled");
    p.push_back("RayCacheCube.resolution");
    return p;
  }();
  return paths;
}

void set_field(EntitySnapshot& s, std::string_view path, std::string_view value) {
  if (path == "RayCacheCube.enabled") {
    if (value != "0" && value != "1")
      throw bad_path(path, "expected 0 or 1, got '" + std::string(value) + "'");
    if (value == "0")
      s.ray_cache_cube.reset();
    else if (!s.ray_cache_cube)
      s.ray_cache_cube = RayCacheCube{};
    return;
  }
  const std::optional<Leaf> leaf = resolve(s, path);
  if (!leaf)
    throw bad_path(path, "the entity has no " + std::string(path.substr(0, path.find('.'))));
  std::visit(
      [&](auto* p) {
        using T = std::remove_pointer_t<decltype(p)>;
        if constexpr (std::is_same_v<T, Kinematics::Type>) {
          if (value == "static")
            *p = T::Static;
          else if (value == "hierarchical")
            *p = T::Hierarchical;
          else if (value == "free")
            *p = T::Free;
          else
            throw bad_path(path, "expected static, hierarchical or free, got '" +
                                     std::string(value) + "'");
        } else if constexpr (std::is_same_v<T, Light::Type>) {
          if (value == "point")
            *p = T::Point;
          else if (value == "directional")
            *p = T::Directional;
          else if (value == "spot")
            *p = T::Spot;
          else
            throw bad_path(path,
                           "expected point, directional or spot, got '" + std::string(value) + "'");
        } else {
          const double v = parse_number(path, value);
          if (v < leaf->lo || v > leaf->hi)
            throw bad_path(path, "must lie in [" + number_text(leaf->lo) + ", " +
                                     number_text(leaf->hi) + "], got " + std::string(value));
          if constexpr (std::is_same_v<T, std::uint32_t>) {
            const auto u = static_cast<std::uint32_t>(v);
            if (double(u) != v || (leaf->power_of_two && (u & (u - 1)) != 0))
              throw bad_path(path, std::string(leaf->power_of_two ? "expected a power of two"
                                                                  : "expected an integer") +
                                       ", got " + std::string(value));
            *p = u;
          } else {
            *p = T(v);
          }
        }
      },
      leaf->ptr);
  if (s.material && s.material->reflectivity + s.material->transmission > 1.0f)
    throw bad_path(path, "reflectivity + transmission must be at most 1");
  if (path.starts_with("Transform.rotation")) {
    if (glm::length(s.transform->rotation) < 1e-6f)
      throw bad_path(path, "the rotation quaternion must not be zero");
    s.transform->rotation = glm::normalize(s.transform->rotation);
  }
}

std::string get_field(const EntitySnapshot& s, std::string_view path) {
  if (path == "RayCacheCube.enabled") return s.ray_cache_cube ? "1" : "0";
  // resolve only takes addresses; nothing is written through them here.
  const std::optional<Leaf> leaf = resolve(const_cast<EntitySnapshot&>(s), path);
  if (!leaf) return {};
  return std::visit(
      [](auto* p) -> std::string {
        using T = std::remove_pointer_t<decltype(p)>;
        if constexpr (std::is_same_v<T, Kinematics::Type>) {
          return *p == T::Static ? "static" : *p == T::Hierarchical ? "hierarchical" : "free";
        } else if constexpr (std::is_same_v<T, Light::Type>) {
          return *p == T::Point ? "point" : *p == T::Directional ? "directional" : "spot";
        } else {
          return number_text(*p);
        }
      },
      leaf->ptr);
}

} // namespace specula::editor
