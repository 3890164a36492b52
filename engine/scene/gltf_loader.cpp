#include "specula/scene/gltf_loader.h"

#include "specula/core/error.h"
#include "specula/core/file_io.h"
#include "specula/core/log.h"
#include "specula/scene/animation_sampling.h"
#include "specula/scene/components.h"
#include "specula/scene/strict_json.h"

// tiny_gltf.h is third-party code written to a looser warning set than ours (-Wshadow,
// -Wold-style-cast, ...). From /usr/include GCC already treats it as a system header, but a copy
// reached through -I would break -Werror builds on code that is not ours to fix, so its warnings
// are silenced for this include only. libtinygltf.so holds the implementation:
// TINYGLTF_IMPLEMENTATION (and STB_*_IMPLEMENTATION) must not be defined here.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wold-style-cast"
#pragma GCC diagnostic ignored "-Wcast-align"
#pragma GCC diagnostic ignored "-Wnull-dereference"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#pragma GCC diagnostic ignored "-Wpedantic"
#include <tiny_gltf.h>
#pragma GCC diagnostic pop

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iterator>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <span>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <utility>
#include <vector>

// Mapping decisions (docs/scene-format.md, "glTF"):
// - Scene: `scene` (the default scene), else scenes[0], else every node that is nobody's child.
// - Node → entity with Name ("node N" when unnamed), Transform (TRS, or the matrix decomposed;
//   shear, perspective, non-finite or singular matrices are errors), Parent for children.
// - Mesh: the triangle primitives of a mesh, grouped by material. One group: Mesh + Material on
//   the node's entity, MeshSource{File, file name, mesh index} (load_gltf_mesh rebuilds exactly
//   this geometry). Several groups: one child entity per group with an identity Transform and an
//   Inline MeshSource (a glTF mesh index alone cannot name a subset of its primitives).
//   Points and lines are skipped with a warning; strips and fans become triangle lists.
// - Material (from pbrMetallicRoughness; textures ignored): base_color = baseColorFactor.rgb;
//   emission = emissiveFactor × KHR_materials_emissive_strength; roughness = roughnessFactor;
//   reflectivity = metallic × (1 − roughness): a smooth metal is a mirror, a rough one scatters
//   like the diffuse term; transmission = KHR_materials_transmission × (1 − metallic), as glTF
//   applies transmission to the dielectric part only (this also keeps reflectivity +
//   transmission ≤ 1); ior = KHR_materials_ior (default 1.5). Primitives without a material
//   get the glTF default material (white, metallic 1, roughness 1: diffuse white).
// - Camera: perspective → Camera in world space from the node's world matrix at load time
//   (origin, −Z forward, +Y up), aspect = aspectRatio or settings width/height. Orthographic
//   cameras are skipped with a warning (Camera is a pinhole model). Camera is world-space, so
//   it keeps the load-time pose even when its node is animated.
// - KHR_lights_punctual → Light on the node's entity (the entity's transform places it).
// - Animation: channels of every glTF animation are merged per node (a node/path pair taken by
//   an earlier animation keeps it, with a warning). LINEAR → Linear, STEP → Step, CUBICSPLINE →
//   the key values only, Linear (the tangents are dropped). Morph weights → vertex keys
//   (base + Σ weight_i · target_i) on the mesh entities of the node.
// - Kinematics: none (glTF cannot state them); load_scene infers them from the animations
//   (settle_kinematics in kinematics_rules.h), as for every format.
// - Skins are ignored (meshes stay in their bind pose), with a warning.
// - Unsupported entries of extensionsRequired (KHR_draco_mesh_compression among them) are
//   errors naming the extension; optional extensions the loader does not know are ignored.

namespace specula {
namespace {

namespace fs = std::filesystem;

/// Extensions the loader maps (lights, transmission, ior, emissive strength, quantized
/// attributes) or can ignore without changing geometry (texture transforms: textures are not
/// used). Any other entry of extensionsRequired is an error naming it.
constexpr std::array<std::string_view, 6> kSupportedRequiredExtensions = {
    "KHR_lights_punctual",        "KHR_materials_emissive_strength", "KHR_materials_ior",
    "KHR_materials_transmission", "KHR_mesh_quantization",           "KHR_texture_transform"};

/// Most elements one accessor may hold (three indices per triangle of the largest mesh any loader
/// accepts); checked before anything is allocated, so absurd counts are errors.
constexpr std::uint64_t kMaxAccessorElements = 3 * kMaxTriangles;
/// Most positions all vertex-animation keys of one mesh entity may hold together (768 MiB).
constexpr std::uint64_t kMaxMorphKeyPositions = std::uint64_t(1) << 26;
/// Most elements of an accessor without a bufferView (zeros, usually patched by sparse values)
/// when nothing else bounds its count: such an accessor costs memory but no file bytes.
constexpr std::uint64_t kMaxUnbackedElements = std::uint64_t(1) << 24;

std::string index_field(std::string_view array, std::size_t index) {
  return std::string(array) + "[" + std::to_string(index) + "]";
}

/// The parsed file plus the name used in messages.
struct Context {
  const tinygltf::Model& model;
  std::string file;

  [[noreturn]] void fail(const std::string& field, const std::string& message) const {
    throw Error(file, field, message);
  }
  void warn(const std::string& message) const {
    log_warning(printable(file, 256) + ": " + one_line(message));
  }
};

/// A JSON number as float. Doubles beyond float range (1e300) are errors too: converting them
/// would be undefined behaviour, not infinity.
float to_float(const Context& ctx, double value, const std::string& field) {
  if (!std::isfinite(value) || std::abs(value) > double(std::numeric_limits<float>::max()))
    ctx.fail(field, "value is not a finite 32-bit float");
  return static_cast<float>(value);
}

/// A JSON number as a double coordinate (a translation), within the representable range
/// (core/math.h kMaxCoordinate), so that `info` refuses what `render` could not trace.
double to_coordinate(const Context& ctx, double value, const std::string& field) {
  if (!std::isfinite(value) || !in_range(value))
    ctx.fail(field, std::string("coordinate is not finite or outside ") + kCoordinateRangeText);
  return value;
}

// ---------------------------------------------------------------------------------------------
// Reading the file

/// tinygltf decodes every image by default; Specula uses no textures, so images are skipped
/// (this also keeps tinygltf from reading image bytes through unchecked buffer views).
bool skip_image(tinygltf::Image*, const int, std::string*, std::string*, int, int,
                const unsigned char*, int, void*) {
  return true;
}

std::string trimmed(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' ')) s.pop_back();
  return s;
}

/// The JSON chunk of a GLB (12-byte header, the chunk's length and type, then its text), or
/// what there is of it: empty when the file is too short, cut at the end of the file when the
/// length says more. Only for checks made before tinygltf's own; it reports malformed framing.
std::string_view glb_json_chunk(std::string_view bytes) {
  if (bytes.size() < 20) return {};
  std::uint32_t length = 0;
  for (std::size_t b = 0; b < 4; ++b)
    length |= std::uint32_t{static_cast<unsigned char>(bytes[12 + b])} << (8 * b);
  return bytes.substr(20, std::min<std::size_t>(length, bytes.size() - 20));
}

// tinygltf reads a glTF's external buffers and images (by URI) through these, so that they get
// the same treatment as the file itself: regular files only, within kMaxDataFileBytes.

bool file_exists(const std::string& path, void*) {
  std::error_code ec;
  return fs::exists(fs::status(path, ec)); // a device or FIFO "exists": reading it fails, clearly
}

std::string same_path(const std::string& path, void*) { return path; }

bool read_bounded(std::vector<unsigned char>* out, std::string* err, const std::string& path,
                  void*) {
  try {
    const std::string bytes = read_file_bounded(path, kMaxDataFileBytes, "glTF buffer or image");
    out->assign(bytes.begin(), bytes.end());
    return true;
  } catch (const Error& e) {
    if (err) *err += e.message();
    return false;
  }
}

bool write_nothing(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err += "writing is not supported";
  return false;
}

/// Throws for the first entry of `required` that the loader does not support.
void check_required_extensions(const std::string& file, const std::vector<std::string>& required) {
  for (std::size_t i = 0; i < required.size(); ++i) {
    const std::string& name = required[i];
    if (std::find(kSupportedRequiredExtensions.begin(), kSupportedRequiredExtensions.end(), name) !=
        kSupportedRequiredExtensions.end())
      continue;
    const std::string why = name == "KHR_draco_mesh_compression"
                                ? " (Draco-compressed meshes cannot be decoded by this build)"
                                : "";
    throw Error(file, index_field("extensionsRequired", i),
                "required extension " + printable(name) + " is not supported" + why);
  }
}

/// extensionsRequired read straight from the file's JSON (best effort: empty when unreadable).
/// Used when tinygltf fails, because a file that needs an unsupported extension (Draco) often
/// fails inside tinygltf first, with a message that hides the real reason.
std::vector<std::string> required_extensions_in_json(std::string_view text) {
  const nlohmann::json doc = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  std::vector<std::string> out;
  if (!doc.is_object()) return out;
  const auto it = doc.find("extensionsRequired");
  if (it == doc.end() || !it->is_array()) return out;
  for (const auto& name : *it)
    if (name.is_string()) out.push_back(name.get<std::string>());
  return out;
}

