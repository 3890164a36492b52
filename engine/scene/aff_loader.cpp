#include "specula/scene/aff_loader.h"

#include "specula/core/error.h"
#include "specula/core/file_io.h"
#include "specula/geometry/primitives.h"
#include "specula/scene/animation_sampling.h"
#include "specula/scene/components.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <map>
#include <memory>
#include <optional>
#include <string_view>
#include <system_error>
#include <tuple>
#include <unordered_map>

namespace specula {
namespace {

/// Most keys one track or `tpa` may have.
constexpr std::uint64_t kMaxFrames = kMaxAnimationFrames;
/// Camera path keys sampled per time unit when the file gives no frames (`a`).
constexpr double kCameraSamplesPerSecond = 60.0;

struct Token {
  std::string_view text;
  int line = 0;
};

/// Whitespace-separated tokens of one file with their line numbers; `#` or `%` at the start of
/// a token comments out the rest of the line (NFF/AFF comments).
class Lexer {
public:
  Lexer(std::string text, std::string file) : text_(std::move(text)), file_(std::move(file)) {}

  [[nodiscard]] const std::string& file() const { return file_; }
  /// The line of the next token (or the last line at the end of the file).
  [[nodiscard]] int line() {
    skip_space();
    return line_;
  }
  [[nodiscard]] std::size_t bytes_left() const { return text_.size() - pos_; }

  [[noreturn]] void fail(int line, const std::string& message) const {
    throw Error(file_, line, message);
  }

  /// The next token, or nothing at the end of the file.
  std::optional<Token> peek() {
    skip_space();
    if (pos_ >= text_.size()) return std::nullopt;
    std::size_t end = pos_;
    while (end < text_.size() && !is_space(text_[end])) ++end;
    return Token{std::string_view(text_).substr(pos_, end - pos_), line_};
  }

  Token next(std::string_view what) {
    const std::optional<Token> t = peek();
    // At the end, the line of the last token: the one whose command is incomplete.
    if (!t) fail(last_line_, "unexpected end of file, expected " + std::string(what));
    pos_ += t->text.size();
    last_line_ = t->line;
    return *t;
  }

  void expect(std::string_view keyword, std::string_view context) {
    const Token t = next(keyword);
    if (t.text != keyword)
      fail(t.line, "expected '" + std::string(keyword) + "' in " + std::string(context) +
                       ", got '" + std::string(t.text) + "'");
  }

  /// A finite number; `what` names the field in messages.
  float number(std::string_view what) {
    const Token t = next(what);
    float v = 0.0f;
    const char* first = t.text.data();
    const char* last = first + t.text.size();
    if (*first == '+') ++first; // from_chars takes no leading '+', which C's scanf allows
    auto [ptr, ec] = std::from_chars(first, last, v);
    if (ec == std::errc::result_out_of_range) {
      // Underflow (1e-45) is a value near zero, written by exporters: keep it. Overflow is not.
      double d = 0.0;
      const auto [dptr, dec] = std::from_chars(first, last, d);
      if (dec != std::errc() || dptr != last || !(std::abs(d) < 1.0))
        fail(t.line, std::string(what) + " '" + std::string(t.text) + "' is out of range");
      v = float(d);
      ptr = dptr;
      ec = std::errc();
    }
    if (ec != std::errc() || ptr != last)
      fail(t.line,
           "expected a number for " + std::string(what) + ", got '" + std::string(t.text) + "'");
    if (!std::isfinite(v)) fail(t.line, std::string(what) + " is not finite");
    return v;
  }

  vec3 vector(std::string_view what) {
    const float x = number(what);
    const float y = number(what);
    return vec3(x, y, number(what));
  }

  /// True when the next token reads as a number (optional fields such as a light's colour).
  bool number_follows() {
    const std::optional<Token> t = peek();
    if (!t) return false;
    float v = 0.0f;
    const char* first = t->text.data() + (t->text.front() == '+' ? 1 : 0);
    const auto [ptr, ec] = std::from_chars(first, t->text.data() + t->text.size(), v);
    return ec == std::errc() && ptr == t->text.data() + t->text.size();
  }

  /// A non-negative integer count of at most `max` items of at least `min_bytes` bytes each, so
  /// that nothing is allocated for items the rest of the file cannot hold (0: a plain number).
  std::uint64_t count(std::string_view what, std::uint64_t max, std::uint64_t min_bytes) {
    const Token t = next(what);
    std::uint64_t v = 0;
    const auto [ptr, ec] = std::from_chars(t.text.data(), t.text.data() + t.text.size(), v);
    if (ec != std::errc() || ptr != t.text.data() + t.text.size())
      fail(t.line, "expected a non-negative integer for " + std::string(what) + ", got '" +
                       std::string(t.text) + "'");
    if (v > max)
      fail(t.line, std::string(what) + " " + std::to_string(v) + " is more than the limit of " +
                       std::to_string(max));
    if (min_bytes > 0 && v > (bytes_left() + 1) / min_bytes)
      fail(t.line, std::string(what) + " " + std::to_string(v) +
                       " is more than the rest of the file can hold");
    return v;
  }

private:
  static bool is_space(char c) {
    return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
  }
  void skip_space() {
    while (pos_ < text_.size()) {
      const char c = text_[pos_];
      if (c == '\n') {
        ++line_;
        ++pos_;
      } else if (is_space(c)) {
        ++pos_;
      } else if (c == '#' || c == '%') {
        while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
      } else {
        return;
      }
    }
  }

