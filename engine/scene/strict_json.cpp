#include "specula/scene/strict_json.h"

#include "specula/core/error.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

namespace specula::strict_json {
namespace {

/// Edit distance, for "did you mean" hints on unknown keys.
std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

} // namespace

std::string member_path(const std::string& parent, std::string_view key) {
  return parent.empty() ? std::string(key) : parent + "." + std::string(key);
}

std::string element_path(const std::string& parent, std::size_t index) {
  return parent + "[" + std::to_string(index) + "]";
}

std::string describe(const json& j) {
  if (j.is_number_integer() || j.is_number_unsigned()) return "the integer " + j.dump();
  if (j.is_number_float()) return "the number " + j.dump();
  if (j.is_string()) // quoted and escaped by dump(), cut by printable()
    return "the string " + printable(j.dump(-1, ' ', false, json::error_handler_t::replace));
  if (j.is_boolean()) return j.get<bool>() ? "true" : "false";
  if (j.is_null()) return "null";
  if (j.is_array()) return "an array of " + std::to_string(j.size());
  return "an object";
}

std::string format_double(double v) {
  char buf[64];
  const auto result = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, result.ptr);
}

void Reader::fail(const std::string& path, const std::string& message) const {
  if (path.empty()) throw Error(file_, message);
  throw Error(file_, path, message);
}

// ---------------------------------------------------------------------------------------------
// Parsing

namespace {

/// Builds the document from nlohmann's SAX events. Doing it here rather than with nlohmann's
/// callback parser (quadratic in the length of an array of objects) lets it reject duplicate keys,
/// which the DOM would silently collapse to the last, and name the JSON path and line of errors
/// the parser raises itself, such as a number literal that overflows (1e999).
class DocumentBuilder {
public:
  using string_t = json::string_t;

  bool null() { return add(nullptr); }
  bool boolean(bool v) { return add(v); }
  bool number_integer(json::number_integer_t v) { return add(v); }
  bool number_unsigned(json::number_unsigned_t v) { return add(v); }
  bool number_float(json::number_float_t v, const string_t&) { return add(v); }
  bool string(string_t& v) { return add(std::move(v)); }
  bool binary(json::binary_t&) { return add(nullptr); } // not produced by the text parser
  bool start_object(std::size_t) { return open(json::value_t::object); }
  bool start_array(std::size_t) { return open(json::value_t::array); }
  bool end_object() { return close(); }
  bool end_array() { return close(); }
  bool key(string_t& k) {
    Frame& f = stack_.back();
    f.key = k;
    if (f.value->contains(k)) {
      duplicate_ = path();
      return false;
    }
    f.member = &(*f.value)[k];
    return true;
  }
  bool parse_error(std::size_t position, const std::string&, const nlohmann::detail::exception& e) {
    error_position_ = position;
    error_message_ = e.what();
    error_path_ = path();
    return false;
  }

  /// Path of the value being read now.
  [[nodiscard]] std::string path() const {
    std::string p;
    for (std::size_t i = 0; i < stack_.size(); ++i) {
      const Frame& f = stack_[i];
      if (f.value->is_object()) {
        p = member_path(p, f.key);
      } else {
        // The innermost array is between elements; outer ones are inside their last element.
        const std::size_t n = f.value->size();
        p = element_path(p, i + 1 == stack_.size() ? n : n - 1);
      }
    }
    return p;
  }

  json root;
  std::optional<std::string> duplicate_;
  std::size_t error_position_ = 0;
  std::string error_message_;
  std::string error_path_;

private:
  struct Frame {
    json* value;
    json* member = nullptr; ///< objects: the slot the next value fills
    std::string key;
  };

  template <typename V>
  json* place(V&& v) {
    if (stack_.empty()) {
      root = json(std::forward<V>(v));
      return &root;
    }
    Frame& f = stack_.back();
    if (f.value->is_array()) {
      f.value->emplace_back(std::forward<V>(v));
      return &f.value->back();
    }
    *f.member = json(std::forward<V>(v));
    return f.member;
  }
  template <typename V>
  bool add(V&& v) {
    place(std::forward<V>(v));
    return true;
  }
  bool open(json::value_t type) {
    // Children are only appended to the innermost open container, so pointers to the open chain
    // stay valid.
    stack_.push_back(Frame{place(type), nullptr, {}});
    return true;
  }
  bool close() {
    stack_.pop_back();
    return true;
  }