tinygltf::Model read_model(const fs::path& path) {
  const std::string file = path.string();
  // Regular files only, within the size bound (tinygltf would read a device for ever), and the
  // whole file in memory, which tinygltf then parses from there.
  const std::string bytes = read_file_bounded(path, kMaxDataFileBytes, "glTF file");
  if (bytes.empty()) throw Error(file, "empty file (0 bytes)");

  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  // .glb is always read as binary, so a wrong magic number is reported as such; other names are
  // sniffed, as some tools write binary glTF under .gltf.
  const bool binary = ext == ".glb" || (ext != ".gltf" && bytes.starts_with("glTF"));
  const std::string_view json_text = binary ? glb_json_chunk(bytes) : std::string_view(bytes);
  // tinygltf's JSON handling recurses once per level of nesting: 20,000 levels overflow the
  // stack. Deeper than any real file is an error before it sees the text.
  strict_json::check_nesting(strict_json::Reader(file), json_text);

  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&skip_image, nullptr);
  loader.SetFsCallbacks(
      tinygltf::FsCallbacks{&file_exists, &same_path, &read_bounded, &write_nothing, nullptr});
  // As LoadASCIIFromFile would: buffer and image URIs are relative to the file's folder.
  const std::string base_dir = path.parent_path().string();
  tinygltf::Model model;
  std::string err;
  std::string warn;
  bool ok = false;
  try {
    const auto size = static_cast<unsigned int>(bytes.size()); // kMaxDataFileBytes < 4 GiB
    ok = binary ? loader.LoadBinaryFromMemory(&model, &err, &warn,
                                              reinterpret_cast<const unsigned char*>(bytes.data()),
                                              size, base_dir)
                : loader.LoadASCIIFromString(&model, &err, &warn, bytes.data(), size, base_dir);
  } catch (const std::exception& e) {
    // tinygltf reports through `err`, but the JSON library under it may still throw on input
    // it did not expect; that is bad input too.
    throw Error(file, "glTF: " + one_line(e.what()));
  }
  err = trimmed(err);
  warn = trimmed(warn);
  // tinygltf sometimes notes a real problem in `err` and still returns true: treat both alike.
  if (!ok || !err.empty()) {
    check_required_extensions(file, required_extensions_in_json(json_text));
    // tinygltf's reports run over several lines and quote the input: one line, cut.
    std::string message =
        "glTF: " + (err.empty() ? std::string("could not be parsed") : one_line(err));
    if (!warn.empty()) message += " (" + one_line(warn, 256) + ")";
    throw Error(file, message);
  }
  if (!warn.empty()) {
    std::istringstream lines(warn);
    for (std::string line; std::getline(lines, line);)
      if (!line.empty()) log_warning(printable(file, 256) + ": glTF: " + one_line(line));
  }
  if (model.asset.version.empty() || model.asset.version[0] != '2')
    throw Error(file, "asset.version",
                "glTF version '" + printable(model.asset.version) +
                    "' is not supported (expected 2.x)");
  check_required_extensions(file, model.extensionsRequired);
  return model;
}

// ---------------------------------------------------------------------------------------------
// Accessors: every index and byte range is checked against the real buffer sizes here, as
// tinygltf checks few of them.

int component_size(int component_type) {
  switch (component_type) {
  case TINYGLTF_COMPONENT_TYPE_BYTE:
  case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
    return 1;
  case TINYGLTF_COMPONENT_TYPE_SHORT:
  case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
    return 2;
  case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
  case TINYGLTF_COMPONENT_TYPE_FLOAT:
    return 4;
  default:
    return 0; // INT and DOUBLE are not glTF 2.0 accessor component types
  }
}

int component_count(int type) {
  switch (type) {
  case TINYGLTF_TYPE_SCALAR:
    return 1;
  case TINYGLTF_TYPE_VEC2:
    return 2;
  case TINYGLTF_TYPE_VEC3:
    return 3;
  case TINYGLTF_TYPE_VEC4:
    return 4;
  default:
    return 0; // matrices are never read by this loader
  }
}

std::string type_name(int type) {
  switch (type) {
  case TINYGLTF_TYPE_SCALAR:
    return "SCALAR";
  case TINYGLTF_TYPE_VEC2:
    return "VEC2";
  case TINYGLTF_TYPE_VEC3:
    return "VEC3";
  case TINYGLTF_TYPE_VEC4:
    return "VEC4";
  case TINYGLTF_TYPE_MAT2:
    return "MAT2";
  case TINYGLTF_TYPE_MAT3:
    return "MAT3";
  case TINYGLTF_TYPE_MAT4:
    return "MAT4";
  default:
    return "type " + std::to_string(type);
  }
}

/// Which component types an accessor may use for a given purpose.
enum class Components {
  Float,             ///< FLOAT only (animation times, translations, scales)
  FloatOrNormalized, ///< FLOAT or normalized integers (rotations, weights)
  AnyNumber,         ///< any numeric type (vertex attributes, KHR_mesh_quantization)
  UnsignedIndex,     ///< UNSIGNED_BYTE/SHORT/INT, not normalized (indices)
};

/// A validated accessor: `count` elements of `components` values, element i at data + i·stride.
struct AccessorInfo {
  const unsigned char* data = nullptr; ///< null: no bufferView, all zeros (before sparse values)
  std::size_t count = 0;
  std::size_t stride = 0;
  int component_type = 0;
  int components = 0;
  bool normalized = false;
  std::string field; ///< "accessors[i]", for messages
};

/// The bytes of bufferViews[index], after checking that the view lies inside its buffer's data.
std::span<const unsigned char> view_bytes(const Context& ctx, int index, const std::string& user) {
  const auto& views = ctx.model.bufferViews;
  if (index < 0 || static_cast<std::size_t>(index) >= views.size())
    ctx.fail(user, "bufferView index " + std::to_string(index) + " is out of range (the file has " +
                       std::to_string(views.size()) + " buffer views)");
  const tinygltf::BufferView& view = views[static_cast<std::size_t>(index)];
  const std::string field = index_field("bufferViews", static_cast<std::size_t>(index));
  const auto& buffers = ctx.model.buffers;
  if (view.buffer < 0 || static_cast<std::size_t>(view.buffer) >= buffers.size())
    ctx.fail(field, "buffer index " + std::to_string(view.buffer) +
                        " is out of range (the file has " + std::to_string(buffers.size()) +
                        " buffers)");
  const std::vector<unsigned char>& data = buffers[static_cast<std::size_t>(view.buffer)].data;
  if (view.byteLength > data.size() || view.byteOffset > data.size() - view.byteLength)
    ctx.fail(field, "byte range [" + std::to_string(view.byteOffset) + ", " +
                        std::to_string(view.byteOffset + view.byteLength) +
                        ") is out of range of " +
                        index_field("buffers", static_cast<std::size_t>(view.buffer)) + " (" +
                        std::to_string(data.size()) + " bytes)");
  return {data.data() + view.byteOffset, view.byteLength};
}