  std::string text_;
  std::string file_;
  std::size_t pos_ = 0;
  int line_ = 1;
  int last_line_ = 1;
};

/// Bytes one number takes at least (a digit and a separator): bounds counts against the file.
constexpr std::uint64_t kNumberBytes = 2;

/// "FILE:LINE" with the file's name only: names entities that the file leaves unnamed.
std::string place(const Lexer& lex, int line) {
  return std::filesystem::path(lex.file()).filename().string() + ":" + std::to_string(line);
}

quat axis_angle(Lexer& lex, const vec3& axis, float degrees, int line) {
  if (degrees == 0.0f) return quat(1.0f, 0.0f, 0.0f, 0.0f);
  if (!(glm::length(axis) > 0.0f)) lex.fail(line, "rotation axis is zero");
  return glm::angleAxis(glm::radians(degrees), glm::normalize(axis));
}

/// Geometry merged per transform node, material and vertex layout (the kitchen's ~100k polygons
/// become a few meshes).
struct Group {
  ecs::Entity parent = ecs::null_entity;
  std::uint32_t material = 0;
  TriangleMesh mesh;
};

/// `tpa` triangles of one node and material sharing their key times: one vertex-animated mesh.
struct Morph {
  ecs::Entity parent = ecs::null_entity;
  std::uint32_t material = 0;
  std::vector<float> times;
  std::vector<std::vector<vec3>> keys;    ///< positions per key time
  std::vector<std::vector<vec3>> normals; ///< vertex normals per key time
};

struct PendingKeys {
  std::string name;
  std::string file;
  int line = 0;
  Animation animation;
};

struct Open {
  ecs::Entity entity;
  std::string file;
  int line;
};

class AffReader {
public:
  explicit AffReader(Scene& scene) : scene_(scene), reg_(scene.registry) {
    materials_.push_back(Material{});
  }

  void parse_file(const std::filesystem::path& path, int depth) {
    std::error_code ec;
    const std::filesystem::path canonical = std::filesystem::weakly_canonical(path, ec);
    if (std::find(open_files_.begin(), open_files_.end(), canonical) != open_files_.end())
      throw Error(path.string(), "include cycle: the file includes itself");
    const std::uint64_t size = check_regular_file(path, kMaxDataFileBytes, "AFF scene file");
    total_bytes_ += size;
    if (total_bytes_ > kMaxDataFileBytes)
      throw Error(path.string(), "the scene and its includes exceed " +
                                     std::to_string(kMaxDataFileBytes) + " bytes in all");
    Lexer lex(read_file_bounded(path, kMaxDataFileBytes, "AFF scene file"), path.string());
    open_files_.push_back(canonical);
    while (lex.peek()) command(lex, path, depth);
    open_files_.pop_back();
  }

  void finish();

private:
  void command(Lexer& lex, const std::filesystem::path& path, int depth);
  void viewpoint(Lexer& lex);
  void light(Lexer& lex, bool animated);
  void fill(Lexer& lex, bool extended);
  void polygon(Lexer& lex, bool normals);
  void textured_triangle(Lexer& lex, bool normals);
  void mesh(Lexer& lex);
  void animated_triangle(Lexer& lex);
  void sphere(Lexer& lex);
  void cone(Lexer& lex);
  void place_primitive(const MeshSource& source, std::shared_ptr<const TriangleMesh> geometry,
                       const Transform& tr, const std::string& what);
  void include(Lexer& lex, const std::filesystem::path& path, int depth, int line);
  void keyframes(Lexer& lex, int line);
  void transform(Lexer& lex, bool is_static, int line);

  ecs::Entity current_parent() const {
    return stack_.empty() ? ecs::null_entity : stack_.back().entity;
  }
  Group& group(bool normals, bool uvs) {
    const ecs::Entity parent = current_parent();
    const auto key = std::make_tuple(parent.index, material_, int(normals) | int(uvs) << 1);
    auto [it, added] = group_index_.try_emplace(key, groups_.size());
    if (added) groups_.push_back(Group{parent, material_, {}});
    return groups_[it->second];
  }
  void add_triangles(Lexer& lex, int line, std::uint64_t n) {
    triangles_ += n;
    if (triangles_ > kMaxTriangles)
      lex.fail(line, "the scene has more than " + std::to_string(kMaxTriangles) + " triangles");
  }