  std::vector<Frame> stack_;
};

} // namespace

void check_nesting(const Reader& r, std::string_view text, std::size_t max_depth) {
  std::size_t depth = 0;
  std::size_t deepest = 0;
  std::size_t line = 1;
  std::size_t first_line = 0; // where the limit was first exceeded
  bool in_string = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '\n') ++line;
    if (in_string) {
      if (c == '\\')
        ++i; // the escaped character, a quote or a backslash among them, cannot end the string
      else if (c == '"')
        in_string = false;
      continue;
    }
    switch (c) {
    case '"':
      in_string = true;
      break;
    case '[':
    case '{':
      deepest = std::max(deepest, ++depth);
      if (depth > max_depth && first_line == 0) first_line = line;
      break;
    case ']':
    case '}':
      if (depth > 0) --depth; // unbalanced: the parser's to report
      break;
    default:
      break;
    }
  }
  if (deepest > max_depth)
    r.fail("", "JSON nesting depth " + std::to_string(deepest) + " exceeds the limit of " +
                   std::to_string(max_depth) + " (first exceeded at line " +
                   std::to_string(first_line) + "; docs/limits.md)");
}

json parse(const Reader& r, const std::string& text) {
  check_nesting(r, text);
  DocumentBuilder builder;
  if (json::sax_parse(text, &builder, json::input_format_t::json, /*strict=*/true,
                      /*ignore_comments=*/false))
    return std::move(builder.root);
  if (builder.duplicate_) r.fail(*builder.duplicate_, "key appears twice in the same object");

  // nlohmann's position counts the characters read, the offending one included.
  const std::size_t at =
      std::min(builder.error_position_ > 0 ? builder.error_position_ - 1 : 0, text.size());
  const auto line = 1 + std::count(text.begin(), text.begin() + std::ptrdiff_t(at), '\n');
  const std::size_t previous_newline = at == 0 ? std::string::npos : text.rfind('\n', at - 1);
  const std::size_t column =
      at + 1 - (previous_newline == std::string::npos ? 0 : previous_newline + 1);
  const std::string where = "line " + std::to_string(line) + " column " + std::to_string(column);

  // Drop nlohmann's "[json.exception.parse_error.101] parse error at line 1, column 2: " prefix.
  std::string detail = builder.error_message_;
  const std::size_t column_colon = detail.find(": ", detail.find("column"));
  const std::size_t bracket = detail.find("] ");
  if (detail.find("parse_error") != std::string::npos && column_colon != std::string::npos) {
    detail = detail.substr(column_colon + 2);
  } else if (bracket != std::string::npos) {
    detail = detail.substr(bracket + 2);
  }
  if (builder.error_message_.find("out_of_range") != std::string::npos)
    r.fail(builder.error_path_, where + ": " + one_line(detail, 256) + " (numbers must be finite)");
  throw Error(r.file(), int(line),
              "malformed JSON at " + where +
                  (builder.error_path_.empty() ? "" : " (in " + builder.error_path_ + ")") + ": " +
                  one_line(detail, 256));
}

// ---------------------------------------------------------------------------------------------
// Objects and values

Object::Object(const Reader& r, const json& j, std::string path,
               std::initializer_list<std::string_view> allowed, std::string_view what)
    : reader_(r), json_(j), path_(std::move(path)) {
  if (!j.is_object())
    r.fail(path_, "expected an object" + (what.empty() ? "" : " (" + std::string(what) + ")") +
                      ", got " + describe(j));
  for (const auto& item : j.items()) {
    const std::string& key = item.key();
    if (std::find(allowed.begin(), allowed.end(), key) != allowed.end()) continue;
    std::string message = "unknown key \"" + printable(key) + "\"";
    std::string_view closest;
    std::size_t best = 3; // at most two edits away counts as a likely typo
    for (const std::string_view candidate : allowed) {
      const std::size_t d = edit_distance(key, candidate);
      if (d < best) {
        best = d;
        closest = candidate;
      }
    }
    if (!closest.empty()) message += " (did you mean \"" + std::string(closest) + "\"?)";
    message += "; allowed here:";
    for (const std::string_view candidate : allowed) message += " " + std::string(candidate);
    r.fail(member_path(path_, key), message);
  }
}