/// Checks accessors[index] for a use that wants `types` and `allowed` components, and exactly
/// `expected_count` elements when that is not 0 (checked before anything is allocated).
AccessorInfo accessor_info(const Context& ctx, int index, const std::string& user,
                           std::initializer_list<int> types, Components allowed,
                           std::size_t expected_count) {
  const auto& accessors = ctx.model.accessors;
  if (index < 0 || static_cast<std::size_t>(index) >= accessors.size())
    ctx.fail(user, "accessor index " + std::to_string(index) + " is out of range (the file has " +
                       std::to_string(accessors.size()) + " accessors)");
  const tinygltf::Accessor& a = accessors[static_cast<std::size_t>(index)];
  AccessorInfo info;
  info.field = index_field("accessors", static_cast<std::size_t>(index));
  const std::string where = user + " (" + info.field + ")";

  if (std::find(types.begin(), types.end(), a.type) == types.end()) {
    std::string expected;
    for (const int t : types) expected += (expected.empty() ? "" : " or ") + type_name(t);
    ctx.fail(where, "accessor type is " + type_name(a.type) + ", expected " + expected);
  }
  info.components = component_count(a.type);
  const int size = component_size(a.componentType);
  if (size == 0)
    ctx.fail(where, "componentType " + std::to_string(a.componentType) +
                        " is not a glTF 2.0 accessor component type");
  const bool is_float = a.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT;
  if (a.normalized && (is_float || a.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
    ctx.fail(where, "normalized is only allowed for byte and short components");
  switch (allowed) {
  case Components::Float:
    if (!is_float) ctx.fail(where, "componentType must be FLOAT (5126)");
    break;
  case Components::FloatOrNormalized:
    if (!is_float && !a.normalized) ctx.fail(where, "componentType must be FLOAT or normalized");
    break;
  case Components::UnsignedIndex:
    if (a.normalized || (a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
                         a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
                         a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
      ctx.fail(where, "indices must be UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT");
    break;
  case Components::AnyNumber:
    break;
  }
  info.component_type = a.componentType;
  info.normalized = a.normalized;

  if (a.count == 0) ctx.fail(where, "count is 0 (glTF requires at least 1)");
  if (expected_count != 0 && a.count != expected_count)
    ctx.fail(where, "count is " + std::to_string(a.count) + ", expected " +
                        std::to_string(expected_count) + " (one per vertex)");
  const std::uint64_t limit =
      a.bufferView < 0 && expected_count == 0 ? kMaxUnbackedElements : kMaxAccessorElements;
  if (a.count > limit)
    ctx.fail(where, "count " + std::to_string(a.count) + " is absurdly large (limit " +
                        std::to_string(limit) + ")");
  info.count = a.count;
  const auto element_size = static_cast<std::size_t>(size * info.components);

  if (a.bufferView < 0) {
    // glTF: an accessor without a bufferView is all zeros (usually replaced by sparse values).
    info.stride = element_size;
    return info;
  }
  const std::span<const unsigned char> bytes = view_bytes(ctx, a.bufferView, where);
  const tinygltf::BufferView& view = ctx.model.bufferViews[static_cast<std::size_t>(a.bufferView)];
  info.stride = view.byteStride == 0 ? element_size : view.byteStride;
  if (view.byteStride != 0 && (view.byteStride < element_size || view.byteStride > 252 ||
                               view.byteStride % static_cast<std::size_t>(size) != 0))
    ctx.fail(index_field("bufferViews", static_cast<std::size_t>(a.bufferView)),
             "byteStride " + std::to_string(view.byteStride) + " does not fit elements of " +
                 std::to_string(element_size) + " bytes");
  // count ≤ 3·10⁸ and stride ≤ 252, so these products cannot overflow.
  const std::size_t needed = (info.count - 1) * info.stride + element_size;
  if (a.byteOffset > bytes.size() || needed > bytes.size() - a.byteOffset)
    ctx.fail(where,
             std::to_string(info.count) + " elements from byteOffset " +
                 std::to_string(a.byteOffset) + " need " + std::to_string(needed) + " bytes, but " +
                 index_field("bufferViews", static_cast<std::size_t>(a.bufferView)) + " has only " +
                 std::to_string(bytes.size()) + " (accessor out of buffer range)");
  info.data = bytes.data() + a.byteOffset;
  return info;
}

template <typename T>
T load(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

/// One component as float; normalized integers map to [0, 1] or [−1, 1] (glTF 2.0 §3.11).
float read_component(const unsigned char* p, int component_type, bool normalized) {
  switch (component_type) {
  case TINYGLTF_COMPONENT_TYPE_BYTE: {
    const float v = load<std::int8_t>(p);
    return normalized ? std::max(v / 127.0f, -1.0f) : v;
  }
  case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
    const float v = load<std::uint8_t>(p);
    return normalized ? v / 255.0f : v;
  }
  case TINYGLTF_COMPONENT_TYPE_SHORT: {
    const float v = load<std::int16_t>(p);
    return normalized ? std::max(v / 32767.0f, -1.0f) : v;
  }
  case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
    const float v = load<std::uint16_t>(p);
    return normalized ? v / 65535.0f : v;
  }
  case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    return static_cast<float>(load<std::uint32_t>(p));
  default:
    return load<float>(p);
  }
}

std::uint32_t read_index(const unsigned char* p, int component_type) {
  switch (component_type) {
  case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
    return load<std::uint8_t>(p);
  case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
    return load<std::uint16_t>(p);
  default:
    return load<std::uint32_t>(p);
  }
}

/// Sparse substitution (glTF 2.0 §3.6.2.3): calls set(element, value_pointer) for each sparse
/// element after checking its ranges; `element_size` is the tightly packed value size.
template <typename Set>
void apply_sparse(const Context& ctx, int index, const AccessorInfo& info, std::size_t element_size,
                  Set&& set) {
  const tinygltf::Accessor& a = ctx.model.accessors[static_cast<std::size_t>(index)];
  if (!a.sparse.isSparse) return;
  const std::string field = info.field + ".sparse";
  if (a.sparse.count < 1 || static_cast<std::size_t>(a.sparse.count) > info.count)
    ctx.fail(field, "count " + std::to_string(a.sparse.count) + " must be in [1, " +
                        std::to_string(info.count) + "]");
  const auto n = static_cast<std::size_t>(a.sparse.count);
  const int index_type = a.sparse.indices.componentType;
  if (index_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
      index_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
      index_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
    ctx.fail(field + ".indices", "componentType must be an unsigned integer type");
  const auto index_size = static_cast<std::size_t>(component_size(index_type));
  if (a.sparse.indices.byteOffset < 0 || a.sparse.values.byteOffset < 0)
    ctx.fail(field, "byteOffset must not be negative");

  const auto indices = view_bytes(ctx, a.sparse.indices.bufferView, field + ".indices");
  const auto indices_offset = static_cast<std::size_t>(a.sparse.indices.byteOffset);
  if (indices_offset > indices.size() || n * index_size > indices.size() - indices_offset)
    ctx.fail(field + ".indices", "the indices lie outside their buffer view");
  const auto values = view_bytes(ctx, a.sparse.values.bufferView, field + ".values");
  const auto values_offset = static_cast<std::size_t>(a.sparse.values.byteOffset);
  if (values_offset > values.size() || n * element_size > values.size() - values_offset)
    ctx.fail(field + ".values", "the values lie outside their buffer view");

  std::size_t previous = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t element =
        read_index(indices.data() + indices_offset + i * index_size, index_type);
    if (element >= info.count || (i > 0 && element <= previous))
      ctx.fail(field + ".indices",
               "index " + std::to_string(element) + " is out of range or not strictly increasing");
    previous = element;
    set(element, values.data() + values_offset + i * element_size);
  }
}

/// The accessor's elements as floats, `components` per element.
std::vector<float> read_floats(const Context& ctx, int index, const std::string& user,
                               std::initializer_list<int> types, Components allowed,
                               std::size_t expected_count = 0) {
  const AccessorInfo info = accessor_info(ctx, index, user, types, allowed, expected_count);
  const auto k = static_cast<std::size_t>(info.components);
  const auto size = static_cast<std::size_t>(component_size(info.component_type));
  std::vector<float> out(info.count * k, 0.0f);
  if (info.data != nullptr)
    for (std::size_t i = 0; i < info.count; ++i)
      for (std::size_t c = 0; c < k; ++c)
        out[i * k + c] = read_component(info.data + i * info.stride + c * size, info.component_type,
                                        info.normalized);
  apply_sparse(ctx, index, info, k * size, [&](std::size_t element, const unsigned char* p) {
    for (std::size_t c = 0; c < k; ++c)
      out[element * k + c] = read_component(p + c * size, info.component_type, info.normalized);
  });
  return out;
}

std::vector<vec3> read_vec3s(const Context& ctx, int index, const std::string& user,
                             Components allowed, std::size_t expected_count = 0) {
  const std::vector<float> f =
      read_floats(ctx, index, user, {TINYGLTF_TYPE_VEC3}, allowed, expected_count);
  std::vector<vec3> out(f.size() / 3);
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = vec3(f[3 * i], f[3 * i + 1], f[3 * i + 2]);
  return out;
}

std::vector<std::uint32_t> read_indices(const Context& ctx, int index, const std::string& user) {
  const AccessorInfo info =
      accessor_info(ctx, index, user, {TINYGLTF_TYPE_SCALAR}, Components::UnsignedIndex, 0);
  const auto size = static_cast<std::size_t>(component_size(info.component_type));
  std::vector<std::uint32_t> out(info.count, 0);
  if (info.data != nullptr)
    for (std::size_t i = 0; i < info.count; ++i)
      out[i] = read_index(info.data + i * info.stride, info.component_type);
  apply_sparse(ctx, index, info, size, [&](std::size_t element, const unsigned char* p) {
    out[element] = read_index(p, info.component_type);
  });
  return out;
}

// ---------------------------------------------------------------------------------------------
// Meshes

/// Triangle primitives of one mesh merged into one TriangleMesh (one material group).
struct MeshPart {
  int material = -1;
  TriangleMesh geometry; ///< positions with the effective morph weights applied
  /// Only when the mesh has morph targets: positions before any target, and each target's
  /// per-vertex position offsets (zeros where a target has no POSITION).
  std::vector<vec3> base_positions;
  std::vector<std::vector<vec3>> target_offsets;
  /// Likewise for normals, when every primitive of the part has NORMAL (normals computed from
  /// the positions of one set of weights do not morph): empty otherwise.
  std::vector<vec3> base_normals;
  std::vector<std::vector<vec3>> target_normal_offsets;
  bool normals_morph = true; ///< no primitive without NORMAL so far
};

std::string mode_name(int mode) {
  switch (mode) {
  case TINYGLTF_MODE_POINTS:
    return "points";
  case TINYGLTF_MODE_LINE:
    return "lines";
  case TINYGLTF_MODE_LINE_LOOP:
    return "line loop";
  case TINYGLTF_MODE_LINE_STRIP:
    return "line strip";
  default:
    return "mode " + std::to_string(mode);
  }
}

/// Whether the primitive is made of triangles (list, strip or fan); errors for unknown modes.
bool is_triangle_primitive(const Context& ctx, const tinygltf::Primitive& prim,
                           const std::string& field) {
  const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
  if (mode > TINYGLTF_MODE_TRIANGLE_FAN)
    ctx.fail(field, "unknown primitive mode " + std::to_string(mode));
  return mode >= TINYGLTF_MODE_TRIANGLES;
}

/// Triangle list from glTF indices in `mode` (strips and fans converted with the winding the
/// glTF spec gives, §3.7.2.1).
std::vector<uvec3> triangles_from(const Context& ctx, const std::vector<std::uint32_t>& indices,
                                  int mode, const std::string& field) {
  std::vector<uvec3> tris;
  const std::size_t n = indices.size();
  if (mode == TINYGLTF_MODE_TRIANGLES) {
    if (n % 3 != 0)
      ctx.fail(field, std::to_string(n) + " indices (or vertices) is not a multiple of 3");
    tris.reserve(n / 3);
    for (std::size_t i = 0; i + 2 < n; i += 3)
      tris.emplace_back(indices[i], indices[i + 1], indices[i + 2]);
  } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
    for (std::size_t i = 0; i + 2 < n; ++i) {
      if (i % 2 == 0)
        tris.emplace_back(indices[i], indices[i + 1], indices[i + 2]);
      else
        tris.emplace_back(indices[i + 1], indices[i], indices[i + 2]);
    }
  } else { // fan
    for (std::size_t i = 1; i + 1 < n; ++i)
      tris.emplace_back(indices[0], indices[i], indices[i + 1]);
  }
  return tris;
}

std::vector<vec3> morphed(const std::vector<vec3>& base,
                          const std::vector<std::vector<vec3>>& offsets,
                          std::span<const float> weights) {
  std::vector<vec3> out = base;
  for (std::size_t t = 0; t < offsets.size() && t < weights.size(); ++t)
    if (weights[t] != 0.0f)
      for (std::size_t v = 0; v < out.size(); ++v) out[v] += weights[t] * offsets[t][v];
  return out;
}

/// Morphed normals (glTF §3.7.2.2: NORMAL targets are displacements), normalised when
/// `normalise`; left as they are for keys, which sample_normals blends and then normalises, so a
/// sampled normal is the normalised morph of the interpolated weights. A normal the weights
/// cancel out is no direction: an error naming `field`.
std::vector<vec3> morphed_normals(const Context& ctx, const std::vector<vec3>& base,
                                  const std::vector<std::vector<vec3>>& offsets,
                                  std::span<const float> weights, const std::string& field,
                                  bool normalise) {
  std::vector<vec3> out = morphed(base, offsets, weights);
  for (std::size_t v = 0; v < out.size(); ++v) {
    const float len = glm::length(out[v]);
    if (!(len > 1e-6f))
      ctx.fail(field,
               "the morph weights give vertex " + std::to_string(v) + " a zero-length normal");
    if (normalise) out[v] /= len;
  }
  return out;
}

/// Reads one triangle primitive and appends it to `part`. `weights` are the morph weights the
/// geometry is built with.
void append_primitive(const Context& ctx, const tinygltf::Primitive& prim, const std::string& field,
                      std::span<const float> weights, MeshPart& part, bool& all_have_uvs) {
  const auto position = prim.attributes.find("POSITION");
  if (position == prim.attributes.end()) ctx.fail(field, "primitive has no POSITION attribute");
  if (prim.extensions.count("KHR_draco_mesh_compression") != 0) {
    const auto& accessors = ctx.model.accessors;
    if (position->second < 0 || static_cast<std::size_t>(position->second) >= accessors.size() ||
        accessors[static_cast<std::size_t>(position->second)].bufferView < 0)
      ctx.fail(field, "KHR_draco_mesh_compression without uncompressed fallback data is not "
                      "supported (Draco cannot be decoded by this build)");
  }
  const std::string attr = field + ".attributes.";
  TriangleMesh mesh;
  std::vector<vec3> base =
      read_vec3s(ctx, position->second, attr + "POSITION", Components::AnyNumber);
  const std::size_t n = base.size();

  if (const auto it = prim.attributes.find("NORMAL"); it != prim.attributes.end()) {
    mesh.normals = read_vec3s(ctx, it->second, attr + "NORMAL", Components::AnyNumber, n);
  }
  if (const auto it = prim.attributes.find("TEXCOORD_0"); it != prim.attributes.end()) {
    const std::vector<float> f = read_floats(ctx, it->second, attr + "TEXCOORD_0",
                                             {TINYGLTF_TYPE_VEC2}, Components::AnyNumber, n);
    mesh.uvs.resize(n);
    for (std::size_t i = 0; i < n; ++i) mesh.uvs[i] = vec2(f[2 * i], f[2 * i + 1]);
  } else {
    all_have_uvs = false;
  }

  // Morph targets (build_mesh_parts checked that every primitive has the same number).
  const auto target_offsets = [&](const char* attribute) {
    std::vector<std::vector<vec3>> offsets(prim.targets.size());
    for (std::size_t t = 0; t < prim.targets.size(); ++t) {
      const std::string target_field = field + index_field(".targets", t) + "." + attribute;
      if (const auto it = prim.targets[t].find(attribute); it != prim.targets[t].end()) {
        offsets[t] = read_vec3s(ctx, it->second, target_field, Components::AnyNumber, n);
        for (const vec3& d : offsets[t])
          if (!is_finite(d))
            ctx.fail(target_field, "morph target offset is not finite (NaN or Inf)");
      } else {
        offsets[t].assign(n, vec3(0.0f));
      }
    }
    return offsets;
  };
  const std::vector<std::vector<vec3>> offsets = target_offsets("POSITION");
  mesh.positions = morphed(base, offsets, weights);
  const bool normals_morph = !offsets.empty() && !mesh.normals.empty();
  std::vector<vec3> base_normals;
  std::vector<std::vector<vec3>> normal_offsets;
  if (normals_morph) {
    base_normals = mesh.normals;
    normal_offsets = target_offsets("NORMAL");
    mesh.normals = morphed_normals(ctx, base_normals, normal_offsets, weights, field, true);
  }

  std::vector<std::uint32_t> indices;
  if (prim.indices >= 0) {
    indices = read_indices(ctx, prim.indices, field + ".indices");
    for (std::size_t i = 0; i < indices.size(); ++i)
      if (indices[i] >= n)
        ctx.fail(field + ".indices",
                 "index " + std::to_string(indices[i]) + " (at position " + std::to_string(i) +
                     ") is out of range: the primitive has " + std::to_string(n) + " vertices");
  } else {
    indices.resize(n);
    for (std::size_t i = 0; i < n; ++i) indices[i] = static_cast<std::uint32_t>(i);
  }
  const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
  mesh.triangles = triangles_from(ctx, indices, mode, field);
  if (mesh.normals.empty()) mesh.compute_vertex_normals();
  try {
    mesh.validate(field);
  } catch (const Error& e) {
    ctx.fail(field, e.message());
  }

  // Append with the vertex offset; the merged mesh must still fit 32-bit indices.
  TriangleMesh& out = part.geometry;
  const std::uint64_t offset = out.positions.size();
  if (offset + n > std::numeric_limits<std::uint32_t>::max() ||
      out.triangles.size() + mesh.triangles.size() > kMaxTriangles)
    ctx.fail(field, "the mesh is too large (more than " + std::to_string(kMaxTriangles) +
                        " triangles or 2^32 vertices)");
  const auto shift = static_cast<std::uint32_t>(offset);
  for (const uvec3& t : mesh.triangles) out.triangles.push_back(t + uvec3(shift));
  out.positions.insert(out.positions.end(), mesh.positions.begin(), mesh.positions.end());
  out.normals.insert(out.normals.end(), mesh.normals.begin(), mesh.normals.end());
  out.uvs.insert(out.uvs.end(), mesh.uvs.begin(), mesh.uvs.end());
  if (!offsets.empty()) {
    part.base_positions.insert(part.base_positions.end(), base.begin(), base.end());
    part.target_offsets.resize(offsets.size());
    for (std::size_t t = 0; t < offsets.size(); ++t)
      part.target_offsets[t].insert(part.target_offsets[t].end(), offsets[t].begin(),
                                    offsets[t].end());
    part.normals_morph = part.normals_morph && normals_morph;
    if (part.normals_morph) {
      part.base_normals.insert(part.base_normals.end(), base_normals.begin(), base_normals.end());
      part.target_normal_offsets.resize(normal_offsets.size());
      for (std::size_t t = 0; t < normal_offsets.size(); ++t)
        part.target_normal_offsets[t].insert(part.target_normal_offsets[t].end(),
                                             normal_offsets[t].begin(), normal_offsets[t].end());
    } else {
      part.base_normals.clear();
      part.target_normal_offsets.clear();
    }
  }
}

/// Default morph weights of a mesh (mesh.weights, else zeros), checked against its targets.
std::vector<float> mesh_default_weights(const Context& ctx, int mesh_index) {
  const tinygltf::Mesh& mesh = ctx.model.meshes[static_cast<std::size_t>(mesh_index)];
  const std::size_t targets = mesh.primitives.empty() ? 0 : mesh.primitives[0].targets.size();
  const std::string field =
      index_field("meshes", static_cast<std::size_t>(mesh_index)) + ".weights";
  if (!mesh.weights.empty() && mesh.weights.size() != targets)
    ctx.fail(field, std::to_string(mesh.weights.size()) + " weights for " +
                        std::to_string(targets) + " morph targets");
  std::vector<float> weights(targets, 0.0f);
  for (std::size_t i = 0; i < mesh.weights.size(); ++i)
    weights[i] = to_float(ctx, mesh.weights[i], field);
  return weights;
}

/// The triangle primitives of meshes[mesh_index], one part per material (first-use order) when
/// `split_by_material`, else one part holding all of them. Non-triangle primitives are skipped
/// with a warning; the result is empty when no triangle primitive is left.
std::vector<MeshPart> build_mesh_parts(const Context& ctx, int mesh_index, bool split_by_material,
                                       std::span<const float> weights) {
  const auto& meshes = ctx.model.meshes;
  if (mesh_index < 0 || static_cast<std::size_t>(mesh_index) >= meshes.size())
    ctx.fail("meshes", "mesh index " + std::to_string(mesh_index) +
                           " is out of range (the file has " + std::to_string(meshes.size()) +
                           " meshes)");
  const std::string mesh_field = index_field("meshes", static_cast<std::size_t>(mesh_index));
  const tinygltf::Mesh& mesh = meshes[static_cast<std::size_t>(mesh_index)];
  if (mesh.primitives.empty()) ctx.fail(mesh_field + ".primitives", "mesh has no primitives");
  // Morph weights apply to every primitive alike, so all have the same targets (glTF §3.7.2.2).
  for (std::size_t p = 1; p < mesh.primitives.size(); ++p)
    if (mesh.primitives[p].targets.size() != mesh.primitives[0].targets.size())
      ctx.fail(mesh_field + index_field(".primitives", p) + ".targets",
               "primitives of one mesh must have the same number of morph targets");

  std::vector<MeshPart> parts;
  std::vector<bool> all_have_uvs;
  std::string skipped;
  for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
    const tinygltf::Primitive& prim = mesh.primitives[p];
    const std::string field = mesh_field + index_field(".primitives", p);
    if (!is_triangle_primitive(ctx, prim, field)) {
      skipped += (skipped.empty() ? "" : ", ") + mode_name(prim.mode);
      continue;
    }
    const int material = split_by_material ? prim.material : -1;
    auto it = std::find_if(parts.begin(), parts.end(),
                           [&](const MeshPart& part) { return part.material == material; });
    if (it == parts.end()) {
      parts.emplace_back().material = material;
      all_have_uvs.push_back(true);
      it = parts.end() - 1;
    }
    bool has_uvs = true;
    append_primitive(ctx, prim, field, weights, *it, has_uvs);
    if (!has_uvs) all_have_uvs[static_cast<std::size_t>(it - parts.begin())] = false;
  }
  if (!skipped.empty())
    ctx.warn(mesh_field + ": skipped primitives that are not triangles (" + skipped + ")");
  // Texture coordinates only survive when every merged primitive has them.
  for (std::size_t i = 0; i < parts.size(); ++i)
    if (!all_have_uvs[i]) parts[i].geometry.uvs.clear();
  return parts;
}

// ---------------------------------------------------------------------------------------------
// Materials, cameras, lights

/// A factor in [0, 1] (a hair outside is clamped: exporters round); anything else is an error.
float unit_factor(const Context& ctx, double value, const std::string& field) {
  if (!std::isfinite(value) || value < -1e-4 || value > 1.0 + 1e-4)
    ctx.fail(field, "value " + std::to_string(value) + " must be in [0, 1]");
  return std::clamp(static_cast<float>(value), 0.0f, 1.0f);
}

/// extensions[extension][key] as a number, if present.
std::optional<double> extension_number(const Context& ctx, const tinygltf::ExtensionMap& extensions,
                                       const std::string& extension, const std::string& key,
                                       const std::string& field) {
  const auto it = extensions.find(extension);
  if (it == extensions.end()) return std::nullopt;
  const std::string where = field + ".extensions." + extension;
  if (!it->second.IsObject()) ctx.fail(where, "extension must be a JSON object");
  if (!it->second.Has(key)) return std::nullopt;
  const tinygltf::Value& v = it->second.Get(key);
  if (!v.IsNumber()) ctx.fail(where + "." + key, "must be a number");
  return v.GetNumberAsDouble();
}

/// A float bound as messages print it: its shortest spelling ("1e+20").
std::string format_bound(float v) {
  char buf[32];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

Material map_material(const Context& ctx, int index) {
  // Primitives without a material use the glTF default material (white, metallic 1, rough 1),
  // which is what a default-constructed tinygltf::Material holds.
  const tinygltf::Material default_material;
  const auto& materials = ctx.model.materials;
  if (index >= 0 && static_cast<std::size_t>(index) >= materials.size())
    ctx.fail("materials", "material index " + std::to_string(index) +
                              " is out of range (the file has " + std::to_string(materials.size()) +
                              " materials)");
  const tinygltf::Material& m =
      index < 0 ? default_material : materials[static_cast<std::size_t>(index)];
  const std::string field =
      index < 0 ? "default material" : index_field("materials", static_cast<std::size_t>(index));
  const auto& pbr = m.pbrMetallicRoughness;

  Material out;
  if (pbr.baseColorFactor.size() != 4)
    ctx.fail(field + ".pbrMetallicRoughness.baseColorFactor", "must have 4 components");
  for (int c = 0; c < 3; ++c)
    out.base_color[c] = unit_factor(ctx, pbr.baseColorFactor[static_cast<std::size_t>(c)],
                                    field + ".pbrMetallicRoughness.baseColorFactor");
  const float metallic =
      unit_factor(ctx, pbr.metallicFactor, field + ".pbrMetallicRoughness.metallicFactor");
  out.roughness =
      unit_factor(ctx, pbr.roughnessFactor, field + ".pbrMetallicRoughness.roughnessFactor");

  if (!m.emissiveFactor.empty()) {
    if (m.emissiveFactor.size() != 3) ctx.fail(field + ".emissiveFactor", "must have 3 components");
    for (int c = 0; c < 3; ++c)
      out.emission[c] = unit_factor(ctx, m.emissiveFactor[static_cast<std::size_t>(c)],
                                    field + ".emissiveFactor");
  }
  if (const auto strength = extension_number(ctx, m.extensions, "KHR_materials_emissive_strength",
                                             "emissiveStrength", field)) {
    const std::string where = field + ".extensions.KHR_materials_emissive_strength";
    const float value = to_float(ctx, *strength, where);
    if (value < 0.0f) ctx.fail(where, "emissiveStrength must be ≥ 0");
    out.emission *= value;
    const float largest = std::max(out.emission.x, std::max(out.emission.y, out.emission.z));
    if (!(largest <= kMaxEmission))
      ctx.fail(where, "emissiveFactor * emissiveStrength must be <= " + format_bound(kMaxEmission) +
                          ", got " + strict_json::format_double(largest));
  }

  // See the mapping notes at the top of the file.
  out.reflectivity = metallic * (1.0f - out.roughness);
  if (m.extensions.count("KHR_materials_transmission") != 0) {
    const double factor = extension_number(ctx, m.extensions, "KHR_materials_transmission",
                                           "transmissionFactor", field)
                              .value_or(0.0);
    out.transmission =
        unit_factor(ctx, factor,
                    field + ".extensions.KHR_materials_transmission.transmissionFactor") *
        (1.0f - metallic);
  }
  if (const auto ior = extension_number(ctx, m.extensions, "KHR_materials_ior", "ior", field)) {
    out.ior = to_float(ctx, *ior, field + ".extensions.KHR_materials_ior.ior");
    if (out.ior < 1.0f) ctx.fail(field + ".extensions.KHR_materials_ior.ior", "ior must be ≥ 1");
  }
  return out;
}

/// The node's camera in world space; nullopt (with a warning) for orthographic cameras.
std::optional<Camera> map_camera(const Context& ctx, int index, const dmat4& world_from_node,
                                 const RenderSettings& settings, const std::string& node_field) {
  const auto& cameras = ctx.model.cameras;
  if (static_cast<std::size_t>(index) >= cameras.size())
    ctx.fail(node_field + ".camera", "camera index " + std::to_string(index) +
                                         " is out of range (the file has " +
                                         std::to_string(cameras.size()) + " cameras)");
  const tinygltf::Camera& c = cameras[static_cast<std::size_t>(index)];
  const std::string field = index_field("cameras", static_cast<std::size_t>(index));
  if (c.type == "orthographic") {
    ctx.warn(field + ": orthographic cameras are not supported; camera skipped");
    return std::nullopt;
  }
  if (c.type != "perspective") ctx.fail(field + ".type", "unknown camera type '" + c.type + "'");
  const double yfov = c.perspective.yfov;
  if (!std::isfinite(yfov) || yfov <= 0.0 || yfov >= glm::pi<double>())
    ctx.fail(field + ".perspective.yfov", "must be in (0, π) radians");
  const double aspect = c.perspective.aspectRatio;
  if (!std::isfinite(aspect) || aspect < 0.0)
    ctx.fail(field + ".perspective.aspectRatio", "must be > 0");

  Camera camera;
  camera.position = dvec3(world_from_node[3]);
  if (!in_range(camera.position))
    ctx.fail(node_field,
             std::string("the camera's world position is outside ") + kCoordinateRangeText);
  const mat3 basis{dmat3(world_from_node)};
  const vec3 forward = basis * vec3(0.0f, 0.0f, -1.0f);
  const vec3 up = basis * vec3(0.0f, 1.0f, 0.0f);
  if (!is_finite(forward) || glm::length(forward) <= 0.0f || glm::length(up) <= 0.0f)
    ctx.fail(node_field, "the camera's world transform is degenerate");
  camera.look_at = camera.position + dvec3(glm::normalize(forward));
  camera.up = glm::normalize(up);
  camera.vertical_fov = static_cast<float>(yfov);
  camera.aspect = aspect > 0.0 ? to_float(ctx, aspect, field + ".perspective.aspectRatio")
                               : static_cast<float>(settings.width) /
                                     static_cast<float>(std::max(1u, settings.height));
  return camera;
}

/// KHR_lights_punctual light referenced by a node, if any.
std::optional<Light> map_light(const Context& ctx, const tinygltf::Node& node,
                               const std::string& node_field) {
  const auto it = node.extensions.find("KHR_lights_punctual");
  if (it == node.extensions.end()) return std::nullopt;
  const std::string field = node_field + ".extensions.KHR_lights_punctual";
  if (!it->second.IsObject() || !it->second.Has("light") || !it->second.Get("light").IsInt())
    ctx.fail(field, "must be an object with an integer 'light'");
  const int index = it->second.Get("light").GetNumberAsInt();
  const auto& lights = ctx.model.lights;
  if (index < 0 || static_cast<std::size_t>(index) >= lights.size())
    ctx.fail(field + ".light", "light index " + std::to_string(index) +
                                   " is out of range (the file has " +
                                   std::to_string(lights.size()) + " lights)");
  const tinygltf::Light& l = lights[static_cast<std::size_t>(index)];
  const std::string lfield = "extensions.KHR_lights_punctual.lights[" + std::to_string(index) + "]";

  Light light;
  if (l.type == "point")
    light.type = Light::Type::Point;
  else if (l.type == "directional")
    light.type = Light::Type::Directional;
  else if (l.type == "spot")
    light.type = Light::Type::Spot;
  else
    ctx.fail(lfield + ".type", "unknown light type '" + l.type + "'");
  if (!l.color.empty()) {
    if (l.color.size() != 3) ctx.fail(lfield + ".color", "must have 3 components");
    for (int c = 0; c < 3; ++c) {
      light.color[c] = to_float(ctx, l.color[static_cast<std::size_t>(c)], lfield + ".color");
      if (light.color[c] < 0.0f) ctx.fail(lfield + ".color", "must be ≥ 0");
    }
  }
  light.intensity = to_float(ctx, l.intensity, lfield + ".intensity");
  if (light.intensity < 0.0f) ctx.fail(lfield + ".intensity", "must be ≥ 0");
  if (const double brightest =
          double(std::max(light.color.x, std::max(light.color.y, light.color.z))) * light.intensity;
      !(brightest <= kMaxLightIntensity))
    ctx.fail(lfield + ".intensity",
             "color * intensity must be <= " + format_bound(kMaxLightIntensity) + ", got " +
                 strict_json::format_double(brightest));
  light.range = to_float(ctx, l.range, lfield + ".range"); // 0: not given, unlimited
  if (light.range < 0.0f) ctx.fail(lfield + ".range", "must be > 0");
  if (light.type == Light::Type::Spot) {
    const double inner = l.spot.innerConeAngle;
    const double outer = l.spot.outerConeAngle;
    if (!std::isfinite(inner) || !std::isfinite(outer) || inner < 0.0 || outer <= inner ||
        outer > glm::half_pi<double>() + 1e-6)
      ctx.fail(lfield + ".spot", "cone angles must satisfy 0 ≤ inner < outer ≤ π/2");
    light.inner_cone = static_cast<float>(inner);
    light.outer_cone = static_cast<float>(outer);
  }
  return light;
}

// ---------------------------------------------------------------------------------------------
// Node transforms

/// TRS from a node's matrix: translation = column 3, scale = column lengths (x negated for a
/// mirroring matrix), rotation from the normalized columns. Errors for non-finite, non-affine,
/// singular or sheared matrices, which a Transform cannot hold.
Transform decompose(const Context& ctx, const std::vector<double>& values,
                    const std::string& field) {
  if (values.size() != 16) ctx.fail(field, "matrix must have 16 numbers");
  mat4 m;
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) {
      // Column-major, as glTF stores it.
      m[c][r] = to_float(ctx, values[static_cast<std::size_t>(4 * c + r)], field);
    }
  if (std::abs(m[0][3]) > 1e-6f || std::abs(m[1][3]) > 1e-6f || std::abs(m[2][3]) > 1e-6f ||
      std::abs(m[3][3] - 1.0f) > 1e-6f)
    ctx.fail(field, "matrix is not affine (its last row must be 0 0 0 1)");
  Transform t;
  // The translation in double, as the file gives it (the float copy above served the checks).
  for (int r = 0; r < 3; ++r)
    t.translation[r] = to_coordinate(ctx, values[static_cast<std::size_t>(12 + r)], field);
  vec3 scale(glm::length(vec3(m[0])), glm::length(vec3(m[1])), glm::length(vec3(m[2])));
  const float det = glm::determinant(mat3(m));
  const float max_scale = std::max({scale.x, scale.y, scale.z});
  if (!(max_scale > 0.0f) || std::abs(det) <= 1e-12f * max_scale * max_scale * max_scale)
    ctx.fail(field, "matrix is singular (zero scale)");
  if (det < 0.0f) scale.x = -scale.x;
  const mat3 rotation = mat3(vec3(m[0]) / scale.x, vec3(m[1]) / scale.y, vec3(m[2]) / scale.z);
  const mat3 should_be_identity = glm::transpose(rotation) * rotation;
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r)
      if (std::abs(should_be_identity[c][r] - (c == r ? 1.0f : 0.0f)) > 1e-3f)
        ctx.fail(field, "matrix has shear, which a translation-rotation-scale cannot represent");
  t.rotation = glm::normalize(glm::quat_cast(rotation));
  t.scale = scale;
  return t;
}