  Scene& scene_;
  ecs::Registry& reg_;
  std::vector<std::filesystem::path> open_files_;
  std::uint64_t total_bytes_ = 0;
  std::vector<Open> stack_;
  std::vector<Material> materials_;
  std::uint32_t material_ = 0;
  std::vector<Group> groups_;
  std::map<std::tuple<std::uint32_t, std::uint32_t, int>, std::size_t> group_index_;
  std::vector<Morph> morphs_;
  std::map<std::tuple<std::uint32_t, std::uint32_t, std::vector<float>>, std::size_t> morph_index_;
  std::vector<PendingKeys> keys_;
  /// Transforms and animated lights by name. BART looks animations up by name, so every node
  /// of a name (an included part used twice) follows the same keyframes.
  std::unordered_map<std::string, std::vector<ecs::Entity>> named_;
  std::optional<ecs::Entity> camera_;
  std::vector<ecs::Entity> lights_;
  std::shared_ptr<const TriangleMesh> unit_sphere_;
  std::uint64_t triangles_ = 0;
  int detail_level_ = 0;
  int command_line_ = 0; ///< line of the command being read, for its messages
};

void AffReader::command(Lexer& lex, const std::filesystem::path& path, int depth) {
  const Token t = lex.next("a command");
  const std::string_view c = t.text;
  command_line_ = t.line;
  if (c == "v") {
    viewpoint(lex);
  } else if (c == "b") {
    const vec3 bg = lex.vector("background colour");
    if (glm::any(glm::lessThan(bg, vec3(0.0f))) ||
        glm::any(glm::greaterThan(bg, vec3(kMaxEmission))))
      lex.fail(t.line, "background colour components must be in [0, 1e20]");
    scene_.settings.background = bg;
  } else if (c == "am") {
    // Specula has no ambient term: the global ambient light is read and dropped (docs).
    (void)lex.vector("ambient colour");
  } else if (c == "l" || c == "la") {
    light(lex, c == "la");
  } else if (c == "f" || c == "fm") {
    fill(lex, c == "fm");
  } else if (c == "p" || c == "pp") {
    polygon(lex, c == "pp");
  } else if (c == "tt" || c == "ttp") {
    textured_triangle(lex, c == "ttp");
  } else if (c == "m") {
    mesh(lex);
  } else if (c == "tpa") {
    animated_triangle(lex);
  } else if (c == "s") {
    sphere(lex);
  } else if (c == "c") {
    cone(lex);
  } else if (c == "d") {
    detail_level_ = int(lex.count("detail level", 1'000'000, 0));
  } else if (c == "i") {
    include(lex, path, depth, t.line);
  } else if (c == "a") {
    const float start = lex.number("animation start time");
    const float end = lex.number("animation end time");
    const std::uint64_t frames = lex.count("number of frames", kMaxAnimationFrames, 0);
    if (!(end >= start)) lex.fail(t.line, "animation end time is before its start time");
    if (frames == 0) lex.fail(t.line, "the number of frames must be at least 1");
    scene_.settings.anim_start = start;
    scene_.settings.anim_end = end;
    scene_.settings.anim_frames = std::uint32_t(frames);
  } else if (c == "k") {
    keyframes(lex, t.line);
  } else if (c == "x" || c == "xs") {
    transform(lex, c == "xs", t.line);
  } else if (c == "}") {
    if (stack_.empty()) lex.fail(t.line, "'}' without an open transform ('x' or 'xs')");
    stack_.pop_back();
  } else {
    lex.fail(t.line, "unknown command '" + std::string(c) + "'");
  }
}

void AffReader::viewpoint(Lexer& lex) {
  const int line = command_line_;
  Camera cam;
  lex.expect("from", "viewpoint 'v'");
  cam.position = dvec3(lex.vector("from"));
  lex.expect("at", "viewpoint 'v'");
  cam.look_at = dvec3(lex.vector("at"));
  lex.expect("up", "viewpoint 'v'");
  cam.up = lex.vector("up");
  lex.expect("angle", "viewpoint 'v'");
  const float angle = lex.number("angle");
  lex.expect("hither", "viewpoint 'v'");
  (void)lex.number("hither"); // the tracers use their own ray offsets, not a near plane
  lex.expect("resolution", "viewpoint 'v'");
  const auto w = std::uint32_t(lex.count("resolution width", kMaxImageSide, 0));
  const auto h = std::uint32_t(lex.count("resolution height", kMaxImageSide, 0));
  if (w == 0 || h == 0) lex.fail(line, "resolution must be at least 1 x 1");
  if (!(angle > 0.0f && angle < 180.0f)) lex.fail(line, "angle must be in (0, 180) degrees");
  if (cam.position == cam.look_at) lex.fail(line, "'from' and 'at' must differ");
  if (!in_range(cam.position) || !in_range(cam.look_at))
    lex.fail(line, std::string("'from' or 'at' is outside ") + kCoordinateRangeText);
  if (!(glm::length(cam.up) > 0.0f)) lex.fail(line, "'up' must not be zero");
  // AFF: the angle is the vertical field of view, the aspect width / height.
  cam.vertical_fov = glm::radians(angle);
  cam.aspect = float(w) / float(h);
  scene_.settings.width = w;
  scene_.settings.height = h;
  if (!camera_) {
    camera_ = reg_.create();
    reg_.emplace<Name>(*camera_, "camera");
  }
  reg_.emplace_or_replace<Camera>(*camera_, cam);
}

void AffReader::light(Lexer& lex, bool animated) {
  const int line = command_line_;
  std::string name = animated ? std::string(lex.next("light name").text) : "light";
  const vec3 pos = lex.vector("light position");
  vec3 color(1.0f);
  if (lex.number_follows()) color = lex.vector("light colour");
  if (glm::any(glm::lessThan(color, vec3(0.0f))) ||
      glm::any(glm::greaterThan(color, vec3(kMaxLightIntensity))))
    lex.fail(line, "light colour components must be in [0, 1e20]");
  const ecs::Entity e = reg_.create();
  reg_.emplace<Name>(e, name);
  Transform tr;
  tr.translation = dvec3(pos);
  reg_.emplace<Transform>(e, tr);
  Light l;
  l.color = color;
  reg_.emplace<Light>(e, l);
  lights_.push_back(e);
  if (animated) named_[name].push_back(e);
}

void AffReader::fill(Lexer& lex, bool extended) {
  Material m;
  float reflect = 0.0f, transmit = 0.0f, ior = 1.0f;
  if (extended) {
    (void)lex.vector("ambient colour"); // no ambient term in Specula
    m.base_color = lex.vector("diffuse colour");
    const vec3 specular = lex.vector("specular colour");
    reflect = glm::max(specular.x, glm::max(specular.y, specular.z));
  } else {
    const vec3 rgb = lex.vector("colour");
    const float kd = lex.number("Kd");
    reflect = lex.number("Ks");
    m.base_color = rgb * kd;
  }
  (void)lex.number("Shine"); // no Phong highlights in the Whitted integrator
  transmit = lex.number("T");
  ior = lex.number("index of refraction");
  // Whitted's model as Specula's weights: Ks (or the specular colour) reflects, T refracts, both
  // in [0, 1] and scaled down together when they sum past 1. NFF files often give 0 as the index
  // of an opaque material: below 1 means 1.
  m.base_color = glm::clamp(m.base_color, vec3(0.0f), vec3(1.0f));
  m.reflectivity = glm::clamp(reflect, 0.0f, 1.0f);
  m.transmission = glm::clamp(transmit, 0.0f, 1.0f);
  const float sum = m.reflectivity + m.transmission;
  if (sum > 1.0f) {
    m.reflectivity /= sum;
    m.transmission /= sum;
  }
  m.ior = std::max(ior, 1.0f);
  const auto it = std::find(materials_.begin(), materials_.end(), m);
  material_ = std::uint32_t(std::distance(materials_.begin(), it));
  if (it == materials_.end()) materials_.push_back(m);
}

void AffReader::polygon(Lexer& lex, bool normals) {
  const int line = command_line_;
  const std::uint64_t n = lex.count("vertex count", kMaxVertices, (normals ? 6 : 3) * kNumberBytes);
  if (n < 3) lex.fail(line, "a polygon needs at least 3 vertices");
  add_triangles(lex, line, n - 2);
  Group& g = group(normals, false);
  TriangleMesh& mesh = g.mesh;
  const auto base = std::uint32_t(mesh.positions.size());
  if (mesh.positions.size() + n > kMaxVertices) lex.fail(line, "too many vertices in one mesh");
  for (std::uint64_t i = 0; i < n; ++i) {
    mesh.positions.push_back(lex.vector("vertex"));
    if (normals) mesh.normals.push_back(lex.vector("normal"));
  }
  // A fan, as BART converts its (convex) polygons.
  for (std::uint32_t i = 1; i + 1 < n; ++i)
    mesh.triangles.push_back(uvec3(base, base + i, base + i + 1));
}

void AffReader::textured_triangle(Lexer& lex, bool normals) {
  const int line = command_line_;
  (void)lex.next("texture name"); // textures are not supported: the coordinates are kept
  add_triangles(lex, line, 1);
  TriangleMesh& mesh = group(normals, true).mesh;
  const auto base = std::uint32_t(mesh.positions.size());
  for (int i = 0; i < 3; ++i) {
    mesh.positions.push_back(lex.vector("vertex"));
    if (normals) mesh.normals.push_back(lex.vector("normal"));
    const float u = lex.number("texture u");
    mesh.uvs.push_back(vec2(u, lex.number("texture v")));
  }
  mesh.triangles.push_back(uvec3(base, base + 1, base + 2));
}

void AffReader::mesh(Lexer& lex) {
  const int line = command_line_;
  lex.expect("vertices", "mesh 'm'");
  const std::uint64_t nv = lex.count("vertex count", kMaxVertices, 3 * kNumberBytes);
  std::vector<vec3> verts(nv);
  for (vec3& v : verts) v = lex.vector("vertex");
  std::vector<vec3> norms;
  std::vector<vec2> uvs;
  Token t = lex.next("'normals', 'texturecoords' or 'triangles'");
  if (t.text == "normals") {
    norms.resize(lex.count("normal count", kMaxVertices, 3 * kNumberBytes));
    for (vec3& n : norms) n = lex.vector("normal");
    t = lex.next("'texturecoords' or 'triangles'");
  }
  if (t.text == "texturecoords") {
    uvs.resize(lex.count("texture coordinate count", kMaxVertices, 2 * kNumberBytes));
    (void)lex.next("texture name");
    for (vec2& uv : uvs) {
      const float u = lex.number("texture u");
      uv = vec2(u, lex.number("texture v"));
    }
    t = lex.next("'triangles'");
  }
  if (t.text != "triangles")
    lex.fail(t.line, "expected 'triangles' in mesh 'm', got '" + std::string(t.text) + "'");
  const std::uint64_t per = 3 * (1 + !norms.empty() + !uvs.empty());
  const std::uint64_t nt = lex.count("triangle count", kMaxTriangles, per * kNumberBytes);
  add_triangles(lex, line, nt);
  TriangleMesh& mesh = group(!norms.empty(), !uvs.empty()).mesh;
  const auto index = [&](std::uint64_t size, std::string_view what) {
    const int at = lex.line();
    const std::uint64_t i = lex.count(what, kMaxVertices, 0);
    if (i >= size)
      lex.fail(at, std::string(what) + " " + std::to_string(i) + " is out of range (" +
                       std::to_string(size) + " given)");
    return std::uint32_t(i);
  };
  if (mesh.positions.size() + 3 * nt > kMaxVertices)
    lex.fail(line, "too many vertices in one mesh");
  for (std::uint64_t k = 0; k < nt; ++k) {
    // Each corner gets its own vertex: positions, normals and coordinates are indexed apart.
    uvec3 v, n, c;
    for (int j = 0; j < 3; ++j) v[j] = index(verts.size(), "vertex index");
    if (!norms.empty())
      for (int j = 0; j < 3; ++j) n[j] = index(norms.size(), "normal index");
    if (!uvs.empty())
      for (int j = 0; j < 3; ++j) c[j] = index(uvs.size(), "texture coordinate index");
    const auto base = std::uint32_t(mesh.positions.size());
    for (int j = 0; j < 3; ++j) {
      mesh.positions.push_back(verts[v[j]]);
      if (!norms.empty()) mesh.normals.push_back(norms[n[j]]);
      if (!uvs.empty()) mesh.uvs.push_back(uvs[c[j]]);
    }
    mesh.triangles.push_back(uvec3(base, base + 1, base + 2));
  }
}

void AffReader::animated_triangle(Lexer& lex) {
  const int line = command_line_;
  const std::uint64_t n = lex.count("key count", kMaxFrames, 19 * kNumberBytes);
  if (n == 0) lex.fail(line, "an animated triangle needs at least one key");
  add_triangles(lex, line, 1);
  std::vector<float> times(n);
  std::vector<vec3> pos(3 * n), nrm(3 * n);
  for (std::uint64_t k = 0; k < n; ++k) {
    const int at = lex.line();
    times[k] = lex.number("key time");
    if (k > 0 && !(times[k] > times[k - 1])) lex.fail(at, "key times must be strictly increasing");
    for (int j = 0; j < 3; ++j) {
      pos[3 * k + j] = lex.vector("vertex");
      const int normal_line = lex.line();
      nrm[3 * k + j] = lex.vector("normal");
      if (!(glm::length(nrm[3 * k + j]) > 1e-6f))
        lex.fail(normal_line, "an animated triangle's normal has zero length");
    }
  }
  const auto key = std::make_tuple(current_parent().index, material_, times);
  auto [it, added] = morph_index_.try_emplace(key, morphs_.size());
  if (added) {
    morphs_.push_back(Morph{current_parent(), material_, times, {}, {}});
    morphs_.back().keys.resize(n);
    morphs_.back().normals.resize(n);
  }
  Morph& m = morphs_[it->second];
  for (std::uint64_t k = 0; k < n; ++k)
    for (int j = 0; j < 3; ++j) {
      m.keys[k].push_back(pos[3 * k + j]);
      m.normals[k].push_back(nrm[3 * k + j]);
    }
}

void AffReader::sphere(Lexer& lex) {
  const int line = command_line_;
  const vec3 center = lex.vector("sphere centre");
  const float radius = lex.number("sphere radius");
  if (!(radius > 0.0f)) lex.fail(line, "sphere radius must be positive");
  MeshSource source;
  source.kind = MeshSource::Kind::Primitive;
  source.primitive = "sphere";
  source.radius = 1.0f;
  if (!unit_sphere_)
    unit_sphere_ = std::make_shared<const TriangleMesh>(make_primitive(source, lex.file()));
  add_triangles(lex, line, unit_sphere_->triangle_count());
  Transform tr;
  tr.translation = dvec3(center);
  tr.scale = vec3(radius);
  place_primitive(source, unit_sphere_, tr, "sphere@" + place(lex, line));
}

void AffReader::cone(Lexer& lex) {
  const int line = command_line_;
  vec3 base = lex.vector("cone base");
  float r0 = lex.number("cone base radius");
  vec3 apex = lex.vector("cone apex");
  float r1 = lex.number("cone apex radius");
  // Negative radii mean "seen from inside" in NFF; the tracers see both sides anyway.
  r0 = std::abs(r0);
  r1 = std::abs(r1);
  if (r0 < r1) {
    std::swap(base, apex);
    std::swap(r0, r1);
  }
  const vec3 axis = apex - base;
  const float height = glm::length(axis);
  if (!(height > 0.0f)) lex.fail(line, "cone base and apex coincide");
  if (!(r0 > 0.0f)) lex.fail(line, "cone radii are zero");
  MeshSource source;
  source.kind = MeshSource::Kind::Primitive;
  source.radius = r0;
  source.height = height;
  if (r1 == r0) {
    source.primitive = "cylinder";
  } else {
    source.primitive = "cone"; // truncated when r1 > 0
    source.top_radius = r1;
  }
  auto geometry = std::make_shared<const TriangleMesh>(make_primitive(source, lex.file()));
  add_triangles(lex, line, geometry->triangle_count());
  // The primitives stand on +Y about the origin: turn +Y onto the axis, centre on its middle.
  const vec3 dir = axis / height;
  Transform tr;
  tr.translation = dvec3(0.5f * (base + apex));
  const vec3 turn = glm::cross(vec3(0, 1, 0), dir);
  const float angle = std::atan2(glm::length(turn), dir.y);
  if (glm::length(turn) > 1e-7f)
    tr.rotation = glm::angleAxis(angle, glm::normalize(turn));
  else if (dir.y < 0.0f)
    tr.rotation = glm::angleAxis(glm::pi<float>(), vec3(1, 0, 0));
  place_primitive(source, std::move(geometry), tr, source.primitive + "@" + place(lex, line));
}

void AffReader::place_primitive(const MeshSource& source,
                                std::shared_ptr<const TriangleMesh> geometry, const Transform& tr,
                                const std::string& what) {
  const ecs::Entity e = reg_.create();
  reg_.emplace<Name>(e, what);
  reg_.emplace<Transform>(e, tr);
  if (current_parent() != ecs::null_entity) reg_.emplace<Parent>(e, Parent{current_parent()});
  reg_.emplace<Mesh>(e, Mesh{std::move(geometry), source, {}, 0});
  reg_.emplace<Material>(e, materials_[material_]);
}

void AffReader::include(Lexer& lex, const std::filesystem::path& path, int depth, int line) {
  // BART writes `i DETAIL FILE` (skipped when DETAIL exceeds the level set by `d`); a bare
  // `i FILE` is read as detail 0.
  int detail = 0;
  Token name = lex.next("include file name");
  const std::optional<Token> after = lex.peek();
  if (after && after->line == name.line) {
    std::uint64_t d = 0;
    const auto [ptr, ec] =
        std::from_chars(name.text.data(), name.text.data() + name.text.size(), d);
    if (ec == std::errc() && ptr == name.text.data() + name.text.size() && d < 1'000'000) {
      detail = int(d);
      name = lex.next("include file name");
    }
  }
  if (detail > detail_level_) return;
  if (depth + 1 > kMaxAffIncludeDepth)
    lex.fail(line, "includes nested deeper than " + std::to_string(kMaxAffIncludeDepth));
  const std::filesystem::path target = path.parent_path() / std::string(name.text);
  std::error_code ec;
  if (!std::filesystem::exists(target, ec))
    lex.fail(line, "included file '" + target.string() + "' not found");
  try {
    parse_file(target, depth + 1);
  } catch (const Error& e) {
    if (e.line() != 0) throw;
    lex.fail(line, "in included file: " + std::string(e.what()));
  }
}

void AffReader::keyframes(Lexer& lex, int line) {
  PendingKeys pk;
  pk.name = std::string(lex.next("animation name").text);
  pk.file = lex.file();
  pk.line = line;
  lex.expect("{", "keyframes 'k'");
  bool seen[4] = {false, false, false, false};
  for (;;) {
    const Token motion = lex.next("'transl', 'rot', 'scale', 'visibility' or '}'");
    if (motion.text == "}") break;
    const int kind = motion.text == "transl"       ? 0
                     : motion.text == "rot"        ? 1
                     : motion.text == "scale"      ? 2
                     : motion.text == "visibility" ? 3
                                                   : -1;
    if (kind < 0)
      lex.fail(motion.line, "unknown keyframe type '" + std::string(motion.text) +
                                "' (expected transl, rot, scale or visibility)");
    if (seen[kind]) lex.fail(motion.line, "'" + std::string(motion.text) + "' given twice");
    seen[kind] = true;
    const std::uint64_t per = kind == 1 ? 8 : kind == 3 ? 2 : 7;
    const std::uint64_t n = lex.count("key count", kMaxFrames, per * kNumberBytes);
    if (kind != 3 && n < 4)
      lex.fail(motion.line, "'" + std::string(motion.text) +
                                "' needs at least 4 keys (the first and last only shape the "
                                "spline's ends), got " +
                                std::to_string(n));
    std::vector<float> times;
    for (std::uint64_t i = 0; i < n; ++i) {
      const int at = lex.line();
      const float time = lex.number("key time");
      if (!times.empty() && !(time > times.back()))
        lex.fail(at, "key times must be strictly increasing");
      times.push_back(time);
      if (kind == 3) { // a switch from this time on: 1 shown, 0 hidden
        pk.animation.visibility.visible.push_back(
            std::uint8_t(lex.count("visibility flag (0 or 1)", 1, 0)));
        continue;
      }
      const vec3 v = lex.vector("key value");
      const float angle = kind == 1 ? lex.number("rotation angle") : 0.0f;
      const vec3 tcb = lex.vector("tension, continuity, bias");
      Animation& a = pk.animation;
      if (kind == 0) {
        a.translation.values.push_back(dvec3(v));
        a.translation.tcb.push_back(tcb);
      } else if (kind == 1) {
        a.rotation.values.push_back(axis_angle(lex, v, angle, at));
        a.rotation.tcb.push_back(tcb);
      } else {
        a.scale.values.push_back(v);
        a.scale.tcb.push_back(tcb);
      }
    }
    Animation& a = pk.animation;
    if (kind == 0) a.translation.times = times;
    if (kind == 1) a.rotation.times = times;
    if (kind == 2) a.scale.times = times;
    if (kind == 3) a.visibility.times = times;
  }
  Animation& a = pk.animation;
  if (!a.translation.empty()) a.translation.interpolation = Interpolation::KochanekBartels;
  if (!a.rotation.empty()) a.rotation.interpolation = Interpolation::KochanekBartels;
  if (!a.scale.empty()) a.scale.interpolation = Interpolation::KochanekBartels;
  validate_animation(pk.animation, 0, lex.file() + ":" + std::to_string(line), "k " + pk.name);
  keys_.push_back(std::move(pk));
}

void AffReader::transform(Lexer& lex, bool is_static, int line) {
  const ecs::Entity e = reg_.create();
  Transform tr;
  std::string name;
  if (is_static) {
    tr.scale = lex.vector("scale");
    const vec3 axis = lex.vector("rotation axis");
    tr.rotation = axis_angle(lex, axis, lex.number("rotation angle"), line);
    tr.translation = dvec3(lex.vector("translation"));
    name = "xs@" + place(lex, line);
  } else {
    name = std::string(lex.next("transform name").text);
    named_[name].push_back(e);
  }
  lex.expect("{", is_static ? "static transform 'xs'" : "transform 'x'");
  reg_.emplace<Name>(e, name);
  reg_.emplace<Transform>(e, tr);
  if (current_parent() != ecs::null_entity) reg_.emplace<Parent>(e, Parent{current_parent()});
  stack_.push_back(Open{e, lex.file(), line});
}

/// The camera along BART's `k camera`: the translation track moves the eye, the rotation track
/// turns the view and rolls it (the camera looks down its -Z, its +Y up). Sampled exactly at
/// every frame of `a` (or 60 per second over the keys when the file gives no frames), linear in
/// between.
CameraPath camera_path(const Animation& a, const Camera& cam, const RenderSettings& s) {
  double t0 = 0.0, t1 = 0.0;
  std::uint64_t n = 0;
  if (s.anim_frames > 0) {
    t0 = s.anim_start;
    t1 = s.anim_end;
    n = s.anim_frames;
  } else {
    const auto& times = !a.translation.empty() ? a.translation.times : a.rotation.times;
    t0 = times[1];
    t1 = times[times.size() - 2];
    n = std::min<std::uint64_t>(kMaxFrames,
                                std::uint64_t(std::ceil((t1 - t0) * kCameraSamplesPerSecond)) + 1);
  }
  if (n < 2 || !(t1 > t0)) n = 1;
  const double distance = glm::length(cam.look_at - cam.position);
  CameraPath path;
  path.time = float(t0);
  for (std::uint64_t i = 0; i < n; ++i) {
    const double t = n == 1 ? t0 : t0 + (t1 - t0) * double(i) / double(n - 1);
    CameraPath::Key key;
    key.time = float(t);
    if (!path.keys.empty() && !(key.time > path.keys.back().time)) continue;
    key.position = a.translation.empty() ? cam.position : sample(a.translation, key.time);
    dvec3 dir = cam.look_at - cam.position;
    key.up = glm::normalize(cam.up);
    if (!a.rotation.empty()) {
      const quat q = sample(a.rotation, key.time);
      dir = distance * dvec3(q * vec3(0, 0, -1));
      key.up = glm::normalize(q * vec3(0, 1, 0));
    }
    key.look_at = key.position + dir;
    path.keys.push_back(key);
  }
  return path;
}

void AffReader::finish() {
  if (!stack_.empty())
    throw Error(stack_.back().file, stack_.back().line,
                "transform opened here is never closed with '}'");
  const float t0 = scene_.settings.anim_frames > 0 ? float(scene_.settings.anim_start) : 0.0f;
  for (const PendingKeys& pk : keys_) {
    if (pk.name == "camera") {
      if (!camera_) throw Error(pk.file, pk.line, "'k camera' needs a viewpoint 'v'");
      if (reg_.try_get<CameraPath>(*camera_))
        throw Error(pk.file, pk.line, "keyframes for 'camera' given twice");
      if (pk.animation.translation.empty() && pk.animation.rotation.empty()) continue;
      CameraPath path = camera_path(pk.animation, reg_.get<Camera>(*camera_), scene_.settings);
      validate_camera_path(path, pk.file + ":" + std::to_string(pk.line), "k camera");
      reg_.emplace<CameraPath>(*camera_, std::move(path));
      continue;
    }
    const auto it = named_.find(pk.name);
    if (it == named_.end())
      throw Error(pk.file, pk.line,
                  "keyframes for '" + pk.name + "', which no 'x' transform or 'la' light names");
    for (const ecs::Entity e : it->second) {
      if (reg_.try_get<Animation>(e))
        throw Error(pk.file, pk.line, "keyframes for '" + pk.name + "' given twice");
      Animation a = pk.animation;
      a.time = t0;
      // Start where the animation starts, so the first frame needs no update.
      Transform& tr = reg_.get<Transform>(e);
      if (!a.translation.empty()) tr.translation = sample(a.translation, t0);
      if (!a.rotation.empty()) tr.rotation = sample(a.rotation, t0);
      if (!a.scale.empty()) tr.scale = sample(a.scale, t0);
      reg_.emplace<Animation>(e, std::move(a));
    }
  }

  const auto add_mesh = [&](ecs::Entity parent, std::uint32_t material, std::string name,
                            TriangleMesh&& mesh) {
    const ecs::Entity e = reg_.create();
    reg_.emplace<Name>(e, std::move(name));
    reg_.emplace<Transform>(e);
    if (parent != ecs::null_entity) reg_.emplace<Parent>(e, Parent{parent});
    reg_.emplace<Material>(e, materials_[material]);
    mesh.validate(scene_.source.string());
    reg_.emplace<Mesh>(e, Mesh{std::make_shared<const TriangleMesh>(std::move(mesh)), {}, {}, 0});
    return e;
  };
  const auto node_name = [&](ecs::Entity parent) {
    return parent == ecs::null_entity ? std::string("scene") : reg_.get<Name>(parent).value;
  };
  for (Group& g : groups_)
    add_mesh(g.parent, g.material,
             node_name(g.parent) + "/mesh " + std::to_string(&g - groups_.data()),
             std::move(g.mesh));
  for (Morph& m : morphs_) {
    TriangleMesh mesh;
    mesh.positions = m.keys.front();
    mesh.normals = m.normals.front();
    for (std::uint32_t i = 0; i < mesh.positions.size(); i += 3)
      mesh.triangles.push_back(uvec3(i, i + 1, i + 2));
    const ecs::Entity e = add_mesh(
        m.parent, m.material, node_name(m.parent) + "/morph " + std::to_string(&m - morphs_.data()),
        std::move(mesh));
    if (m.times.size() > 1) {
      // BART's tpa interpolates linearly between its keys, normals included (renormalised).
      Animation a;
      a.vertices.times = m.times;
      a.vertices.values = std::move(m.keys);
      a.normals.times = std::move(m.times);
      a.normals.values = std::move(m.normals);
      a.time = t0;
      validate_animation(a, a.vertices.values.front().size(), scene_.source.string(), "tpa");
      reg_.emplace<Animation>(e, std::move(a));
    }
  }

  // NFF lights have no falloff; Specula's point lights fall off with distance². Each light gets
  // the intensity that gives irradiance 1 at the point the viewpoint looks at.
  const dvec3 target = camera_ ? reg_.get<Camera>(*camera_).look_at : dvec3(0.0);
  for (const ecs::Entity e : lights_) {
    const double d = glm::length(reg_.get<Transform>(e).translation - target);
    reg_.get<Light>(e).intensity = float(std::clamp(d * d, 1e-12, double(kMaxLightIntensity)));
  }
}

} // namespace

Scene load_aff_scene(const std::filesystem::path& path) {
  Scene scene;
  scene.source = path;
  AffReader reader(scene);
  reader.parse_file(path, 0);
  reader.finish();
  return scene;
}

} // namespace specula
