#pragma once
/// \file
/// Strict JSON reading for Specula's file formats, knowing nothing of scenes: a parser that
/// rejects duplicate keys and places syntax errors by line, column and JSON path; objects whose
/// keys are checked against those allowed at their place; typed readers. Every failure is a
/// specula::Error naming the file and the JSON path of the bad value, as messages show paths:
/// `entities[3].material.ior`. json_scene.cpp maps the values onto components.
///
/// Internal to the engine's loaders: it exposes nlohmann::json, a private dependency of
/// specula::engine, so code outside engine/ should not include it.

#include "specula/core/math.h"

#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <string_view>

namespace specula::strict_json {

using json = nlohmann::json;

/// Path of member `key` of the value at `parent`: "parent.key", or "key" at the root ("").
[[nodiscard]] std::string member_path(const std::string& parent, std::string_view key);
/// Path of element `index` of the array at `parent`: "parent[index]".
[[nodiscard]] std::string element_path(const std::string& parent, std::size_t index);

/// A value as messages name it: "the integer 3", "the number 0.5", "the string \"a\"", "true",
/// "null", "an array of 2", "an object".
[[nodiscard]] std::string describe(const json& j);

/// The shortest decimal that reads back to exactly `v` (std::to_chars).
[[nodiscard]] std::string format_double(double v);

/// Where failures are reported: fail() throws specula::Error for the file, at a JSON path (""
/// for the whole document).
class Reader {
public:
  explicit Reader(std::string file) : file_(std::move(file)) {}

  [[noreturn]] void fail(const std::string& path, const std::string& message) const;
  /// fail(path, message) unless `ok`.
  void check(bool ok, const std::string& path, const std::string& message) const {
    if (!ok) fail(path, message);
  }
  [[nodiscard]] const std::string& file() const { return file_; }

private:
  std::string file_;
};

/// Deepest nesting of arrays and objects any JSON input may have (Specula scenes, glTF): far
/// beyond any real file, and small enough that recursive parsers (tinygltf's) cannot run out
/// of stack. docs/limits.md.
inline constexpr std::size_t kMaxJsonNesting = 256;

/// Fails unless the arrays and objects of `text` nest at most `max_depth` deep: "JSON nesting
/// depth D exceeds the limit of L (first exceeded at line N)". A cheap scan of the bytes, for
/// use before any parser sees them; brackets inside strings (escaped quotes included) do not
/// count. Not a syntax check: malformed text is left to the parser.
void check_nesting(const Reader& r, std::string_view text, std::size_t max_depth = kMaxJsonNesting);

/// Parses `text` as one JSON document (RFC 8259: no comments, no trailing commas). A key that
/// appears twice in one object is an error at that key's path, rather than the last one silently
/// winning. Syntax errors name the line and column (Error::line()) and the path being read;
/// number literals outside the double range (1e999) are errors at their path. Checks the
/// nesting first (check_nesting).
[[nodiscard]] json parse(const Reader& r, const std::string& text);

/// A JSON object whose keys are checked against those the format allows at its place, so a typo
/// is an error instead of a silently ignored field. The constructor fails when `j` is not an
/// object (`what` names what was expected, e.g. "camera") or has a key outside `allowed`; the
/// message suggests the closest allowed key (at most two edits away) and lists them all. Holds
/// references: `r` and `j` must outlive it.
class Object {
public:
  Object(const Reader& r, const json& j, std::string path,
         std::initializer_list<std::string_view> allowed, std::string_view what = "");

  /// The member `key`, or nullptr when absent.
  [[nodiscard]] const json* find(std::string_view key) const;
  /// The member `key`; fails at the object's path when absent.
  [[nodiscard]] const json& require(std::string_view key) const;
  [[nodiscard]] bool has(std::string_view key) const { return find(key) != nullptr; }
  /// Path of member `key`, for reading it and for messages about it.
  [[nodiscard]] std::string path(std::string_view key) const { return member_path(path_, key); }

private:
  const Reader& reader_;
  const json& json_;
  std::string path_;
};

// Typed readers: each fails at `path` when `j` is not what it reads, saying what was expected
// and what was found (describe).

/// A finite number.
[[nodiscard]] double read_number(const Reader& r, const json& j, const std::string& path);
/// A number within the single-precision range, converted to float (rounded to nearest).
[[nodiscard]] float read_float(const Reader& r, const json& j, const std::string& path);
/// A float in [min, max].
[[nodiscard]] float read_float_in(const Reader& r, const json& j, const std::string& path,
                                  float min, float max);
/// A float > 0.
[[nodiscard]] float read_positive(const Reader& r, const json& j, const std::string& path);
/// A float >= 0.
[[nodiscard]] float read_non_negative(const Reader& r, const json& j, const std::string& path);
/// An integer literal (1.0 is not one) in [min, max].
[[nodiscard]] std::uint64_t read_unsigned(const Reader& r, const json& j, const std::string& path,
                                          std::uint64_t min, std::uint64_t max);
/// read_unsigned narrowed to 32 bits.
[[nodiscard]] std::uint32_t read_u32(const Reader& r, const json& j, const std::string& path,
                                     std::uint32_t min, std::uint32_t max);
/// true or false.
[[nodiscard]] bool read_bool(const Reader& r, const json& j, const std::string& path);
/// A string.
[[nodiscard]] std::string read_string(const Reader& r, const json& j, const std::string& path);
/// An array, returned for iteration; `what` says what its elements are, for the message.
const json& read_array(const Reader& r, const json& j, const std::string& path,
                       std::string_view what);

/// An array of exactly N numbers read with read_float, e.g. [x, y, z] for N = 3.
template <int N>
[[nodiscard]] glm::vec<N, float> read_vec(const Reader& r, const json& j, const std::string& path) {
  static_assert(N >= 2 && N <= 4);
  static constexpr std::string_view kShape[] = {"", "", "[x, y]", "[x, y, z]", "[x, y, z, w]"};
  if (!j.is_array() || j.size() != N)
    r.fail(path, "expected an array of " + std::to_string(N) + " numbers " +
                     std::string(kShape[N]) + ", got " + describe(j));
  glm::vec<N, float> v;
  for (int i = 0; i < N; ++i)
    v[i] = read_float(r, j[static_cast<std::size_t>(i)],
                      element_path(path, static_cast<std::size_t>(i)));
  return v;
}

} // namespace specula::strict_json