Transform node_transform(const Context& ctx, const tinygltf::Node& node, const std::string& field) {
  if (!node.matrix.empty()) {
    if (!node.translation.empty() || !node.rotation.empty() || !node.scale.empty())
      ctx.warn(field + ": has both matrix and translation/rotation/scale; using the matrix");
    return decompose(ctx, node.matrix, field + ".matrix");
  }
  Transform t;
  const auto vector3 = [&](const std::vector<double>& v, const char* name, auto& out) {
    if (v.empty()) return;
    if (v.size() != 3) ctx.fail(field + "." + name, "must have 3 numbers");
    for (int i = 0; i < 3; ++i) {
      const double x = v[static_cast<std::size_t>(i)];
      if constexpr (std::is_same_v<std::decay_t<decltype(out)>, dvec3>)
        out[i] = to_coordinate(ctx, x, field + "." + name);
      else
        out[i] = to_float(ctx, x, field + "." + name);
    }
  };
  vector3(node.translation, "translation", t.translation);
  vector3(node.scale, "scale", t.scale);
  if (t.scale.x == 0.0f || t.scale.y == 0.0f || t.scale.z == 0.0f)
    ctx.fail(field + ".scale", "zero scale makes the transform singular");
  if (!node.rotation.empty()) {
    if (node.rotation.size() != 4) ctx.fail(field + ".rotation", "must have 4 numbers");
    const auto& r = node.rotation;
    const std::string where = field + ".rotation";
    const quat q(to_float(ctx, r[3], where), to_float(ctx, r[0], where), to_float(ctx, r[1], where),
                 to_float(ctx, r[2], where)); // glTF stores x, y, z, w
    if (!is_finite(q) || glm::length(q) < 1e-6f)
      ctx.fail(field + ".rotation", "must be a finite, non-zero quaternion");
    t.rotation = glm::normalize(q);
  }
  return t;
}