const json* Object::find(std::string_view key) const {
  const auto it = json_.find(key);
  return it == json_.end() ? nullptr : &*it;
}

const json& Object::require(std::string_view key) const {
  const json* j = find(key);
  if (!j) reader_.fail(path_, "missing required key \"" + std::string(key) + "\"");
  return *j;
}

double read_number(const Reader& r, const json& j, const std::string& path) {
  if (!j.is_number()) r.fail(path, "expected a number, got " + describe(j));
  const double v = j.get<double>();
  // The parser already rejects overflowing literals; this guards hand-built documents.
  if (!std::isfinite(v)) r.fail(path, "number is not finite");
  return v;
}

float read_float(const Reader& r, const json& j, const std::string& path) {
  const double v = read_number(r, j, path);
  if (std::abs(v) > static_cast<double>(std::numeric_limits<float>::max()))
    r.fail(path, "number " + format_double(v) + " is outside the single-precision range");
  return static_cast<float>(v);
}

std::uint64_t read_unsigned(const Reader& r, const json& j, const std::string& path,
                            std::uint64_t min, std::uint64_t max) {
  const std::string range = "[" + std::to_string(min) + ", " + std::to_string(max) + "]";
  if (j.is_number_float()) {
    r.fail(path, "expected an integer in " + range + ", got " + describe(j));
  }
  if (!j.is_number_integer()) r.fail(path, "expected an integer, got " + describe(j));
  if (j.is_number_unsigned()) {
    const auto v = j.get<std::uint64_t>();
    if (v < min || v > max) r.fail(path, "must be in " + range + ", got " + std::to_string(v));
    return v;
  }
  const auto v = j.get<std::int64_t>();
  if (v < 0 || static_cast<std::uint64_t>(v) < min || static_cast<std::uint64_t>(v) > max)
    r.fail(path, "must be in " + range + ", got " + std::to_string(v));
  return static_cast<std::uint64_t>(v);
}

std::uint32_t read_u32(const Reader& r, const json& j, const std::string& path, std::uint32_t min,
                       std::uint32_t max) {
  return static_cast<std::uint32_t>(read_unsigned(r, j, path, min, max));
}

bool read_bool(const Reader& r, const json& j, const std::string& path) {
  if (!j.is_boolean()) r.fail(path, "expected true or false, got " + describe(j));
  return j.get<bool>();
}

std::string read_string(const Reader& r, const json& j, const std::string& path) {
  if (!j.is_string()) r.fail(path, "expected a string, got " + describe(j));
  return j.get<std::string>();
}

const json& read_array(const Reader& r, const json& j, const std::string& path,
                       std::string_view what) {
  if (!j.is_array())
    r.fail(path, "expected an array (" + std::string(what) + "), got " + describe(j));
  return j;
}

float read_float_in(const Reader& r, const json& j, const std::string& path, float min, float max) {
  const float v = read_float(r, j, path);
  r.check(v >= min && v <= max, path,
          "must be in [" + format_double(min) + ", " + format_double(max) + "], got " +
              format_double(v));
  return v;
}

float read_positive(const Reader& r, const json& j, const std::string& path) {
  const float v = read_float(r, j, path);
  r.check(v > 0.0f, path, "must be > 0, got " + format_double(v));
  return v;
}

float read_non_negative(const Reader& r, const json& j, const std::string& path) {
  const float v = read_float(r, j, path);
  r.check(v >= 0.0f, path, "must be >= 0, got " + format_double(v));
  return v;
}

} // namespace specula::strict_json