// ---------------------------------------------------------------------------------------------
// Animations

/// Morph weight keys of one node (`targets` weights per key), turned into vertex keys per mesh
/// entity once the node's geometry is known.
struct WeightTrack {
  std::vector<float> times;
  std::vector<std::vector<float>> weights;
  Interpolation interpolation = Interpolation::Linear;
  std::string field; ///< the channel, for messages
};

struct NodeAnimation {
  Animation trs; ///< translation/rotation/scale tracks (no vertices)
  std::optional<WeightTrack> weights;
};

std::size_t morph_target_count(const Context& ctx, const tinygltf::Node& node) {
  if (node.mesh < 0 || static_cast<std::size_t>(node.mesh) >= ctx.model.meshes.size()) return 0;
  const auto& prims = ctx.model.meshes[static_cast<std::size_t>(node.mesh)].primitives;
  return prims.empty() ? 0 : prims[0].targets.size();
}

/// Reads every animation channel into per-node tracks. TRS channels are validated on their own
/// so that errors name them ("animations[0].channels[2]"); weight channels are validated with
/// the vertex keys they become.
std::map<int, NodeAnimation> read_animations(const Context& ctx) {
  std::map<int, NodeAnimation> out;
  // (node, path) pairs already set, by which animation: the first animation to set one keeps it.
  std::map<std::pair<int, std::string>, std::size_t> claimed;
  const auto& nodes = ctx.model.nodes;
  for (std::size_t a = 0; a < ctx.model.animations.size(); ++a) {
    const tinygltf::Animation& anim = ctx.model.animations[a];
    for (std::size_t c = 0; c < anim.channels.size(); ++c) {
      const tinygltf::AnimationChannel& channel = anim.channels[c];
      const std::string field = index_field("animations", a) + index_field(".channels", c);
      if (channel.target_node < 0) continue; // glTF: a channel without a node is ignored
      if (static_cast<std::size_t>(channel.target_node) >= nodes.size())
        ctx.fail(field + ".target.node", "node index " + std::to_string(channel.target_node) +
                                             " is out of range (the file has " +
                                             std::to_string(nodes.size()) + " nodes)");
      const std::string& path = channel.target_path;
      if (path != "translation" && path != "rotation" && path != "scale" && path != "weights") {
        ctx.warn(field + ": animation path '" + printable(path) +
                 "' is not supported; channel skipped");
        continue;
      }
      if (const auto [it, inserted] = claimed.emplace(std::pair(channel.target_node, path), a);
          !inserted) {
        if (it->second != a)
          ctx.warn(field + ": " + path + " of node " + std::to_string(channel.target_node) +
                   " is already animated by animations[" + std::to_string(it->second) +
                   "]; channel skipped");
        else
          ctx.fail(field, "a second channel for " + path + " of node " +
                              std::to_string(channel.target_node) + " in the same animation");
        continue;
      }
      if (channel.sampler < 0 || static_cast<std::size_t>(channel.sampler) >= anim.samplers.size())
        ctx.fail(field + ".sampler",
                 "sampler index " + std::to_string(channel.sampler) + " is out of range");
      const std::string sampler_field =
          index_field("animations", a) +
          index_field(".samplers", static_cast<std::size_t>(channel.sampler));
      const tinygltf::AnimationSampler& sampler =
          anim.samplers[static_cast<std::size_t>(channel.sampler)];
      Interpolation interpolation = Interpolation::Linear;
      bool cubic = false;
      if (sampler.interpolation == "STEP")
        interpolation = Interpolation::Step;
      else if (sampler.interpolation == "CUBICSPLINE")
        cubic = true;
      else if (sampler.interpolation != "LINEAR" && !sampler.interpolation.empty())
        ctx.fail(sampler_field + ".interpolation",
                 "unknown interpolation '" + printable(sampler.interpolation) + "'");

      const std::vector<float> times = read_floats(ctx, sampler.input, sampler_field + ".input",
                                                   {TINYGLTF_TYPE_SCALAR}, Components::Float);
      const std::size_t keys = times.size();
      // CUBICSPLINE stores (in-tangent, value, out-tangent) per key: keep the values and sample
      // them linearly (Keyframes has no cubic mode; the tangents are dropped).
      const std::size_t per_key = cubic ? 3 : 1;
      const std::size_t value_index = cubic ? 1 : 0;
      const std::string output_field = sampler_field + ".output";
      const auto count_error = [&](std::size_t values, const std::string& what) {
        ctx.fail(output_field, std::to_string(values) + " " + what + " for " +
                                   std::to_string(keys) + " key times" +
                                   (cubic ? " (CUBICSPLINE needs 3 per key)" : ""));
      };

      NodeAnimation& node_anim = out[channel.target_node];
      if (path == "weights") {
        const std::size_t targets =
            morph_target_count(ctx, nodes[static_cast<std::size_t>(channel.target_node)]);
        if (targets == 0)
          ctx.fail(field, "animates the morph weights of node " +
                              std::to_string(channel.target_node) + ", which has no morph targets");
        const std::vector<float> f =
            read_floats(ctx, sampler.output, output_field, {TINYGLTF_TYPE_SCALAR},
                        Components::FloatOrNormalized);
        if (f.size() != keys * per_key * targets)
          count_error(f.size(), "weights (" + std::to_string(targets) + " morph targets)");
        WeightTrack w;
        w.times = times;
        w.interpolation = interpolation;
        w.field = field;
        for (std::size_t i = 0; i < keys; ++i) {
          const auto first = static_cast<std::ptrdiff_t>((i * per_key + value_index) * targets);
          w.weights.emplace_back(f.begin() + first,
                                 f.begin() + first + static_cast<std::ptrdiff_t>(targets));
        }
        node_anim.weights = std::move(w);
        continue;
      }

      Animation track; // this channel alone, validated so that errors name it
      if (path == "rotation") {
        const std::vector<float> f = read_floats(
            ctx, sampler.output, output_field, {TINYGLTF_TYPE_VEC4}, Components::FloatOrNormalized);
        if (f.size() / 4 != keys * per_key) count_error(f.size() / 4, "rotations");
        track.rotation.times = times;
        track.rotation.interpolation = interpolation;
        for (std::size_t i = 0; i < keys; ++i) {
          const float* q = &f[4 * (i * per_key + value_index)];
          track.rotation.values.emplace_back(q[3], q[0], q[1], q[2]); // glTF: x, y, z, w
        }
      } else {
        const std::vector<vec3> values =
            read_vec3s(ctx, sampler.output, output_field, Components::Float);
        if (values.size() != keys * per_key) count_error(values.size(), "values");
        const auto fill = [&](auto& k) {
          k.times = times;
          k.interpolation = interpolation;
          for (std::size_t i = 0; i < keys; ++i)
            k.values.emplace_back(values[i * per_key + value_index]);
        };
        if (path == "translation")
          fill(track.translation);
        else
          fill(track.scale);
      }
      validate_animation(track, 0, ctx.file, field);
      if (path == "translation")
        node_anim.trs.translation = std::move(track.translation);
      else if (path == "rotation") {
        node_anim.trs.rotation = std::move(track.rotation);
        for (quat& q : node_anim.trs.rotation.values) q = glm::normalize(q);
      } else
        node_anim.trs.scale = std::move(track.scale);
    }
  }
  return out;
}

/// Vertex keys for one mesh part: base + Σ weight_i · target_i at every key time.
Keyframes<std::vector<vec3>> vertex_keys(const Context& ctx, const WeightTrack& w,
                                         const MeshPart& part) {
  const std::uint64_t total = std::uint64_t(w.times.size()) * part.base_positions.size();
  if (total > kMaxMorphKeyPositions)
    ctx.fail(w.field, "morph animation would need " + std::to_string(total) +
                          " key positions (limit " + std::to_string(kMaxMorphKeyPositions) + ")");
  Keyframes<std::vector<vec3>> keys;
  keys.times = w.times;
  keys.interpolation = w.interpolation;
  keys.values.reserve(w.times.size());
  for (const auto& weights : w.weights)
    keys.values.push_back(morphed(part.base_positions, part.target_offsets, weights));
  return keys;
}

/// Normal keys for one mesh part whose normals morph (MeshPart::base_normals), at the same times;
/// an empty track for one whose normals do not.
Keyframes<std::vector<vec3>> normal_keys(const Context& ctx, const WeightTrack& w,
                                         const MeshPart& part) {
  Keyframes<std::vector<vec3>> keys;
  if (part.base_normals.empty()) return keys;
  keys.times = w.times;
  keys.interpolation = w.interpolation;
  keys.values.reserve(w.times.size());
  for (const auto& weights : w.weights)
    keys.values.push_back(morphed_normals(ctx, part.base_normals, part.target_normal_offsets,
                                          weights, w.field, false));
  return keys;
}

// ---------------------------------------------------------------------------------------------
// Scene

/// Geometry built once per (mesh, morph weights) and shared by every node using it.
struct CachedMesh {
  std::vector<MeshPart> parts;
  std::vector<std::shared_ptr<const TriangleMesh>> geometry; ///< one per part
};

/// The roots of the scene to load (scene, else scenes[0], else every node nobody points at).
std::vector<int> scene_roots(const Context& ctx, std::string& roots_field) {
  const tinygltf::Model& model = ctx.model;
  if (model.nodes.empty()) ctx.fail("nodes", "the file has no nodes");
  if (model.nodes.size() > kMaxEntities)
    ctx.fail("nodes", "more than " + std::to_string(kMaxEntities) + " nodes");
  if (!model.scenes.empty()) {
    int s = model.defaultScene;
    if (s >= 0 && static_cast<std::size_t>(s) >= model.scenes.size())
      ctx.fail("scene", "scene index " + std::to_string(s) + " is out of range (the file has " +
                            std::to_string(model.scenes.size()) + " scenes)");
    if (s < 0) s = 0;
    const std::string scene_field = index_field("scenes", static_cast<std::size_t>(s));
    roots_field = scene_field + ".nodes";
    const std::vector<int>& roots = model.scenes[static_cast<std::size_t>(s)].nodes;
    if (roots.empty()) ctx.fail(scene_field, "the scene has no nodes");
    return roots;
  }
  roots_field = "nodes";
  std::vector<bool> is_child(model.nodes.size(), false);
  for (const tinygltf::Node& node : model.nodes)
    for (const int child : node.children)
      if (child >= 0 && static_cast<std::size_t>(child) < model.nodes.size())
        is_child[static_cast<std::size_t>(child)] = true;
  std::vector<int> roots;
  for (std::size_t i = 0; i < model.nodes.size(); ++i)
    if (!is_child[i]) roots.push_back(static_cast<int>(i));
  if (roots.empty())
    ctx.fail("nodes", "no root nodes: every node is another node's child (the node graph has a "
                      "cycle)");
  return roots;
}

std::string material_label(const Context& ctx, int material) {
  if (material < 0) return "default material";
  const std::string& name = ctx.model.materials[static_cast<std::size_t>(material)].name;
  return name.empty() ? index_field("materials", static_cast<std::size_t>(material)) : name;
}

/// The morph weights a node's geometry is built with: node.weights, else the mesh's defaults.
std::vector<float> node_weights(const Context& ctx, const tinygltf::Node& node,
                                const std::string& field) {
  std::vector<float> weights = mesh_default_weights(ctx, node.mesh);
  if (node.weights.empty()) return weights;
  if (node.weights.size() != weights.size())
    ctx.fail(field + ".weights", std::to_string(node.weights.size()) + " weights for " +
                                     std::to_string(weights.size()) + " morph targets");
  for (std::size_t i = 0; i < weights.size(); ++i)
    weights[i] = to_float(ctx, node.weights[i], field + ".weights");
  return weights;
}

Scene build_scene(const Context& ctx, const fs::path& path) {
  const tinygltf::Model& model = ctx.model;
  Scene scene;
  scene.source = path;
  ecs::Registry& reg = scene.registry;

  std::string roots_field;
  const std::vector<int> roots = scene_roots(ctx, roots_field);
  const std::map<int, NodeAnimation> animations = read_animations(ctx);

  std::map<std::pair<int, std::vector<float>>, CachedMesh> mesh_cache;
  std::map<int, Material> material_cache;
  const auto material_for = [&](int index) -> const Material& {
    auto it = material_cache.find(index);
    if (it == material_cache.end())
      it = material_cache.emplace(index, map_material(ctx, index)).first;
    return it->second;
  };
  bool warned_skin = false;

  // Depth-first with an explicit stack (deep hierarchies must not overflow the call stack);
  // parents are created before their children.
  struct Pending {
    int node = -1;
    ecs::Entity parent = ecs::null_entity;
    dmat4 world_from_parent{1.0};
    std::string field; ///< where the node index was found, for messages
  };
  std::vector<Pending> stack;
  for (std::size_t i = roots.size(); i-- > 0;)
    stack.push_back(
        {roots[i], ecs::null_entity, dmat4(1.0), roots_field + "[" + std::to_string(i) + "]"});
  std::vector<bool> visited(model.nodes.size(), false);

  while (!stack.empty()) {
    const Pending item = std::move(stack.back());
    stack.pop_back();
    if (item.node < 0 || static_cast<std::size_t>(item.node) >= model.nodes.size())
      ctx.fail(item.field, "node index " + std::to_string(item.node) +
                               " is out of range (the file has " +
                               std::to_string(model.nodes.size()) + " nodes)");
    const auto node_index = static_cast<std::size_t>(item.node);
    // A format check this traversal needs to terminate, not the ECS cycle check of load_scene.
    if (visited[node_index])
      ctx.fail(item.field, "node " + std::to_string(item.node) +
                               " is reached twice: the node graph has a cycle or a node with two "
                               "parents (glTF nodes must form a tree)");
    visited[node_index] = true;
    const tinygltf::Node& node = model.nodes[node_index];
    const std::string field = index_field("nodes", node_index);

    const auto anim_it = animations.find(item.node);
    const NodeAnimation* node_anim = anim_it == animations.end() ? nullptr : &anim_it->second;
    const bool deforms = node_anim != nullptr && node_anim->weights.has_value();

    const ecs::Entity e = reg.create();
    const std::string name = node.name.empty() ? "node " + std::to_string(item.node) : node.name;
    reg.emplace<Name>(e, name);
    const Transform transform = node_transform(ctx, node, field);
    reg.emplace<Transform>(e, transform);
    if (!item.parent.is_null()) reg.emplace<Parent>(e, Parent{item.parent});
    const dmat4 world_from_node = item.world_from_parent * transform.parent_from_local();

    Animation node_animation;
    if (node_anim != nullptr) node_animation = node_anim->trs;
    std::size_t node_vertex_count = 0; // vertices of the mesh on the node's own entity

    if (node.skin >= 0 && !warned_skin) {
      ctx.warn(field + ": skins are not supported; skinned meshes stay in their bind pose");
      warned_skin = true;
    }

    if (node.mesh >= 0) {
      if (static_cast<std::size_t>(node.mesh) >= model.meshes.size())
        ctx.fail(field + ".mesh", "mesh index " + std::to_string(node.mesh) +
                                      " is out of range (the file has " +
                                      std::to_string(model.meshes.size()) + " meshes)");
      std::vector<float> weights = node_weights(ctx, node, field);
      const bool default_weights = weights == mesh_default_weights(ctx, node.mesh);
      auto cached = mesh_cache.find({node.mesh, weights});
      if (cached == mesh_cache.end()) {
        CachedMesh entry;
        entry.parts = build_mesh_parts(ctx, node.mesh, true, weights);
        for (const MeshPart& part : entry.parts)
          entry.geometry.push_back(std::make_shared<const TriangleMesh>(part.geometry));
        cached =
            mesh_cache.emplace(std::pair(node.mesh, std::move(weights)), std::move(entry)).first;
      }
      const CachedMesh& mesh = cached->second;
      if (mesh.parts.empty())
        ctx.warn(field + ": mesh " + std::to_string(node.mesh) +
                 " has no triangle primitives; the node gets no geometry");

      const bool split = mesh.parts.size() > 1;
      for (std::size_t p = 0; p < mesh.parts.size(); ++p) {
        const MeshPart& part = mesh.parts[p];
        const Material& material = material_for(part.material); // checks the index
        ecs::Entity target = e;
        if (split) {
          // Several materials: one child entity per material, at the node's origin.
          target = reg.create();
          reg.emplace<Name>(target, name + " (" + material_label(ctx, part.material) + ")");
          reg.emplace<Transform>(target);
          reg.emplace<Parent>(target, Parent{e});
        }
        Mesh component;
        component.geometry = mesh.geometry[p];
        if (!split && default_weights) {
          // load_gltf_mesh(file, mesh) rebuilds exactly this geometry, so the scene can refer
          // to it; a subset of primitives or other morph weights cannot be named that way.
          component.source.kind = MeshSource::Kind::File;
          component.source.path = path.filename().string();
          component.source.gltf_mesh = node.mesh;
        }
        reg.emplace<Mesh>(target, std::move(component));
        reg.emplace<Material>(target, material);

        Animation* animation = &node_animation;
        Animation part_animation;
        if (split) animation = &part_animation;
        if (deforms) {
          animation->vertices = vertex_keys(ctx, *node_anim->weights, part);
          animation->normals = normal_keys(ctx, *node_anim->weights, part);
          validate_animation(*animation, part.geometry.vertex_count(), ctx.file,
                             node_anim->weights->field);
        }
        if (split) {
          if (deforms) reg.emplace<Animation>(target, std::move(part_animation));
        } else {
          node_vertex_count = part.geometry.vertex_count();
        }
      }
    }

    if (!node_animation.translation.empty() || !node_animation.rotation.empty() ||
        !node_animation.scale.empty() || !node_animation.vertices.empty()) {
      // Each track was checked where it was read (naming its channel); this checks the whole.
      validate_animation(node_animation, node_vertex_count, ctx.file, field + ".animation");
      reg.emplace<Animation>(e, std::move(node_animation));
    }

    if (node.camera >= 0)
      if (const auto camera = map_camera(ctx, node.camera, world_from_node, scene.settings, field))
        reg.emplace<Camera>(e, *camera);
    if (const auto light = map_light(ctx, node, field)) reg.emplace<Light>(e, *light);

    for (std::size_t c = node.children.size(); c-- > 0;)
      stack.push_back({node.children[c], e, world_from_node, field + index_field(".children", c)});
  }
  return scene;
}

} // namespace

Scene load_gltf_scene(const std::filesystem::path& path) {
  const tinygltf::Model model = read_model(path);
  const Context ctx{model, path.string()};
  return build_scene(ctx, path);
}

TriangleMesh load_gltf_mesh(const std::filesystem::path& path, int mesh_index) {
  const tinygltf::Model model = read_model(path);
  const Context ctx{model, path.string()};
  if (mesh_index < 0 || static_cast<std::size_t>(mesh_index) >= model.meshes.size())
    ctx.fail("meshes", "mesh index " + std::to_string(mesh_index) +
                           " is out of range (the file has " + std::to_string(model.meshes.size()) +
                           " meshes)");
  std::vector<MeshPart> parts =
      build_mesh_parts(ctx, mesh_index, false, mesh_default_weights(ctx, mesh_index));
  if (parts.empty())
    ctx.fail(index_field("meshes", static_cast<std::size_t>(mesh_index)),
             "mesh has no triangle primitives");
  return std::move(parts.front().geometry);
}

} // namespace specula
